"""What the filter hands to the live page of ``identify --follow FILE --serve``; its process.

The page is served by another process (:mod:`enkf.app.live_page`, bokeh), so that drawing
never takes the filter's time nor its interpreter: the filter writes what the page shows
into ``--out`` and goes on. Besides ``estimates.csv`` (written at every reading anyway)
it writes, each replaced atomically (written beside, then renamed):

- ``live/meta.json``: the parameters' names, the depths of the tracked temperatures, the
  camera's extent and the risk map's axes (once);
- ``live/frame.npy``: the latest frame (ny, nx) deg C, at most every ``frame_every_s``;
- ``live/risk.npy``: the probability of injury (damage integral > 1, MCmatlab's
  Arrhenius law for the estimated medium; without its ``E`` and ``A``: of having been
  above 60 deg C) on the x-z plane through the beam, from the members' temperatures
  (:class:`enkf.tissue.risk.RiskTracker`), at most every ``risk_every_s`` and at the end.

The same files make ``tissue-enkf replay RUN_DIR`` show a recorded run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["LiveRecorder", "start_page"]

#: deg C: the map's threshold for a medium without Arrhenius parameters (RiskTracker's)
T_INJURY = 60.0


def _atomic_save(path: Path, array: np.ndarray) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:
        np.save(fh, np.asarray(array, dtype=np.float32), allow_pickle=False)
    os.replace(tmp, path)


def write_json_atomic(path: Path, value) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(value))
    os.replace(tmp, path)


class LiveRecorder:
    """Writes the live page's files into ``out/live`` as the filter runs."""

    def __init__(self, out: Path, setup, medium=None, *, frame_every_s: float = 0.05,
                 risk_every_s: float = 0.5):
        self.dir = Path(out) / "live"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.frame_every_s, self.risk_every_s = frame_every_s, risk_every_s
        self._last_frame = self._last_risk = -np.inf
        self.tracker = self._ever = None
        self.setup = setup
        if medium is not None and medium.E and medium.A:
            from ..tissue.risk import RiskTracker

            self.tracker = RiskTracker(E=medium.E, A=medium.A, record_every=10**9)
        self.write_meta(setup)

    def write_meta(self, setup) -> None:
        grid = setup.grid
        meta = {"names": list(setup.parameters.names),
                "tracked_z_cm": [float(p[2]) for p in setup.sensors.tracked],
                "risk_extent_cm": [-grid.Lx / 2, grid.Lx / 2, 0.0, grid.Lz],
                "risk": "P(damage integral > 1)" if self.tracker else
                f"P(T > {T_INJURY:g} deg C so far)",
                "drift": setup.parameters.drift is not None, "started": time.time()}
        if setup.sensors.image is not None:
            # in the image's own axes, from the beam's axis (turned by its rotation)
            (x0, x1), (y0, y1) = setup.sensors.image.x_range, setup.sensors.image.y_range
            meta.update(frame_shape=[int(v) for v in setup.sensors.image.shape],
                        frame_extent_cm=[x0, x1, y0, y1], rotation=setup.sensors.image.rotation)
        write_json_atomic(self.dir / "meta.json", meta)

    def frame(self, t: float, frame: np.ndarray) -> None:
        """A frame just read (``on_frame`` of the folder follower)."""
        now = time.monotonic()
        if now - self._last_frame >= self.frame_every_s:
            _atomic_save(self.dir / "frame.npy", frame)
            self._last_frame = now

    def reading(self, t: float, identifier) -> None:
        """After a reading is assimilated: the members' damage so far (a medium without
        Arrhenius parameters: whether each member's node has been above 60 deg C)."""
        X = identifier.state_ensemble
        if self.tracker is not None:
            self.tracker.update(t, X)
        else:
            hot = X > T_INJURY
            self._ever = hot if self._ever is None or self._ever.shape != hot.shape \
                else self._ever | hot
        now = time.monotonic()
        if now - self._last_risk >= self.risk_every_s:
            self.write_risk()
            self._last_risk = now

    def write_risk(self) -> None:
        from ..tissue.risk import xz_slice

        if self.tracker is not None and self.tracker.omega is not None:
            p = (self.tracker.omega > self.tracker.omega_threshold).mean(axis=0)
        elif self._ever is not None:
            p = self._ever.mean(axis=0)
        else:
            return
        _atomic_save(self.dir / "risk.npy", xz_slice(p, self.setup.grid))


def start_page(run_dir: Path, port: int) -> tuple[subprocess.Popen, str]:
    """Start the live page's server process on ``run_dir``; ``(process, url)``.

    The server prints its address when it listens; it ends when its parent does."""
    cmd = [sys.executable, "-m", "enkf.app.live_page", str(run_dir), "--port", str(port),
           "--parent", str(os.getpid())]
    log = Path(run_dir) / "live" / "server.log"
    with open(log, "w") as err:  # the server's messages; stdout gives only its address
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, text=True,
                                process_group=0)  # its own process group: Ctrl-C reaches the filter only
    line = proc.stdout.readline().strip()
    if not line.startswith("http"):
        proc.kill()
        proc.wait()
        raise ValueError(f"--serve: the live page did not start: {line or log.read_text()[-300:]}")
    return proc, line
