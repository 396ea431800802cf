"""Odd files and live streams (issue 51): no hang, bounded memory, a clear refusal.

Pipes, FIFOs and devices as data, config or followed file are refused before they are
read (a FIFO without a writer used to hang, ``/dev/zero`` to fill the memory, a pipe to
be read twice); an NPZ whose header declares a huge shape, and a zip bomb, are refused
from their headers before anything is unpacked; a CSV or config too large for the
memory is refused before it is read. In a ``--follow`` stream a bad line is skipped and
reported with its number, a clock that restarts in a replaced file stops the stream
naming the file and line, and a last line the writer never finished is reported.
"""

from __future__ import annotations

import io
import json
import os
import threading
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

import mcmatlab_py.budget as budget
import mcmatlab_py.config as mconfig
from enkf.app.cli import main
from enkf.app.readers import follow_csv, load_frames, read_sensor_csv
from enkf.tissue import OnlineIdentifier
from mcmatlab_py.config import ConfigError, read_toml
from mcmatlab_py.files import npz_headers, open_regular

EX = Path(__file__).parents[1] / "examples"
DATA = (EX / "tiny_data.csv").read_text().splitlines()  # header, then 20 readings


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("emulator-cache"))


def run(*argv) -> int:
    return main([str(a) for a in argv])


def one_error_line(capsys, *needles) -> str:
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    for n in needles:
        assert n in err, err
    return err


@pytest.fixture
def fifo(tmp_path):
    """A named FIFO that no program writes to. Should a reader block on it, a guard opens
    it for writing after a while (the reader then sees its end) and the test fails."""
    path = tmp_path / "fifo"
    os.mkfifo(path)
    done, hung = threading.Event(), []

    def guard():
        if not done.wait(60):
            hung.append(True)
            os.close(os.open(path, os.O_WRONLY))
    th = threading.Thread(target=guard, daemon=True)
    th.start()
    yield path
    done.set()
    th.join()
    assert not hung, "a reader waited on the FIFO"


# ------------------------------------------------------------- not a regular file

@pytest.mark.parametrize("what", ["data", "config"])
def test_a_fifo_is_refused_without_waiting_for_a_writer(tmp_path, capsys, fifo, what):
    out = tmp_path / "out"
    argv = (["identify", fifo, "--data", EX / "tiny_data.csv"] if what == "config" else
            ["identify", EX / "tiny.toml", "--data", fifo])
    assert run(*argv, "--out", out, "--quiet") == 2
    one_error_line(capsys, f"{str(fifo)!r} is a pipe or FIFO, not a regular file")
    assert not out.exists()


def test_a_followed_fifo_is_refused(tmp_path, tissue, fifo):
    with pytest.raises(ValueError, match="is a pipe or FIFO, not a regular file"):
        follow_csv(fifo, OnlineIdentifier(tissue.setup()), lambda *a: None, idle_timeout_s=1)


def test_a_pipe_is_refused_not_read_twice(tmp_path, capsys):
    """``--data <(cat file)`` and ``--data /dev/stdin`` fed by a pipe: /dev/fd/N of a pipe."""
    r, w = os.pipe()
    try:
        os.write(w, "\n".join(DATA).encode())
        os.close(w)
        assert run("identify", EX / "tiny.toml", "--data", f"/dev/fd/{r}", "--out",
                   tmp_path / "out") == 2
    finally:
        os.close(r)
    one_error_line(capsys, f"'/dev/fd/{r}' is a pipe or FIFO", "save it to a file first")


@pytest.mark.parametrize("what", ["data", "config"])
def test_dev_zero_is_refused_before_it_is_read(tmp_path, capsys, what):
    argv = (["identify", "/dev/zero", "--data", EX / "tiny_data.csv"] if what == "config"
            else ["identify", EX / "tiny.toml", "--data", "/dev/zero"])
    assert run(*argv, "--out", tmp_path / "out") == 2
    one_error_line(capsys, "'/dev/zero' is a character device, not a regular file")


def test_a_directory_is_refused_naming_it(tmp_path):
    with pytest.raises(ValueError, match="is a directory, not a regular file"):
        read_sensor_csv(tmp_path, 1)
    with pytest.raises(ConfigError, match="config file .* is a directory"):
        read_toml(tmp_path)


# ------------------------------------------------------------- too large

def test_a_csv_the_memory_cannot_hold_is_refused_before_it_is_read(tmp_path, monkeypatch):
    p = tmp_path / "long.csv"
    p.write_text("\n".join(DATA) + "\n")
    monkeypatch.setattr(budget, "available_memory", lambda: 1000)
    with pytest.raises(ValueError, match=rf"data file '{p}' \(.*\) needs about .* of memory"):
        read_sensor_csv(p, 1)


def test_a_config_over_the_limit_is_refused(tmp_path, monkeypatch):
    p = tmp_path / "big.toml"
    p.write_text((EX / "tiny.toml").read_text() + "\n" + "# padding\n" * 100)
    monkeypatch.setattr(mconfig, "MAX_CONFIG_BYTES", 1000)
    with pytest.raises(ConfigError, match=rf"config file '{p}' is .* more than the 1 kB"):
        read_toml(p)


def _npz_with_member(path: Path, name: str, npy: bytes, compress=zipfile.ZIP_STORED):
    with zipfile.ZipFile(path, "w", compression=compress) as zf:
        buf = io.BytesIO()
        np.lib.format.write_array(buf, np.linspace(0.1, 1.0, 10))
        zf.writestr("times.npy", buf.getvalue())
        zf.writestr(name + ".npy", npy)


def _no_unpacking(monkeypatch):
    def refuse(*a, **kw):
        raise AssertionError("np.load was called")
    monkeypatch.setattr(np, "load", refuse)


def test_an_npz_header_declaring_a_huge_shape_is_refused_from_the_header(tmp_path,
                                                                         monkeypatch):
    buf = io.BytesIO()  # 48 TB declared, 80 bytes stored
    np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False,
                                                "shape": (10, 2_400_000, 250_000)})
    p = tmp_path / "liar.npz"
    _npz_with_member(p, "frames", buf.getvalue() + bytes(80))
    _no_unpacking(monkeypatch)
    with pytest.raises(ValueError, match=r"array 'frames' declares shape \(10, 2400000, "
                                         r"250000\) \(48 TB\), but the file holds 80 B"):
        load_frames(p)


def test_a_zip_bomb_is_refused_before_it_is_unpacked(tmp_path, monkeypatch):
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.zeros((10, 1000, 800)))  # 64 MB of zeros
    p = tmp_path / "bomb.npz"
    _npz_with_member(p, "frames", buf.getvalue(), compress=zipfile.ZIP_DEFLATED)
    assert p.stat().st_size < 200_000
    monkeypatch.setattr(budget, "available_memory", lambda: 100_000_000)
    _no_unpacking(monkeypatch)
    with pytest.raises(ValueError, match=rf"data file '{p}' \(64 MB of arrays once unpacked\) "
                                         r"needs about 192 MB of memory"):
        load_frames(p)


def test_npz_headers_read_an_honest_archive(tmp_path):
    p = tmp_path / "ok.npz"
    np.savez_compressed(p, times=np.arange(3.0), frames=np.zeros((3, 2, 4), np.float32))
    h = npz_headers(p, "data file")
    assert h["times"][:2] == ((3,), np.dtype(float)) and h["frames"][:2] == (
        (3, 2, 4), np.dtype(np.float32))
    with open_regular(p, "data file") as fh:
        assert fh.read(2) == b"PK"


# ------------------------------------------------------------- --follow

def _lines(times, ys):
    return "".join(f"{t:.3f},{y:.4f}\n" for t, y in zip(times, ys, strict=True))


def test_bad_lines_in_a_stream_are_skipped_and_reported(tmp_path, tissue):
    s = tissue.setup()
    times, data = tissue.twin_data(s, 1.4, 100.0)
    p = tmp_path / "live.csv"
    good = _lines(times[:6], data[:6, 0]).splitlines()
    p.write_bytes(("time,sensor_0\n" + good[0] + "\nabc,def\n" + good[1] + "\ninf,37\n"
                   + "nan,37\n" + good[2] + "\n" + "1" * 5_000_000 + "\n" + good[3] + "\n"
                   + "0.05,37\n" + good[4] + "\n").encode() + b"\xff\xfe,1\n"
                  + (good[5] + "\n# end\n").encode())
    skipped, warned, seen = [], [], []
    n = follow_csv(p, OnlineIdentifier(s), lambda est, line: seen.append(line),
                   idle_timeout_s=2.0, warn=warned.append, skipped=skipped)
    assert n == 6 and seen == [2, 4, 7, 9, 11, 13]
    assert [line for line, _ in skipped] == [3, 5, 6, 8, 10, 12]
    reasons = dict(skipped)
    assert "field 1 is not a number: 'abc'" in reasons[3]
    assert "time must be a finite number" in reasons[5] and "finite" in reasons[6]
    assert "longer than 4224 bytes" in reasons[8]
    assert "time 0.05 s is not after the last reading's" in reasons[10]
    assert reasons[12] == "not UTF-8 text"
    assert len(warned) == 6 and all(f"{p}:" in w and "line skipped" in w for w in warned)


def test_only_the_first_skipped_lines_are_shown(tmp_path, tissue):
    from enkf.app.readers import SHOWN_SKIPS

    p = tmp_path / "live.csv"
    p.write_text("time,sensor_0\n" + "x,1\n" * (SHOWN_SKIPS + 5) + "# end\n")
    skipped, warned = [], []
    assert follow_csv(p, OnlineIdentifier(tissue.setup()), lambda *a: None,
                      idle_timeout_s=2.0, warn=warned.append, skipped=skipped) == 0
    assert len(skipped) == SHOWN_SKIPS + 5 and len(warned) == SHOWN_SKIPS
    assert "further skipped lines are counted, not shown" in warned[-1]


def test_a_bad_header_stops_the_stream(tmp_path, tissue):
    p = tmp_path / "live.csv"
    p.write_text("temps,probe\n0.1,37\n")
    with pytest.raises(ValueError, match=rf"{p}:1: the first column must be 'time'"):
        follow_csv(p, OnlineIdentifier(tissue.setup()), lambda *a: None, idle_timeout_s=1)


def _rotating_writer(path, seen, n_before, after_text, warned):
    def writer():
        deadline = time.monotonic() + 60
        while len(seen) < n_before and time.monotonic() < deadline:
            time.sleep(0.01)
        path.rename(path.with_name("live.csv.1"))
        path.write_text("time,sensor_0\n")
        while not warned and time.monotonic() < deadline:
            time.sleep(0.01)
        with open(path, "a") as f:
            f.write(after_text)
    return threading.Thread(target=writer)


def test_a_rotated_file_whose_clock_restarts_stops_naming_file_and_line(tmp_path, tissue):
    s = tissue.setup()
    times, data = tissue.twin_data(s, 1.4, 100.0)
    path = tmp_path / "live.csv"
    path.write_text("time,sensor_0\n" + _lines(times[:4], data[:4, 0]))
    seen, warned = [], []
    th = _rotating_writer(path, seen, 4, _lines(times[:2] - 0.05, data[:2, 0]), warned)
    th.start()
    with pytest.raises(ValueError, match=rf"{path}:2: the clock restarted: time 0.05 s is not "
                                         r"after the last reading.s 0.4 s in a file replaced"):
        follow_csv(path, OnlineIdentifier(s), lambda est, line: seen.append(line),
                   idle_timeout_s=5.0, warn=warned.append)
    th.join()
    assert len(seen) == 4


def test_a_rewritten_file_repeating_its_readings_goes_on(tmp_path, tissue):
    """A writer that writes the whole file anew each time: the repeats are passed over."""
    s = tissue.setup()
    times, data = tissue.twin_data(s, 1.4, 100.0)
    path = tmp_path / "live.csv"
    path.write_text("time,sensor_0\n" + _lines(times[:4], data[:4, 0]))
    seen, warned = [], []
    th = _rotating_writer(path, seen, 4, _lines(times[:6], data[:6, 0]) + "# end\n", warned)
    th.start()
    n = follow_csv(path, OnlineIdentifier(s), lambda est, line: seen.append(line),
                   idle_timeout_s=5.0, warn=warned.append)
    th.join()
    assert n == 6 and seen == [2, 3, 4, 5, 6, 7]


def test_a_line_the_writer_never_finished_is_reported(tmp_path, tissue):
    s = tissue.setup()
    times, data = tissue.twin_data(s, 1.4, 100.0)
    p = tmp_path / "live.csv"
    p.write_text("time,sensor_0\n" + _lines(times[:3], data[:3, 0]) + "0.4,3")  # no newline
    skipped, warned = [], []
    assert follow_csv(p, OnlineIdentifier(s), lambda *a: None, idle_timeout_s=0.5,
                      warn=warned.append, skipped=skipped) == 3
    assert skipped == [(5, "the last line has no end of line (5 bytes; did the writer stop "
                            "in the middle of it?): not assimilated")]
    assert warned == [f"--follow: {p}:5: {skipped[0][1]}"]


def test_follow_keeps_a_run_json_from_start_to_end(tmp_path, capsys, cache):
    """Skipped lines go on record; a whole run has its run.json from the start."""
    live = tmp_path / "live.csv"
    live.write_text("\n".join(DATA[:3]) + "\nabc,def\n")
    out = tmp_path / "out"
    during = []

    def writer():
        deadline = time.monotonic() + 900  # the emulator and the JIT come first
        while time.monotonic() < deadline and not (
                (out / "estimates.csv").exists()
                and len((out / "estimates.csv").read_text().splitlines()) == 3):
            time.sleep(0.02)
        during.append(json.loads((out / "run.json").read_text()))
        with open(live, "a") as f:
            f.write("\n".join(DATA[3:5]) + "\n# end\n")

    th = threading.Thread(target=writer)
    th.start()
    rc = run("identify", EX / "tiny.toml", "--follow", live, "--out", out, "--quiet",
             "--cache-dir", cache, "--idle-timeout", "600")
    th.join()
    err = capsys.readouterr().err
    assert rc == 0, err
    assert during[0]["running"] is True and during[0]["readings"] == 0
    man = json.loads((out / "run.json").read_text())
    assert man["readings"] == 4 and "running" not in man and man["skipped_lines"] == 1
    assert man["skipped"][0]["line"] == 4 and "'abc'" in man["skipped"][0]["reason"]
    assert f"{live}:4: field 1 is not a number" in err and "1 line of" in err


def test_a_stream_that_fails_at_once_leaves_nothing(tmp_path, capsys, cache):
    live = tmp_path / "live.csv"
    live.write_text("time,a,b\n0.1,1,2\n")
    out = tmp_path / "out"
    assert run("identify", EX / "tiny.toml", "--follow", live, "--out", out, "--quiet",
               "--cache-dir", cache, "--idle-timeout", "5") == 2
    one_error_line(capsys, f"{live}:1: 2 data columns, the setup observes 1")
    assert not out.exists()


def test_a_stream_stopped_by_a_restarted_clock_keeps_a_whole_run(tmp_path, capsys, cache):
    live = tmp_path / "live.csv"
    live.write_text("\n".join(DATA[:4]) + "\n")
    out = tmp_path / "out"

    def writer():
        deadline = time.monotonic() + 900
        while time.monotonic() < deadline and not (
                (out / "estimates.csv").exists()
                and len((out / "estimates.csv").read_text().splitlines()) == 4):
            time.sleep(0.02)
        live.unlink()
        live.write_text("\n".join(DATA[:3]) + "\n")  # the clock from 0 again, new values
        with open(live, "a") as f:
            f.write("0.15,36\n")

    th = threading.Thread(target=writer)
    th.start()
    rc = run("identify", EX / "tiny.toml", "--follow", live, "--out", out, "--quiet",
             "--cache-dir", cache, "--idle-timeout", "600")
    th.join()
    assert rc == 2
    err = capsys.readouterr().err.splitlines()
    assert err[-1].startswith(f"error: {live}:4: the clock restarted: time 0.15 s")
    assert err[-1].endswith(f"(3 readings assimilated before it: estimates kept in {out})")
    man = json.loads((out / "run.json").read_text())
    assert man["readings"] == 3 and "the clock restarted" in man["stopped"]
    assert len((out / "estimates.csv").read_text().splitlines()) == 4


def test_a_stream_the_health_check_stops_ends_as_a_file_does(tmp_path, capsys, cache):
    """A reading the filter cannot follow: the estimates up to it, status 0, run.json says
    why (identify on a file does the same)."""
    live = tmp_path / "live.csv"
    live.write_text("\n".join(DATA[:4]) + "\n0.5,5000\n0.6,1e5\n# end\n")
    out = tmp_path / "out"
    assert run("identify", EX / "tiny.toml", "--follow", live, "--out", out, "--quiet",
               "--cache-dir", cache, "--idle-timeout", "5") == 0
    captured = capsys.readouterr()
    assert "3 readings assimilated" in captured.out
    assert f"warning: {live}: the filter stopped early: filter diverged at step 1" in captured.err
    man = json.loads((out / "run.json").read_text())
    assert man["readings"] == 3 and man["stopped"].startswith("filter diverged")


def test_a_mesh_file_that_is_a_fifo_is_refused(fifo):
    pytest.importorskip("pyvista")
    from mcmatlab_py.geometry.stl import find_inside_voxels

    X, Y, Z = np.meshgrid(*[np.array([0.25, 0.75])] * 3, indexing="ij")
    with pytest.raises(ValueError, match="mesh file .* is a pipe or FIFO, not a regular file"):
        find_inside_voxels(X, Y, Z, str(fifo))
