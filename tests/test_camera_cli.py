"""identify on a camera's files: a TIFF stack whose spot's centre is found in the first
frames, and --follow on a folder that a camera writes frames into."""

import json
import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from enkf.app.cli import main

tifffile = pytest.importorskip("tifffile")

EX = Path(__file__).parents[1] / "examples"
SPOT = (4.6, 3.2)  # column, row of the laser spot's centre in the frames
CAMERA = """
[sensors]
positions = []
rate = 10.0

[sensors.camera]
shape = [8, 8]
pixel_size = 0.03
spot_center = {spot}
rotation = 2.0
"""


def camera_config(tmp_path, spot='"auto"') -> Path:
    text = (EX / "tiny.toml").read_text()
    head, tail = text.split("[sensors]", 1)
    tail = tail.split("[filter]", 1)[1]
    cfg = tmp_path / "camera.toml"
    cfg.write_text(head + CAMERA.format(spot=spot) + "\n[filter]" + tail)
    return cfg


def frames(n=12, seed=0) -> np.ndarray:
    """(n, 8, 8) deg C: a spot that warms for 1 s and then cools, with 0.1 deg C noise (a
    stand-in for the model's image: the test is of the files and the registration)."""
    y, x = np.mgrid[:8, :8]
    shape = np.exp(-((x - SPOT[0]) ** 2 + (y - SPOT[1]) ** 2) / 12.0)
    t = 0.1 * np.arange(n)
    amp = 5.5 * np.minimum(t, 1.0) - 1.5 * np.maximum(t - 1.0, 0.0)  # as tiny_data.csv
    rng = np.random.default_rng(seed)
    return amp[:, None, None] * shape + 0.1 * rng.standard_normal((n, 8, 8))


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("emulator-cache"))


def follow_while_writing(writer, cfg, follow, out, cache) -> None:
    """``identify --follow FOLLOW`` while ``writer()`` writes the camera's output in a
    thread (it ends the stream itself, with ``END``); exit 0."""
    th = threading.Thread(target=writer)
    th.start()
    try:
        assert run("identify", cfg, "--follow", follow, "--out", out, "--quiet", "--cache-dir",
                   cache, "--idle-timeout", "5") == 0
    finally:
        th.join()


def run(*argv):
    return main([str(a) for a in argv])


def test_identify_a_tiff_stack_finds_the_spot(tmp_path, cache):
    cfg = camera_config(tmp_path)
    tifffile.imwrite(tmp_path / "stack.tif", frames().astype("f4"), imagej=True,
                     metadata={"finterval": 0.1, "axes": "TYX"})
    out = tmp_path / "id"
    assert run("identify", cfg, "--data", tmp_path / "stack.tif", "--out", out, "--quiet",
               "--cache-dir", cache) == 0
    s = json.loads((out / "summary.json").read_text())
    col, row = s["camera"]["spot_center_px"]
    assert abs(col - SPOT[0]) < 0.2 and abs(row - SPOT[1]) < 0.2
    rows = (out / "estimates.csv").read_text().splitlines()
    # the prior at t = 0, then 11 frames: the first is the baseline at the laser's start
    assert len(rows) == 1 + 1 + 11 and rows[2].startswith("0.1,")


def test_a_camera_outside_the_tissue_is_refused(tmp_path, cache, capsys):
    cfg = camera_config(tmp_path, spot="[-5.0, 3.0]")
    assert run("identify", cfg, "--data", tmp_path / "x.tif", "--out", tmp_path / "o") == 2
    err = capsys.readouterr().err
    assert "sensors.camera with the spot's centre at column -5.00" in err and "outside" in err


def test_follow_a_folder_as_the_camera_writes_it(tmp_path, cache, capsys):
    cfg = camera_config(tmp_path)
    live = tmp_path / "camera"
    f = frames(14)

    def writer():
        time.sleep(0.3)
        live.mkdir()
        for k, frame in enumerate(f):
            name = live / f"frame{k}.tif"
            if k == 6:  # written in place, slowly: read once it is whole
                data = _tiff_bytes(frame)
                with open(name, "wb") as fh:
                    fh.write(data[:100])
                    fh.flush()
                    time.sleep(0.3)
                    fh.write(data[100:])
            else:  # the usual way: a hidden temporary renamed into place
                tmp = live / f".frame{k}.tif.tmp"
                tmp.write_bytes(_tiff_bytes(frame))
                os.replace(tmp, name)
            if k == 9:
                (live / "frame9b.tif").write_bytes(b"II*\x00 damaged")  # never readable
            time.sleep(0.05)
        (live / "END").write_text("")

    out = tmp_path / "follow"
    follow_while_writing(writer, cfg, live, out, cache)
    rows = (out / "estimates.csv").read_text().splitlines()
    assert len(rows) == 1 + 13  # frame 0 is the baseline
    times = [float(r.split(",")[0]) for r in rows[1:]]
    np.testing.assert_allclose(times, 0.1 * np.arange(1, 14), atol=1e-9)
    man = json.loads((out / "run.json").read_text())
    assert man["readings"] == 13 and man["skipped_lines"] == 1
    assert "frame9b.tif" in man["skipped"][0]["line"]
    col, row = man["camera"]["spot_center_px"]
    assert abs(col - SPOT[0]) < 0.3 and abs(row - SPOT[1]) < 0.3
    assert "frame9b.tif" in capsys.readouterr().err


def _tiff_bytes(frame) -> bytes:
    import io

    buf = io.BytesIO()
    tifffile.imwrite(buf, frame.astype("f4"))
    return buf.getvalue()


def test_a_binned_camera_reads_super_pixels(tmp_path, cache, capsys):
    """sensors.camera.binning = 2: the 8 x 8 frames are read as 4 x 4 block means (the
    filter's readings), the spot's centre still found in the camera's own pixels; a
    binning that does not divide the frames is refused."""
    cfg = camera_config(tmp_path)
    cfg.write_text(cfg.read_text().replace("rotation = 2.0", "rotation = 2.0\nbinning = 2"))
    tifffile.imwrite(tmp_path / "stack.tif", frames().astype("f4"), imagej=True,
                     metadata={"finterval": 0.1, "axes": "TYX"})
    out = tmp_path / "id"
    assert run("identify", cfg, "--data", tmp_path / "stack.tif", "--out", out, "--quiet",
               "--cache-dir", cache) == 0
    s = json.loads((out / "summary.json").read_text())
    col, row = s["camera"]["spot_center_px"]
    assert abs(col - SPOT[0]) < 0.2 and abs(row - SPOT[1]) < 0.2
    cfg.write_text(cfg.read_text().replace("binning = 2", "binning = 3"))
    assert run("identify", cfg, "--data", tmp_path / "stack.tif", "--out", tmp_path / "bad",
               "--quiet", "--cache-dir", cache) == 2
    assert "sensors.camera.binning must divide the shape [8, 8]" in capsys.readouterr().err


def test_a_flir_sequence_is_refused_on_the_command_line_with_exit_2(tmp_path, cache, capsys):
    cfg = camera_config(tmp_path)
    seq = tmp_path / "run.seq"
    seq.write_bytes(b"FFF\x00" + bytes(64))
    out = tmp_path / "o"
    assert run("identify", cfg, "--data", seq, "--out", out, "--quiet") == 2
    assert "FLIR sequences (.seq, .csq) are not read here" in capsys.readouterr().err
    assert not out.exists()
