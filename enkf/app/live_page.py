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

The server looks every 20 ms whether the filter wrote a reading (the sizes of
``estimates.csv`` and ``advice.csv``) and then sends at once only what is new: the rows in
one ``stream`` of one data source for all the curves, the frame when a new one came (float32).
So the browser draws after the filter's step, while the filter waits for the next frame,
and the page shows a reading within 20 ms of its line; without readings it sends what
changed at least every 150 ms (the frames before the first reading, the risk map, the
run's end). Started by the filter (``--parent``), the server lowers its own priority
(``nice`` 10): the filter comes first.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from .live_source import BAND, POLL_MS, UNITS, WATCH_MS, RunSource, advice_columns, advice_text

__all__ = ["RunSource", "advice_columns", "advice_text", "make_document", "serve"]

TIME_SPAN_S = 5.0  #: the time axes reach the next multiple of this (s)
SPARE = 0.2  #: a range widens by this share of its span beyond the data

def make_document(doc, source: RunSource, parent: int | None = None) -> None:
    """Lay out the page in the bokeh document ``doc`` and poll ``source``."""
    from bokeh.layouts import column, row
    from bokeh.models import ColorBar, ColumnDataSource, Div, LinearColorMapper, Range1d
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
    # the optics and the temperatures: filled once the header is known; their curves share
    # one data source, so that a reading is one stream (one message, one change in the browser)
    series = ColumnDataSource({"t": []})
    sources: dict = {}
    figs = {}
    # the curves' axes: ranges the server widens in steps (Range1d), not ranges the browser
    # fits to the data at every reading (DataRange1d relabels the axes and lays the page out
    # again each time: most of the browser's work at 10 Hz)
    t_range = Range1d(0.0, TIME_SPAN_S)
    y_ranges: dict = {}  # figure key -> (Range1d, the columns it spans)
    fitted: set = set()  # the ids of the y ranges fitted to data at least once

    def band_figure(key, title, names, labels, y_label, width=360):
        y_range = Range1d(0.0, 1.0)
        f = figure(title=title, width=width, height=260, x_axis_label="time (s)",
                   y_axis_label=y_label, toolbar_location=None, x_range=t_range,
                   y_range=y_range)
        for n in names:
            series.data.update({f"{n}_m": [], f"{n}_lo": [], f"{n}_hi": []})
        y_ranges[key] = (y_range, [f"{n}_{k}" for n in names for k in ("lo", "hi")])
        src = series
        colours = Category10[10]
        for j, n in enumerate(names):
            c = colours[j % 10]
            f.varea(x="t", y1=f"{n}_lo", y2=f"{n}_hi", source=src, fill_color=c, fill_alpha=0.25)
            f.line(x="t", y=f"{n}_m", source=src, line_color=c, line_width=2)
        sources[key], figs[key] = src, f
        if len(names) == 1:  # the title names the one curve
            return f
        # several curves: their names once, in the page (a legend in the plot is drawn again
        # at every reading)
        key_text = " &nbsp; ".join(
            f"<span style='color:{colours[j % 10]}'>&#9644; {lab}</span>"
            for j, lab in enumerate(labels))
        return column(f, Div(text=key_text, width=width, styles={"font-size": "13px"}))

    plots = column(Div(text=""))
    advice_figs = column(Div(text=""))  # with advice.csv: when to stop, and the risks
    # the title and the status line are roots of their own: the status line's new text at
    # every reading then lays out only itself, not the plots
    doc.add_root(title)
    doc.add_root(status)
    doc.add_root(column(row(f_frame, f_risk), plots, advice_figs))
    doc.title = f"tissue-enkf: {source.dir.name}"
    state = {"last": None, "n": 0, "built": False, "done": False, "advice": None,
             "polled": -np.inf}

    def build_advice():
        cols = advice_columns(source.advice_header)
        q = cols["quantiles"]
        y_range = Range1d(0.0, 1.0)
        f = figure(title=f"when to stop the laser: median, {q[0]}%-{q[1]}%", width=420,
                   height=260, x_axis_label="time (s)", y_axis_label="stop at (s)",
                   toolbar_location=None, x_range=t_range, y_range=y_range)
        src = ColumnDataSource({"t": [], "m": [], "lo": [], "hi": []})
        f.varea(x="t", y1="lo", y2="hi", source=src, fill_color="green", fill_alpha=0.25)
        f.line(x="t", y="m", source=src, line_color="green", line_width=2)
        sources["advice"] = src
        y_ranges["advice"] = (y_range, ["lo", "hi", "m"])
        children = [f]
        if cols["risks"]:
            g = figure(title="risks under the plan", width=420, height=260, y_range=(0, 1),
                       x_axis_label="time (s)", y_axis_label="probability",
                       toolbar_location=None, x_range=t_range)
            rsrc = ColumnDataSource({"t": [], **{c: [] for c in cols["risks"].values()}})
            colours = ("magenta", "red")
            for j, c in enumerate(cols["risks"].values()):
                g.line(x="t", y=c, source=rsrc, line_width=2, line_color=colours[j % 2])
            sources["risks"] = rsrc
            key_text = " &nbsp; ".join(
                f"<span style='color:{colours[j % 2]}'>&#9644; {label}</span>"
                for j, label in enumerate(cols["risks"]))
            children.append(column(g, Div(text=key_text, width=420,
                                          styles={"font-size": "13px"})))
        advice_figs.children = [row(*children)]

    def stream_advice(rows):
        h = source.advice_header
        idx = {c: i for i, c in enumerate(h)}
        cols = advice_columns(h)
        a = np.array(rows, dtype=float)
        a[~np.isfinite(a)] = np.nan  # beyond the horizon: not drawn
        t = a[:, idx["time_s"]]
        med, lo, hi = cols["stop"]
        new = {"t": t, "m": a[:, idx[med]], "lo": a[:, idx[lo]], "hi": a[:, idx[hi]]}
        sources["advice"].stream(new)
        widen_time(t)
        widen(y_ranges["advice"], new)
        if "risks" in sources:
            sources["risks"].stream({"t": t, **{c: a[:, idx[c]] for c in cols["risks"].values()}})
        state["advice"] = rows[-1]

    def build():
        cols = source.cols
        z = meta.get("tracked_z_cm") or []
        children = []
        for p in cols["params"]:
            children.append(band_figure(p, f"{p}: mean +- 2 sd", [p], [p],
                                        f"{p} ({UNITS.get(p.rstrip('2'), '')})"))
        temps = cols["temps"]
        labels = [f"z = {10 * z[j]:.1f} mm" if j < len(z) else t for j, t in enumerate(temps)]
        children.append(band_figure("T", "temperatures below the surface: mean +- 2 sd",
                                    temps, labels, "deg C", width=480))
        if cols["drift"]:
            f = figure(title="P(optics drift while heated)", width=360, height=260,
                       y_range=(0, 1), x_axis_label="time (s)", toolbar_location=None,
                       x_range=t_range)
            series.data["w"] = []
            src = series
            f.line(x="t", y="w", source=src, line_width=2)
            sources["drift"], figs["drift"] = src, f
            children.append(f)
        plots.children = [row(*children[i:i + 3]) for i in range(0, len(children), 3)]
        state["built"] = True

    def stream(rows):
        h = source.header
        idx = {c: i for i, c in enumerate(h)}
        a = np.array(rows, dtype=float)
        upd = {"t": a[:, idx["time_s"]]}
        for n in source.cols["params"] + source.cols["temps"]:
            m, s = a[:, idx[f"{n}_mean"]], a[:, idx[f"{n}_std"]]
            upd.update({f"{n}_m": m, f"{n}_lo": m - BAND * s, f"{n}_hi": m + BAND * s})
        if source.cols["drift"]:
            upd["w"] = a[:, idx["drift_weight"]]
        series.stream(upd)
        widen_time(upd["t"])
        for key in source.cols["params"] + ["T"]:
            widen(y_ranges[key], upd)
        state["last"], state["n"] = a[-1], state["n"] + len(rows)

    def widen_time(t):
        """The time axis from the first reading's (a multiple of TIME_SPAN_S below it, so
        that a camera's clock far from 0 is seen) to the next multiple past the last."""
        t = t[np.isfinite(t)]
        if not t.size:
            return
        if id(t_range) not in fitted:
            fitted.add(id(t_range))
            t_range.start = TIME_SPAN_S * math.floor(t.min() / TIME_SPAN_S)
        if t.max() >= t_range.end:
            t_range.end = TIME_SPAN_S * (math.floor(t.max() / TIME_SPAN_S) + 1)

    def widen(entry, new):
        """Widen a curve's y range to hold ``new`` (columns -> values), with room to spare
        (SPARE of the span on the side it grows), so that it changes now and then."""
        rng, names = entry
        vals = np.concatenate([np.asarray(new[n], float).ravel() for n in names])
        vals = vals[np.isfinite(vals)]
        if not vals.size:
            return
        lo, hi = float(vals.min()), float(vals.max())
        first = id(rng) not in fitted
        if not first and rng.start <= lo and hi <= rng.end:
            return
        start, end = (lo, hi) if first else (min(rng.start, lo), max(rng.end, hi))
        pad = SPARE * max(end - start, 1e-6 * max(abs(start), abs(end), 1e-9))
        rng.update(start=start - pad if first or lo < rng.start else start,
                   end=end + pad if first or hi > rng.end else end)
        fitted.add(id(rng))

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
            frame_src.data = {"image": [np.asarray(fr, np.float32)]}  # as recorded
            finite = fr[np.isfinite(fr)]
            if finite.size:
                # the colour scale is refitted only when a frame leaves it or fills less than
                # half of it (a scale fitted to every frame relabels the colour bar at 10 Hz)
                lo, hi = float(finite.min()), float(finite.max())
                low, high = frame_map.low, frame_map.high
                if (low is None or lo < low or hi > high
                        or hi - lo < 0.5 * (high - low)):
                    pad = SPARE * max(hi - lo, 1e-6)
                    frame_map.update(low=lo - pad, high=hi + pad)
        rk = source.risk()
        if rk is not None:
            risk_src.data = {"image": [np.asarray(rk, float)]}
        done = source.finished()
        if rows or adv or done != state["done"]:
            status.text = status_text(done)
            state["done"] = done

    def watch():
        """Right after a reading (the browser then draws while the filter waits for the next
        frame), else at least every POLL_MS."""
        now = time.monotonic()
        if source.grew() or now - state["polled"] >= POLL_MS / 1e3:
            state["polled"] = now
            poll()

    doc.add_periodic_callback(watch, WATCH_MS)


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
    if args.parent is not None:  # the filter's page: the filter's steps come first
        os.nice(10)

    def announce(url):
        print(url, flush=True)
        devnull = os.open(os.devnull, os.O_WRONLY)  # nothing more on the pipe the parent
        os.dup2(devnull, sys.stdout.fileno())       # stops reading
    serve(args.run_dir, args.port, args.replay, args.parent, announce)
    return 0


if __name__ == "__main__":
    sys.exit(main())
