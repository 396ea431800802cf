"""``identify --follow FILE`` on one camera file that grows (enkf.app.follow_file): a TIFF
stack whose pages are appended and an HDF5 file whose ``frames`` are resized, written at
~100 Hz while the follower reads them; every frame assimilated, in order."""

import json
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from test_camera_cli import EX, SPOT, camera_config, follow_while_writing, frames, run
from test_follow_frames import SlowIdentifier

from enkf.app.follow_file import follow_file
from enkf.app.frames import read_frames

tifffile = pytest.importorskip("tifffile")
h5py = pytest.importorskip("h5py")

RATE = 100.0  # Hz, the writers'


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("emulator-cache"))


def _frame(k, shape=(4, 4)):
    return np.full(shape, 20.0 + k, "f4")


def _follow(path, ident, names, **kw):
    skipped = []
    kw = {"idle_timeout_s": 5.0, "settle_s": 0.3, **kw}
    count = follow_file(path, lambda times, frames, final=False: ident,
                        lambda est, name: names.append(name), skipped=skipped,
                        warn=lambda message: None, **kw)
    return count, skipped


def _write_tiff(path, n, times=True, bad=None):
    """A camera at RATE Hz appending a page a frame (tifffile's metadata holds its time
    when ``times``), then END beside it; ``bad``: {k: frame} written instead."""
    with tifffile.TiffWriter(path) as tw:
        for k in range(n):
            frame = (bad or {}).get(k, _frame(k))
            tw.write(frame, photometric="minisblack",
                     metadata={"times": [k / RATE]} if times else None)
            time.sleep(1.0 / RATE)
    (path.parent / "END").write_text("")


@pytest.mark.parametrize("times", [True, False])
def test_a_growing_tiff_stack_is_assimilated_frame_by_frame(tmp_path, times):
    # the filter lags behind the camera (and pauses once, as at a smoother's restart)
    n = 40
    ident, names = SlowIdentifier(step_s=0.012, pause_at=5, pause_s=0.2), []
    path = tmp_path / "stack.tif"
    th = threading.Thread(target=_write_tiff, args=(path, n, times))
    th.start()
    try:
        count, skipped = _follow(path, ident, names, rate=RATE)
    finally:
        th.join()
    assert count == n - 1 and not skipped  # all but the baseline frame (t = 0)
    assert names == [f"stack.tif frame {k}" for k in range(1, n)]
    np.testing.assert_allclose(ident.history, np.arange(1, n) / RATE)


def test_frames_of_another_shape_or_all_nan_are_skipped(tmp_path):
    n = 12
    ident, names = SlowIdentifier(step_s=0.0), []
    path = tmp_path / "stack.tif"
    bad = {4: _frame(4, (5, 4)), 7: np.full((4, 4), np.nan, "f4")}
    th = threading.Thread(target=_write_tiff, args=(path, n, True, bad))
    th.start()
    try:
        count, skipped = _follow(path, ident, names)
    finally:
        th.join()
    assert count == n - 3
    assert skipped == [("stack.tif frame 4", "a frame of (5, 4) pixels, the first frame's (4, 4)"),
                       ("stack.tif frame 7", "every pixel of the frame at 0.07 s is NaN")]
    np.testing.assert_allclose(ident.history, [k / RATE for k in range(1, n) if k not in bad])


def test_a_stack_rewritten_and_renamed_at_each_frame_is_read_on(tmp_path):
    # a camera that writes the whole stack anew beside the file and renames it into place:
    # each version is read from the frame after the last one read, after one warning
    n = 15
    path = tmp_path / "stack.tif"
    stack = np.stack([_frame(k) for k in range(n)])

    def writer():
        for k in range(n):
            tifffile.imwrite(tmp_path / ".stack.tmp", stack[:k + 1], photometric="minisblack",
                             metadata={"times": list(np.arange(k + 1) / RATE)})
            os.replace(tmp_path / ".stack.tmp", path)
            time.sleep(2.0 / RATE)
        (tmp_path / "END").write_text("")

    ident, names, warnings = SlowIdentifier(step_s=0.0), [], []
    th = threading.Thread(target=writer)
    th.start()
    try:
        count = follow_file(path, lambda times, frames, final=False: ident,
                            lambda est, name: names.append(name), idle_timeout_s=5.0,
                            warn=warnings.append)
    finally:
        th.join()
    assert count == n - 1 and names == [f"stack.tif frame {k}" for k in range(1, n)]
    np.testing.assert_allclose(ident.history, np.arange(1, n) / RATE)
    assert len(warnings) == 1 and "was replaced after frame" in warnings[0]


_H5_WRITER = """
import sys, time
import h5py, numpy as np
path, n, rate, mode = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
if mode == "swmr":  # the datasets made first, then SWMR: the reader sees each flush
    f = h5py.File(path, "w", libver="latest")
    d = f.create_dataset("frames", (0, 4, 4), "f4", maxshape=(None, 4, 4), chunks=(1, 4, 4))
    t = f.create_dataset("times", (0,), "f8", maxshape=(None,), chunks=(256,))
    f.swmr_mode = True
    for k in range(n):
        d.resize(k + 1, axis=0)
        d[k] = 20.0 + k
        t.resize(k + 1, axis=0)  # the time after its frame: the frame waits for it
        t[k] = k / rate
        f.flush()
        time.sleep(1 / rate)
    f.close()
else:  # opened, appended to and closed at every frame; the times from attribute 'rate'
    for k in range(n):
        with h5py.File(path, "a") as f:
            if "frames" not in f:
                f.create_dataset("frames", (0, 4, 4), "f4", maxshape=(None, 4, 4),
                                 chunks=(1, 4, 4)).attrs["rate"] = rate
            d = f["frames"]
            d.resize(k + 1, axis=0)
            d[k] = 20.0 + k
        time.sleep(1 / rate)
open(path.rsplit("/", 1)[0] + "/END", "w").close()
"""


@pytest.mark.parametrize("mode", ["swmr", "reopened"])
def test_a_growing_hdf5_file_is_assimilated_frame_by_frame(tmp_path, mode):
    # the camera is another process: HDF5 in one process shares one open file between its
    # writer and its reader, which is not what a camera's file is
    n = 40
    ident, names = SlowIdentifier(step_s=0.012, pause_at=5, pause_s=0.2), []
    path = tmp_path / "frames.h5"
    writer = subprocess.Popen([sys.executable, "-c", _H5_WRITER, str(path), str(n), str(RATE),
                               mode])
    try:
        count, skipped = _follow(path, ident, names)
    finally:
        assert writer.wait(timeout=30) == 0
    assert count == n - 1 and not skipped
    assert names == [f"frames.h5 frame {k}" for k in range(1, n)]
    np.testing.assert_allclose(ident.history, np.arange(1, n) / RATE)
    # the finished file, read whole (identify --data, replay), gives the same frames
    series = read_frames(path)
    np.testing.assert_allclose(series.times, np.arange(n) / RATE)
    np.testing.assert_array_equal(series.frames[:, 0, 0], 20.0 + np.arange(n))


def _tiff_bytes(n) -> bytes:
    import io

    buf = io.BytesIO()
    with tifffile.TiffWriter(buf) as tw:
        for k in range(n):
            tw.write(_frame(k, (16, 16)), photometric="minisblack")
    return buf.getvalue()


@pytest.mark.parametrize("name, data, message", [
    ("x.tif", b"time,T1\n0,20\n", "x.tif: not a readable TIFF file"),
    ("x.tif", _tiff_bytes(1)[:200], "x.tif: not a readable TIFF file"),
    ("x.h5", b"\x89HDF\r\n\x1a\n" + bytes(100), "x.h5: not a readable HDF5 file"),
])
def test_a_file_that_is_not_a_camera_file_is_refused(tmp_path, name, data, message):
    (tmp_path / name).write_bytes(data)
    t0 = time.monotonic()
    with pytest.raises(ValueError, match=message):
        _follow(tmp_path / name, SlowIdentifier(0.0), [], rate=RATE, settle_s=0.2)
    assert time.monotonic() - t0 < 2.0  # once it stopped changing for settle_s


def test_a_truncated_stack_keeps_its_whole_frames(tmp_path):
    # a writer that stopped half way through a page: the frames before it are assimilated,
    # the rest is reported when the stream ends
    data = _tiff_bytes(6)
    path = tmp_path / "cut.tif"
    path.write_bytes(data[:len(data) - 700])
    ident, names = SlowIdentifier(0.0), []
    count, skipped = _follow(path, ident, names, rate=RATE, idle_timeout_s=0.5)
    assert count == len(names) >= 3 and names[0] == "cut.tif frame 1"
    assert len(skipped) == 1 and skipped[0][0] == f"cut.tif frame {count + 1}"
    assert "could not be read when the stream ended" in skipped[0][1]


@pytest.mark.parametrize("name, message", [
    ("IR_1.jpg", "a .jpg file is not followed as it grows"),
    ("frames.npz", "a .npz file is not followed as it grows"),
    ("run.seq", r"FLIR sequences \(.seq, .csq\) are not read here"),
])
def test_single_frame_files_are_sent_to_their_folder(tmp_path, name, message):
    with pytest.raises(ValueError, match=message):
        _follow(tmp_path / name, SlowIdentifier(0.0), [])


def test_identify_follows_a_growing_tiff_stack(tmp_path, cache):
    """The command line: the spot's centre found in the first frames of the growing file,
    every frame after the baseline assimilated."""
    cfg = camera_config(tmp_path)
    path = tmp_path / "camera" / "stack.tif"
    path.parent.mkdir()
    f = frames(14)

    def writer():
        with tifffile.TiffWriter(path) as tw:
            for k, frame in enumerate(f):
                tw.write(frame.astype("f4"), photometric="minisblack",
                         metadata={"times": [0.1 * k]})
                time.sleep(0.03)
        (path.parent / "END").write_text("")

    out = tmp_path / "follow"
    follow_while_writing(writer, cfg, path, out, cache)
    rows = (out / "estimates.csv").read_text().splitlines()
    times = [float(r.split(",")[0]) for r in rows[1:]]
    np.testing.assert_allclose(times, 0.1 * np.arange(1, 14), atol=1e-9)
    man = json.loads((out / "run.json").read_text())
    assert man["readings"] == 13 and man["skipped_lines"] == 0
    col, row = man["camera"]["spot_center_px"]
    assert abs(col - SPOT[0]) < 0.3 and abs(row - SPOT[1]) < 0.3
    # the finished stack, read whole (identify --data, replay): each page's time in order
    np.testing.assert_allclose(read_frames(path).times, 0.1 * np.arange(14), atol=1e-12)


@pytest.mark.parametrize("camera, message", [
    (True, "stack.tif: not a readable TIFF file"),
    (False, "stack.tif: camera frames: the config needs [sensors.camera] and no point sensors"),
])
def test_identify_refuses_with_exit_2_and_writes_nothing(tmp_path, cache, capsys, camera,
                                                         message):
    # a damaged file; frames for a config of point sensors
    cfg = camera_config(tmp_path) if camera else EX / "tiny.toml"
    path = tmp_path / "stack.tif"
    path.write_bytes(_tiff_bytes(1)[:200])
    out = tmp_path / "o"
    assert run("identify", cfg, "--follow", path, "--out", out, "--quiet", "--cache-dir",
               cache, "--idle-timeout", "5") == 2
    assert message in capsys.readouterr().err
    assert not out.exists()
