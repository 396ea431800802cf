"""What the live page reads from a run directory (:mod:`enkf.app.live_page`): the new lines
of estimates.csv and advice.csv as they grow, the latest frame and risk map, run.json's
state; no bokeh here."""

from __future__ import annotations

import csv
import json
import os
import re
import time
from pathlib import Path

import numpy as np

__all__ = ["BAND", "POLL_MS", "UNITS", "WATCH_MS", "RunSource", "advice_columns", "advice_text",
           "load_array"]

BAND = 2.0  #: the bands are mean +- 2 sd
UNITS = {"mua": "1/cm", "mus": "1/cm", "VHC": "J/(cm^3 K)", "TC": "W/(cm K)",
          "beam_radius": "cm"}
#: ms: how often the page's server looks whether a reading came (two ``stat`` calls)
WATCH_MS = 20
#: ms: the longest wait between two updates of the page when no reading comes (the frames
#: before the first reading, a filter behind the camera, the risk map, the run's end)
POLL_MS = 150


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
        self._sizes = None  # of estimates.csv and advice.csv, at the last grew()
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

    def grew(self) -> bool:
        """Whether a reading came since the last call: estimates.csv or advice.csv changed
        size (replay: the clock passed the next row's time)."""
        if self.speed is not None:
            return self.shown < len(self.rows) and self.rows[self.shown][0] <= self.now()
        sizes = []
        for name in ("estimates.csv", "advice.csv"):
            try:
                sizes.append(os.stat(self.dir / name).st_size)
            except OSError:
                sizes.append(-1)
        grew, self._sizes = sizes != self._sizes, sizes
        return grew

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
        return None if p is None else load_array(p)

    def risk(self) -> np.ndarray | None:
        if self.speed is not None and self.shown < len(self.rows):
            return None  # the recorded map is the run's last: shown at the end
        p = self._changed("risk.npy")
        return None if p is None else load_array(p)


def load_array(p: Path) -> np.ndarray | None:
    try:
        return np.load(p, allow_pickle=False)
    except (OSError, ValueError, EOFError):
        return None  # replaced while read: the next poll has it


# ---------------------------------------------------------------------- the page
