"""The tool's input and output under abuse (issue #14): followed files that are replaced or
truncated, bad --idle-timeout values, batches, --follow --force, Ctrl-C in --follow, byte-
order marks, quoted headers, huge values in error lines, files that are not NPZ, umask."""

import csv
import json
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from enkf.app.cli import main
from enkf.app.readers import follow_csv, load_frames, read_sensor_csv
from enkf.app.rundir import atomic_dir
from enkf.tissue import OnlineIdentifier
from fem.checks import shorten
from mcmatlab_py.config import read_toml

EX = Path(__file__).parents[1] / "examples"
TINY = (EX / "tiny.toml").read_text()
DATA = (EX / "tiny_data.csv").read_text().splitlines()  # header, then 20 readings


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("emulator-cache"))


def run(*argv):
    return main([str(a) for a in argv])


def wait_for(condition, timeout=5.0):
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


# --- --follow: a file that is replaced or truncated while it is read -------------------

def _lines(times, ys):
    return "".join(f"{t:.3f},{y:.4f}\n" for t, y in zip(times, ys, strict=True))


@pytest.mark.parametrize("how", ["deleted and written anew", "rotated", "truncated"])
def test_follow_reads_a_replaced_or_truncated_file_from_its_start(tmp_path, tissue, how):
    s = tissue.setup()
    times, data = tissue.twin_data(s, 1.4, 100.0)
    path = tmp_path / "live.csv"
    path.write_text("time,sensor_0\n" + _lines(times[:3], data[:3, 0]))
    seen, warnings = [], []

    def writer():
        wait_for(lambda: len(seen) == 3)
        if how == "deleted and written anew":
            path.unlink()
            time.sleep(0.1)  # a moment without a file: the reader waits for the new one
            path.write_text("time,sensor_0\n")
        elif how == "rotated":
            path.rename(tmp_path / "live.csv.1")
            path.write_text("time,sensor_0\n")
        else:
            with open(path, "w") as f:
                f.write("time,sensor_0\n")  # shorter than what was read
        # the rest once the reader has seen the change (later, an append could hide a
        # truncation: the file would be as long as before)
        wait_for(lambda: warnings, timeout=3.0)
        with open(path, "a") as f:
            f.write(_lines(times[3:6], data[3:6, 0]) + "# end\n")

    th = threading.Thread(target=writer)
    th.start()
    n = follow_csv(path, OnlineIdentifier(s), lambda est, line: seen.append((est, line)),
                   idle_timeout_s=3.0, warn=warnings.append)
    th.join()
    assert n == 6 and [e.time for e, _ in seen] == pytest.approx(times[:6])
    assert [line for _, line in seen[3:]] == [2, 3, 4]  # the new file's lines, header first
    word = "truncated" if how == "truncated" else "replaced"
    assert len(warnings) == 1 and word in warnings[0] and str(path) in warnings[0]


def test_follow_warns_on_stderr_by_default(tmp_path, tissue, capsys):
    s = tissue.setup()
    times, data = tissue.twin_data(s, 1.4, 100.0)
    path = tmp_path / "live.csv"
    path.write_text("time,sensor_0\n" + _lines(times[:2], data[:2, 0]))
    seen = []

    def writer():
        wait_for(lambda: len(seen) == 2)
        path.write_text("time,sensor_0\n")
        time.sleep(0.3)
        with open(path, "a") as f:
            f.write(_lines(times[2:3], data[2:3, 0]) + "# end\n")

    th = threading.Thread(target=writer)
    th.start()
    n = follow_csv(path, OnlineIdentifier(s), lambda est, line: seen.append(est),
                   idle_timeout_s=3.0)
    th.join()
    err = capsys.readouterr().err
    assert n == 3 and err.startswith("warning: --follow: ") and "truncated" in err


@pytest.mark.parametrize("value", ["nan", "inf", "-1", "0", "-inf"])
def test_a_bad_idle_timeout_exits_2_naming_it(tmp_path, capsys, value):
    live = tmp_path / "live.csv"
    live.write_text("time,sensor_0\n# end\n")
    out = tmp_path / "out"
    assert run("identify", EX / "tiny.toml", "--follow", live, "--out", out,
               f"--idle-timeout={value}") == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --idle-timeout ") and value in err and err.count("\n") == 1
    assert not out.exists()


def test_follow_csv_refuses_a_bad_idle_timeout(tmp_path, tissue):
    (tmp_path / "live.csv").write_text("time,sensor_0\n# end\n")
    for v in (float("nan"), float("inf"), -1.0, 0.0):
        with pytest.raises(ValueError, match="idle_timeout_s must be a finite number"):
            follow_csv(tmp_path / "live.csv", OnlineIdentifier(tissue.setup()),
                       lambda *a: None, idle_timeout_s=v)


def test_help_says_what_idle_timeout_takes(capsys):
    with pytest.raises(SystemExit):
        main(["identify", "--help"])
    assert "finite number > 0" in " ".join(capsys.readouterr().out.split())


# --- batches -----------------------------------------------------------------------------

def test_a_batch_where_every_file_failed_exits_1(tmp_path, capsys, cache):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,sensor_0\n0.1,1\n0.1,2\n")
    out = tmp_path / "batch"
    assert run("identify", EX / "tiny.toml", "--data", bad, tmp_path / "missing.csv",
               "--out", out, "--quiet", "--cache-dir", cache) == 1
    err = capsys.readouterr().err
    assert "error: all 2 data files failed" in err and str(out / "batch.csv") in err
    rows = list(csv.DictReader(open(out / "batch.csv", newline="")))
    assert [r["status"] for r in rows] == ["error", "error"]
    assert "duplicate times" in rows[0]["message"] and "does not exist" in rows[1]["message"]


def test_batch_csv_is_valid_csv_with_commas_and_quotes(tmp_path, cache):
    good = tmp_path / "day 1, probe A.csv"  # a comma in the path
    good.write_text("\n".join(DATA) + "\n")
    bad = tmp_path / "bad.csv"
    bad.write_text('time,sensor_0\n0.1,1\n0.2,2"C\n')  # the error message holds a quote
    out = tmp_path / "batch"
    assert run("identify", EX / "tiny.toml", "--data", good, bad, "--out", out, "--quiet",
               "--cache-dir", cache) == 0
    with open(out / "batch.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    header, ok, err = rows
    assert header == ["data", "dir", "status", "mua_mean", "mua_std", "mus_mean", "mus_std",
                      "message"]
    assert len(ok) == len(err) == len(header)
    assert ok[0] == str(good) and ok[2] == "ok" and float(ok[3]) > 0 and ok[7] == ""
    assert err[0] == str(bad) and err[2] == "error" and err[3:7] == [""] * 4
    assert "'2\"C'" in err[7] and "field 2 is not a number" in err[7]


# --- --follow --force, and Ctrl-C in --follow ------------------------------------------

def test_follow_force_clears_the_old_outputs_and_nothing_else(tmp_path, cache):
    out = tmp_path / "live-out"
    (out / "fields").mkdir(parents=True)
    (out / "fields" / "final.vtu").write_text("old")
    (out / "summary.json").write_text("{}")
    (out / "batch.csv").write_text("old")
    (out / "notes.txt").write_text("the operator's notes")  # not ours: stays
    live = tmp_path / "live.csv"
    live.write_text("\n".join(DATA[:6]) + "\n# end\n")
    argv = ["identify", EX / "tiny.toml", "--follow", live, "--out", out, "--quiet",
            "--cache-dir", cache, "--idle-timeout", "5"]
    assert run(*argv) == 2  # without --force: refused
    assert run(*argv, "--force") == 0
    assert sorted(p.name for p in out.iterdir()) == ["estimates.csv", "figures", "notes.txt",
                                                     "run.json"]
    assert len((out / "estimates.csv").read_text().splitlines()) == 6
    assert (out / "notes.txt").read_text() == "the operator's notes"


def test_ctrl_c_in_follow_says_what_was_kept(tmp_path, capsys, cache):
    live = tmp_path / "live.csv"
    live.write_text("\n".join(DATA[:4]) + "\n")  # 3 readings, then nothing (no '# end')
    out = tmp_path / "live-out"

    def interrupt():
        # generous waits (here and --idle-timeout): on a fresh clone the emulator is built and
        # the JIT compiled first, minutes on a loaded machine, and the idle clock may run
        # out before the first estimate is written; the interrupt comes as soon as the
        # three readings are written
        if wait_for(lambda: (out / "estimates.csv").exists()
                    and len((out / "estimates.csv").read_text().splitlines()) == 4, 900.0):
            time.sleep(0.1)
            os.kill(os.getpid(), signal.SIGINT)

    th = threading.Thread(target=interrupt)
    th.start()
    rc = run("identify", EX / "tiny.toml", "--follow", live, "--out", out, "--quiet",
             "--cache-dir", cache, "--idle-timeout", "600")
    th.join()
    err = capsys.readouterr().err
    assert rc == 130, err
    assert f"interrupted: 3 readings assimilated, estimates kept in {out}" in err
    assert "nothing written" not in err
    assert len((out / "estimates.csv").read_text().splitlines()) == 4
    man = json.loads((out / "run.json").read_text())
    assert man["readings"] == 3 and man["interrupted"] is True


# --- byte-order marks and quoted headers --------------------------------------------------

@pytest.mark.parametrize("header", ["\ufefftime,probe", '"time","probe"', '\ufeff"time", "probe"'])
def test_a_bom_and_a_quoted_header_are_read(tmp_path, tissue, header):
    p = tmp_path / "d.csv"
    p.write_text(f"{header}\n0.1,1.0\n0.2,\n", encoding="utf-8")
    times, data, names = read_sensor_csv(p, 1)
    assert names == ["time", "probe"] and np.array_equal(times, [0.1, 0.2])
    assert data[0, 0] == 1.0 and np.isnan(data[1, 0])
    p.write_text(f"{header}\n0.1,1.0\n# end\n", encoding="utf-8")
    assert follow_csv(p, OnlineIdentifier(tissue.setup()), lambda *a: None,
                      idle_timeout_s=2.0, columns=["time", "probe"]) == 1


def test_a_toml_file_with_a_bom_is_read(tmp_path):
    p = tmp_path / "bom.toml"
    p.write_bytes(b"\xef\xbb\xbf" + TINY.encode())
    assert read_toml(p)["G"]["nx"] == 10


# --- long values in error lines ----------------------------------------------------------

BIG = "a" * 100_000


def test_shorten_cuts_long_values_and_says_how_long():
    assert shorten(repr("abc")) == "'abc'" and shorten([1, 2]) == "[1, 2]"
    cut = shorten(repr(BIG))
    assert cut == "'" + "a" * 79 + "... (100002 characters)"
    assert shorten("two\nlines") == "two lines"


@pytest.mark.parametrize("old, new, where", [
    ("n_members = 20", f'n_members = 20\nmethod = "{BIG}"', "filter.method"),
    ("n_members = 20", f"n_members = 20\n{BIG} = 1", "unknown key filter."),
    ("P = 0.5 ", f"P = [{', '.join(['1'] * 20_000)}] ", "HS.P"),
    ("grid = [5, 5, 5]", f"grid = [{', '.join(['5'] * 20_000)}]", "filter.grid"),
    ("mua = 1.0 ", f'mua = "{BIG}" ', "mua"),  # a validator's message: the CLI's cut
])
def test_a_huge_value_is_cut_in_the_error_line(tmp_path, capsys, bad_toml, old, new, where):
    cfg = bad_toml(old, new)
    assert run("identify", cfg, "--data", EX / "tiny_data.csv", "--out", tmp_path / "o") == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and where in err and err.count("\n") == 1
    assert len(err) < 500 and "characters)" in err


def test_a_huge_csv_field_is_cut_in_the_error(tmp_path):
    p = tmp_path / "d.csv"
    p.write_text(f"time,s0\n0.1,{BIG}\n")
    with pytest.raises(ValueError, match=r"field 2 is not a number: 'a+\.\.\. \(100002 ") as exc:
        read_sensor_csv(p, 1)
    assert len(str(exc.value)) < 200 + len(str(p))
    p.write_text(f"{BIG},s0\n0.1,1\n")
    with pytest.raises(ValueError, match="first column must be 'time'") as exc:
        read_sensor_csv(p, 1)
    assert len(str(exc.value)) < 250 + len(str(p))


# --- NPZ files that are not, or hold complex numbers ------------------------------------

def test_a_csv_renamed_npz_is_called_not_an_npz(tmp_path):
    p = tmp_path / "frames.npz"
    p.write_text("\n".join(DATA) + "\n")
    with pytest.raises(ValueError, match="not a zip archive") as exc:
        load_frames(p)
    assert "pickled" not in str(exc.value)
    np.save(tmp_path / "one.npy", np.zeros(3))
    (tmp_path / "one.npy").rename(tmp_path / "one.npz")
    with pytest.raises(ValueError, match="not a zip archive"):
        load_frames(tmp_path / "one.npz")


@pytest.mark.parametrize("name", ["times", "frames"])
def test_complex_npz_arrays_are_refused_naming_the_array(tmp_path, name):
    times = 0.1 * np.arange(1, 6)
    arrays = {"times": times, "frames": np.ones((5, 2, 3))}
    arrays[name] = arrays[name] + 1j
    np.savez(tmp_path / "c.npz", **arrays)
    with pytest.raises(ValueError, match=f"'{name}' is complex"):
        load_frames(tmp_path / "c.npz")
    arrays[name] = np.full(arrays[name].shape, "x")
    np.savez(tmp_path / "s.npz", **arrays)
    with pytest.raises(ValueError, match=f"'{name}' must hold numbers"):
        load_frames(tmp_path / "s.npz")


# --- run directories honour the umask ----------------------------------------------------

@pytest.mark.parametrize("umask", [0o022, 0o027])
def test_run_directories_honour_the_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        with atomic_dir(tmp_path / "run") as tmp:
            (tmp / "x.txt").write_text("x")
    finally:
        os.umask(old)
    assert (tmp_path / "run" / "x.txt").exists()
    assert (tmp_path / "run").stat().st_mode & 0o777 == 0o777 & ~umask
