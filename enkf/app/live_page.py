"""The live page (bokeh): a run's latest frame, optics, temperatures beneath and risk map.

``python -m enkf.app.live_page RUN_DIR --port PORT`` serves the run directory that
``identify --follow ... --serve`` writes (:mod:`enkf.app.live`), and ``--replay`` shows a
recorded run at its own pace (``tissue-enkf replay RUN_DIR``). The page has:

- the latest frame of the camera (deg C), when the data are frames;
- each estimated parameter's mean and +-2 sd band over time;
- the temperatures below the surface (the tracked points) with their +-2 sd bands;
- the damage-risk map: the probability of a damage integral above 1 on the x-z plane
  through the beam;
- with a drift bank, the weight the data give to optics that drift while heated;
- with ``[advice]`` (``advice.csv``, :mod:`enkf.tissue.advice`): when to stop the laser,
  the median and the interval (5%-95% by default) after each reading, and the risks
  under the plan that the protected tissue or the surface passes its limit;
- a status line: the time, the readings, the latest estimate, the latest advice, and
  ``finished`` once ``run.json`` says the run ended.

The page polls the files every 100 ms and sends only what is new (bokeh's ``stream``):
it keeps up with 10 Hz readings without taking anything from the filter's process.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["RunSource", "advice_columns", "advice_text", "make_document", "serve"]

_BAND = 2.0  #: the bands are mean +- 2 sd
_UNITS = {"mua": "1/cm", "mus": "1/cm", "VHC": "J/(cm^3 K)", "TC": "W/(cm K)",
          "beam_radius": "cm"}
POLL_MS = 100


def _columns(header: list[str]) -> dict:
    """Which columns of estimates.csv are the parameters, the temperatures, the drift."""
    params, temps = [], []
    for c in header:
        if not c.endswith("_mean"):
            continue
        base = c[: -len("_mean")]
        if f"{base}_std" not in header:
            continue
        if re.fullmatch(r"T\d+|T_z[-\d.]+", base):
            temps.append(base)
        elif not (base.startswith("sensor") or base.endswith("_eff")):
            params.append(base)
    return {"params": params, "temps": temps, "drift": "drift_weight" in header}


def advice_columns(header: list[str]) -> dict:
    """advice.csv's columns the page shows: the stop time's median and interval
    (``stop``: (median, lower, upper), the quantile columns in the file's order) and the
    risks under the plan (``risks``: ``{label: column}``)."""
    q = [c for c in header if re.fullmatch(r"stop_time_q[\dp]+_s", c)]
    risks = {f"P({r} over its limit)": f"p_{r}_plan" for r in ("protected", "surface")
             if f"p_{r}_plan" in header}
    return {"stop": ("stop_time_median_s", *q[:2]), "risks": risks,
            "quantiles": [c[len("stop_time_q"):-2].replace("p", ".") for c in q[:2]]}


def advice_text(header: list[str], row: list[float]) -> str:
    """The status line's advice from one row of advice.csv: when to stop (median and
    interval; beyond the forecast's horizon: ``not within the horizon``) and the risks."""
    idx = {c: i for i, c in enumerate(header)}
    cols = advice_columns(header)

    def when(c):
        v = row[idx[c]]
        return f"{v:.2f} s" if np.isfinite(v) else "beyond the horizon"

    med, lo, hi = cols["stop"]
    q = cols["quantiles"]
    parts = [f"stop the laser at {when(med)} ({q[0]}%-{q[1]}%: {when(lo)} to {when(hi)})"]
    parts += [f"{label} = {row[idx[c]]:.2f}" for label, c in cols["risks"].items()]
    return " &middot; ".join(parts)


class _CsvTail:
    """The whole lines added to a CSV file since the last call, as floats (the header
    kept apart): the writer may be mid-line."""

    def __init__(self, path: Path):
        self.path, self.offset, self.header = path, 0, None

    def read(self) -> list[list[float]]:
        try:
            with open(self.path, "rb") as fh:
                fh.seek(self.offset)
                chunk = fh.read()
        except OSError:
            return []
        end = chunk.rfind(b"\n") + 1
        self.offset += end
        out = []
        for row in csv.reader(chunk[:end].decode("utf-8", "replace").splitlines()):
            if not row:
                continue
            if self.header is None:
                self.header = row
                continue
            try:
                out.append([float(v) for v in row])
            except ValueError:
                continue
        return out


class RunSource:
    """What the page shows of a run directory: new estimate rows, the frame, the risk.

    Live (``replay_speed`` None): rows as they are written. Replay: the rows of a finished
    run revealed as the clock runs (``replay_speed`` times the data's own pace), with the
    frames of its data where they are camera files.
    """

    def __init__(self, run_dir: str | Path, replay_speed: float | None = None):
        self.dir = Path(run_dir)
        self.speed = replay_speed
        self.offset = 0  # bytes of estimates.csv read
        self.header = None
        self.cols = None
        self.rows: list[list[float]] = []  # replay: every row, revealed by the clock
        self.shown = 0
        self.t0 = time.monotonic()
        self._stamp = {}
        self.frames = None  # replay: (times, frames)
        self._advice = _CsvTail(self.dir / "advice.csv")
        self.advice_rows: list[list[float]] = []  # replay: every row, revealed by the clock
        self.advice_shown = 0
        if replay_speed is not None:
            self._load_recorded()

    # ------------------------------------------------------------------ reading
    def meta(self) -> dict:
        p = self.dir / "live" / "meta.json"
        try:
            return json.loads(p.read_text())
        except (OSError, ValueError):
            return {}

    def run_info(self) -> dict:
        try:
            return json.loads((self.dir / "run.json").read_text())
        except (OSError, ValueError):
            return {}

    def finished(self) -> bool:
        info = self.run_info()
        done = bool(info) and not info.get("running", False)
        if self.speed is not None:
            return done and self.shown >= len(self.rows)
        return done

    def _parse(self, text: str) -> list[list[float]]:
        out = []
        for row in csv.reader(text.splitlines()):
            if not row:
                continue
            if self.header is None:
                self.header = row
                self.cols = _columns(row)
                continue
            try:
                out.append([float(v) for v in row])
            except ValueError:
                continue
        return out

    def _read_new(self) -> list[list[float]]:
        p = self.dir / "estimates.csv"
        try:
            with open(p, "rb") as fh:
                fh.seek(self.offset)
                chunk = fh.read()
        except OSError:
            return []
        end = chunk.rfind(b"\n") + 1  # whole lines only: the writer may be mid-line
        self.offset += end
        return self._parse(chunk[:end].decode("utf-8", "replace"))

    @property
    def advice_header(self) -> list[str] | None:
        """advice.csv's column names (None before its first line)."""
        return self._advice.header

    def new_advice(self) -> list[list[float]]:
        """advice.csv's rows not yet sent to the page (its columns:
        :attr:`advice_header`)."""
        if self.speed is None:
            return self._advice.read()
        t = self.now()
        k = self.advice_shown
        while k < len(self.advice_rows) and self.advice_rows[k][0] <= t:
            k += 1
        out, self.advice_shown = self.advice_rows[self.advice_shown:k], k
        return out

    def _load_recorded(self) -> None:
        self.rows = self._read_new()
        self.advice_rows = self._advice.read()
        info = self.run_info()
        data = info.get("follow") or (info.get("data") or [None])[0]
        if data is None:
            return
        try:
            from .frames import FRAME_SUFFIXES, read_frames

            if Path(data).is_dir() or Path(data).suffix.lower() in FRAME_SUFFIXES:
                rate = (info.get("config", {}).get("sensors", {}) or {}).get("rate")
                s = read_frames(data, rate=rate)
                self.frames = (s.times, s.frames)
        except (ValueError, OSError):
            self.frames = None

    def now(self) -> float:
        return (time.monotonic() - self.t0) * (self.speed or 1.0)

    def new_rows(self) -> list[list[float]]:
        """Rows not yet sent to the page."""
        if self.speed is None:
            return self._read_new()
        t = self.now()
        k = self.shown
        while k < len(self.rows) and self.rows[k][0] <= t:
            k += 1
        out, self.shown = self.rows[self.shown:k], k
        return out

    def _changed(self, name: str) -> Path | None:
        p = self.dir / "live" / name
        try:
            st = os.stat(p)
        except OSError:
            return None
        sig = (st.st_mtime_ns, st.st_size, st.st_ino)
        if self._stamp.get(name) == sig:
            return None
        self._stamp[name] = sig
        return p

    def frame(self) -> np.ndarray | None:
        """The latest frame, when it changed (None otherwise)."""
        if self.speed is not None:
            if self.frames is None or self.shown == 0:
                return None
            t = self.rows[self.shown - 1][0]
            k = int(np.searchsorted(self.frames[0], t, side="right")) - 1
            if k < 0 or self._stamp.get("frame") == k:
                return None
            self._stamp["frame"] = k
            return self.frames[1][k]
        p = self._changed("frame.npy")
        return None if p is None else _load(p)

    def risk(self) -> np.ndarray | None:
        if self.speed is not None and self.shown < len(self.rows):
            return None  # the recorded map is the run's last: shown at the end
        p = self._changed("risk.npy")
        return None if p is None else _load(p)


def _load(p: Path) -> np.ndarray | None:
    try:
        return np.load(p, allow_pickle=False)
    except (OSError, ValueError, EOFError):
        return None  # replaced while read: the next poll has it


# ---------------------------------------------------------------------- the page
def make_document(doc, source: RunSource, parent: int | None = None) -> None:
    """Lay out the page in the bokeh document ``doc`` and poll ``source``."""
    from bokeh.layouts import column, row
    from bokeh.models import ColorBar, ColumnDataSource, Div, LinearColorMapper
    from bokeh.palettes import Category10, Inferno256, Viridis256
    from bokeh.plotting import figure

    meta = source.meta()
    status = Div(text="<b>waiting for the first reading</b>", name="status",
                 styles={"font-size": "15px"}, width=1100)
    title = Div(text=f"<h2 style='margin:4px 0'>tissue-enkf: {source.dir.name}"
                     f"{' (replay)' if source.speed is not None else ''}</h2>", width=1100)
    # the frame
    ext = meta.get("frame_extent_cm") or [0, 1, 0, 1]
    frame_src = ColumnDataSource({"image": [np.zeros((2, 2))]})
    frame_map = LinearColorMapper(palette=Inferno256)
    turned = f", turned {meta['rotation']:g} deg" if meta.get("rotation") else ""
    f_frame = figure(title=f"latest frame (deg C{turned})", width=360, height=330,
                     x_range=(ext[0], ext[1]), y_range=(ext[2], ext[3]),
                     x_axis_label="along the rows (cm from the beam)",
                     y_axis_label="along the columns (cm)",
                     toolbar_location=None)
    f_frame.image(image="image", x=ext[0], y=ext[2], dw=ext[1] - ext[0], dh=ext[3] - ext[2],
                  color_mapper=frame_map, source=frame_src)
    f_frame.add_layout(ColorBar(color_mapper=frame_map, width=10), "right")
    # the risk map
    rext = meta.get("risk_extent_cm") or [-1, 1, 0, 1]
    risk_src = ColumnDataSource({"image": [np.zeros((2, 2))]})
    risk_map = LinearColorMapper(palette=Viridis256, low=0.0, high=1.0)
    f_risk = figure(title=f"damage risk: {meta.get('risk') or 'not recorded'} (x-z at y = 0)",
                    width=420, height=330, x_range=(rext[0], rext[1]), y_range=(rext[3], rext[2]),
                    x_axis_label="x (cm)", y_axis_label="depth z (cm)", toolbar_location=None)
    f_risk.image(image="image", x=rext[0], y=rext[2], dw=rext[1] - rext[0], dh=rext[3] - rext[2],
                 color_mapper=risk_map, source=risk_src)
    f_risk.add_layout(ColorBar(color_mapper=risk_map, width=10), "right")
    # the optics and the temperatures: filled once the header is known
    sources: dict = {}
    figs = {}

    def band_figure(key, title, names, labels, y_label, width=360):
        f = figure(title=title, width=width, height=260, x_axis_label="time (s)",
                   y_axis_label=y_label, toolbar_location=None)
        cols = {"t": []}
        for n in names:
            cols.update({f"{n}_m": [], f"{n}_lo": [], f"{n}_hi": []})
        src = ColumnDataSource(cols)
        colours = Category10[10]
        for j, (n, lab) in enumerate(zip(names, labels, strict=True)):
            c = colours[j % 10]
            f.varea(x="t", y1=f"{n}_lo", y2=f"{n}_hi", source=src, fill_color=c, fill_alpha=0.25)
            f.line(x="t", y=f"{n}_m", source=src, line_color=c, line_width=2, legend_label=lab)
        f.legend.location = "top_left"
        f.legend.background_fill_alpha = 0.5
        sources[key], figs[key] = src, f
        return f

    plots = column(Div(text=""))
    advice_figs = column(Div(text=""))  # with advice.csv: when to stop, and the risks
    doc.add_root(column(title, status, row(f_frame, f_risk), plots, advice_figs))
    doc.title = f"tissue-enkf: {source.dir.name}"
    state = {"last": None, "n": 0, "built": False, "done": False, "advice": None}

    def build_advice():
        cols = advice_columns(source.advice_header)
        q = cols["quantiles"]
        f = figure(title=f"when to stop the laser: median, {q[0]}%-{q[1]}%", width=420,
                   height=260, x_axis_label="time (s)", y_axis_label="stop at (s)",
                   toolbar_location=None)
        src = ColumnDataSource({"t": [], "m": [], "lo": [], "hi": []})
        f.varea(x="t", y1="lo", y2="hi", source=src, fill_color="green", fill_alpha=0.25)
        f.line(x="t", y="m", source=src, line_color="green", line_width=2)
        sources["advice"] = src
        children = [f]
        if cols["risks"]:
            g = figure(title="risks under the plan", width=420, height=260, y_range=(0, 1),
                       x_axis_label="time (s)", y_axis_label="probability",
                       toolbar_location=None)
            rsrc = ColumnDataSource({"t": [], **{c: [] for c in cols["risks"].values()}})
            for j, (label, c) in enumerate(cols["risks"].items()):
                g.line(x="t", y=c, source=rsrc, line_width=2, legend_label=label,
                       line_color=("magenta", "red")[j % 2])
            g.legend.location = "top_left"
            sources["risks"] = rsrc
            children.append(g)
        advice_figs.children = [row(*children)]

    def stream_advice(rows):
        h = source.advice_header
        idx = {c: i for i, c in enumerate(h)}
        cols = advice_columns(h)
        a = np.array(rows, dtype=float)
        a[~np.isfinite(a)] = np.nan  # beyond the horizon: not drawn
        t = a[:, idx["time_s"]]
        med, lo, hi = cols["stop"]
        sources["advice"].stream({"t": t, "m": a[:, idx[med]], "lo": a[:, idx[lo]],
                                  "hi": a[:, idx[hi]]})
        if "risks" in sources:
            sources["risks"].stream({"t": t, **{c: a[:, idx[c]] for c in cols["risks"].values()}})
        state["advice"] = rows[-1]

    def build():
        cols = source.cols
        z = meta.get("tracked_z_cm") or []
        children = []
        for p in cols["params"]:
            children.append(band_figure(p, f"{p}: mean +- 2 sd", [p], [p],
                                        f"{p} ({_UNITS.get(p.rstrip('2'), '')})"))
        temps = cols["temps"]
        labels = [f"z = {10 * z[j]:.1f} mm" if j < len(z) else t for j, t in enumerate(temps)]
        children.append(band_figure("T", "temperatures below the surface: mean +- 2 sd",
                                    temps, labels, "deg C", width=480))
        if cols["drift"]:
            f = figure(title="P(optics drift while heated)", width=360, height=260,
                       y_range=(0, 1), x_axis_label="time (s)", toolbar_location=None)
            src = ColumnDataSource({"t": [], "w": []})
            f.line(x="t", y="w", source=src, line_width=2)
            sources["drift"], figs["drift"] = src, f
            children.append(f)
        plots.children = [row(*children[i:i + 3]) for i in range(0, len(children), 3)]
        state["built"] = True

    def stream(rows):
        h = source.header
        idx = {c: i for i, c in enumerate(h)}
        a = np.array(rows, dtype=float)
        t = a[:, idx["time_s"]]
        for p in source.cols["params"]:
            m, s = a[:, idx[f"{p}_mean"]], a[:, idx[f"{p}_std"]]
            sources[p].stream({"t": t, f"{p}_m": m, f"{p}_lo": m - _BAND * s,
                               f"{p}_hi": m + _BAND * s})
        upd = {"t": t}
        for n in source.cols["temps"]:
            m, s = a[:, idx[f"{n}_mean"]], a[:, idx[f"{n}_std"]]
            upd.update({f"{n}_m": m, f"{n}_lo": m - _BAND * s, f"{n}_hi": m + _BAND * s})
        sources["T"].stream(upd)
        if source.cols["drift"]:
            sources["drift"].stream({"t": t, "w": a[:, idx["drift_weight"]]})
        state["last"], state["n"] = a[-1], state["n"] + len(rows)

    def status_text(done: bool) -> str:
        last = state["last"]
        if last is None:
            return "<b>waiting for the first reading</b>"
        idx = {c: i for i, c in enumerate(source.header)}
        parts = [f"t = {last[idx['time_s']]:.2f} s", f"readings: {state['n']}"]
        parts += [f"{p} = {last[idx[p + '_mean']]:.4g} &plusmn; {2 * last[idx[p + '_std']]:.2g}"
                  for p in source.cols["params"]]
        if source.cols["drift"]:
            w = last[idx["drift_weight"]]
            parts.append(f"optics {'drifting' if w >= 0.5 else 'still'} while heated "
                         f"(P(drift) = {w:.2f})")
        if state["advice"] is not None:
            parts.append(advice_text(source.advice_header, state["advice"]))
        head = "<b>final estimate</b> (finished)" if done else "<b>running</b>"
        return head + " &middot; " + " &middot; ".join(parts)

    def poll():
        if parent is not None and os.getppid() != parent:  # the filter's process is gone
            from tornado.ioloop import IOLoop

            IOLoop.current().stop()
            return
        rows = source.new_rows()
        if rows and not state["built"] and source.cols is not None:
            build()
        if rows:
            stream(rows)
        adv = source.new_advice()
        if adv:
            if "advice" not in sources:
                build_advice()
            stream_advice(adv)
        fr = source.frame()
        if fr is not None:
            frame_src.data = {"image": [np.asarray(fr, float)]}
            finite = fr[np.isfinite(fr)]
            if finite.size:
                frame_map.low, frame_map.high = float(finite.min()), float(finite.max())
        rk = source.risk()
        if rk is not None:
            risk_src.data = {"image": [np.asarray(rk, float)]}
        done = source.finished()
        if rows or adv or done != state["done"]:
            status.text = status_text(done)
            state["done"] = done

    doc.add_periodic_callback(poll, POLL_MS)


def serve(run_dir: str | Path, port: int = 5006, replay_speed: float | None = None,
          parent: int | None = None, announce=print) -> None:
    """Serve the page of ``run_dir`` on ``localhost:port`` (0: a free port) until stopped;
    ``announce(url)`` once it listens."""
    from bokeh.server.server import Server

    from .frames import require

    require("bokeh", "the live page")

    def app(doc):
        make_document(doc, RunSource(run_dir, replay_speed), parent)

    if port == 0:  # a free port, known before the server starts (for its allowed origins)
        import socket

        with socket.socket() as sock:
            sock.bind(("127.0.0.1", 0))
            port = sock.getsockname()[1]
    server = Server({"/": app}, port=port, address="127.0.0.1", num_procs=1,
                    allow_websocket_origin=[f"127.0.0.1:{port}", f"localhost:{port}"])
    server.start()
    announce(f"http://127.0.0.1:{server.port}/")
    try:
        server.io_loop.start()
    finally:
        server.stop()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir")
    ap.add_argument("--port", type=int, default=5006)
    ap.add_argument("--replay", type=float, default=None, metavar="SPEED")
    ap.add_argument("--parent", type=int, default=None)
    args = ap.parse_args(argv)

    def announce(url):
        print(url, flush=True)
        devnull = os.open(os.devnull, os.O_WRONLY)  # nothing more on the pipe the parent
        os.dup2(devnull, sys.stdout.fileno())       # stops reading
    serve(args.run_dir, args.port, args.replay, args.parent, announce)
    return 0


if __name__ == "__main__":
    sys.exit(main())
