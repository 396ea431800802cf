"""``identify --follow FOLDER`` (enkf.app.follow_frames): every frame the camera writes is
assimilated, however far the filter lags behind the camera."""

import os
import threading
import time
from types import SimpleNamespace

import numpy as np

from enkf.app.follow_frames import follow_folder


class SlowIdentifier:
    """The parts of an OnlineIdentifier that ``follow_folder`` uses; each update takes
    ``step_s`` (one, a smoother's restart, ``pause_s``), so the camera gets ahead."""

    def __init__(self, step_s, pause_at=None, pause_s=0.0):
        self.time, self.history = 0.0, []
        self.step_s, self.pause_at, self.pause_s = step_s, pause_at, pause_s
        self.setup = SimpleNamespace(sensors=SimpleNamespace(
            image=SimpleNamespace(readings=lambda frame: frame.ravel())))

    def update(self, t, readings):
        time.sleep(self.pause_s if len(self.history) == self.pause_at else self.step_s)
        self.time = t
        self.history.append(t)
        return SimpleNamespace(time=t)


def _write(folder, n, rate):
    """A camera at ``rate`` Hz: each frame written beside and renamed into place, then
    END right after the last."""
    import tifffile

    for k in range(n):
        tmp = folder / f".f{k}.tmp"
        tifffile.imwrite(tmp, np.full((4, 4), 20.0 + k, "f4"), photometric="minisblack")
        os.replace(tmp, folder / f"f{k:04d}.tif")
        time.sleep(1.0 / rate)
    (folder / "END").write_text("")


def test_follow_folder_assimilates_every_frame_when_the_filter_lags(tmp_path):
    # the filter is slower than the camera (and pauses once, as at a smoother's restart):
    # the frames that arrive while it works, up to the END marker, are all read
    n, rate = 30, 100.0
    ident = SlowIdentifier(step_s=0.03, pause_at=5, pause_s=0.3)
    names = []
    th = threading.Thread(target=_write, args=(tmp_path, n, rate))
    th.start()
    try:
        count = follow_folder(tmp_path, lambda times, frames, final=False: ident,
                              lambda est, name: names.append(name), rate=rate,
                              idle_timeout_s=5.0)
    finally:
        th.join()
    assert count == n - 1  # all but the baseline frame (t = 0)
    assert names == [f"f{k:04d}.tif" for k in range(1, n)]
    np.testing.assert_allclose(ident.history, np.arange(1, n) / rate)
