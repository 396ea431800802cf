"""Bad input, interruption and cache failure (issue 14): what the tool guarantees.

Each test fails without its fix: a budget refused before allocating, SIGTERM handled as
Ctrl-C, stale partial directories removed, an unwritable cache found before the build,
values beyond physical ranges and numeric strings refused, the laser required, data
with no usable reading refused, the Monte Carlo's energy balance checked, and any
unexpected error reported in one line.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest

from enkf.app.cli import main
from enkf.app.rundir import atomic_dir, remove_stale_partials

EX = Path(__file__).parents[1] / "examples"


def run(*argv) -> int:
    return main([str(a) for a in argv])


def one_error_line(capsys, *needles):
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    for n in needles:
        assert n in err, err
    return err


@pytest.mark.parametrize("old, new, needles", [
    ("n_members = 20", "n_members = 10000000", ("filter.n_members must be <= 100000",)),
    ("grid = [5, 5, 5]", "grid = [900, 900, 900]", ("needs about", "filter.grid")),
    ("dt = 0.1 ", "dt = 1e-9 ", ("time steps", "HS.dt")),
    ("Lz = 0.25", "Lz = 1e300", ("G.Lz must be <= 1000",)),
    ("Lx = 0.5", "Lx = 1e-300", ("smallest voxel size",)),
    ("Lx = 0.5", 'Lx = "0.5"', ("G.Lx must be a number, got '0.5'",)),
    ("nx = 10", 'nx = "10"', ("G.nx must be an integer, got '10'",)),
    ("mua = 1.0 ", "mua = 1e300 ", ("mua must be <= 1e+06",)),
    ("n_members = 20", 'n_members = "20"', ("filter.n_members must be an integer",)),
    ("n_members = 20", "n_members = 20\nmodel_noise_std = 1e300",
     ("filter.model_noise_std must be <= 100",)),
])
def test_identify_refuses_before_allocating(tmp_path, capsys, bad_toml, old, new, needles):
    out = tmp_path / "out"
    t0 = time.perf_counter()
    assert run("identify", bad_toml(old, new), "--data", EX / "tiny_data.csv", "--out", out) == 2
    assert time.perf_counter() - t0 < 30  # refused, not attempted (a loose guard, not a timing)
    one_error_line(capsys, *needles)
    assert not out.exists()


@pytest.mark.parametrize("old, new, needles", [
    ("dt = 0.1 ", "dt = 1e-9 ", ("time steps", "HS.dt")),
    ("P = 0.5", "P = 1e300", ("HS.P must be <= 1e+06",)),
])
def test_heat_refuses_before_the_monte_carlo(tmp_path, capsys, bad_toml, old, new, needles):
    assert run("heat", bad_toml(old, new), "--out", tmp_path / "out") == 2
    one_error_line(capsys, *needles)


def test_heat_mesh_that_cannot_fit_is_refused():
    from mcmatlab_py import Medium, Model
    from mcmatlab_py.heat import check_heat

    m = Model()
    m.G.media = [Medium("t", mua=1.0, mus=100.0, VHC=3.7, TC=0.0037)]
    m.HS.mesh_divisions = (3000, 3000, 3000)
    m.HS.validate(m.G)
    with pytest.raises(ValueError, match="HS.mesh_divisions"):
        check_heat(m.G, m.HS)


def test_huge_seed_is_bad_input(tmp_path, capsys):
    assert run("mc", EX / "tiny.toml", "--out", tmp_path / "o", "--seed",
               "99999999999999999999999") == 2
    one_error_line(capsys, "--seed must be <=")


def test_identify_requires_the_laser(tmp_path, capsys):
    text = (EX / "tiny.toml").read_text()
    start = text.index("[HS]")
    end = text.index("\n[", start + 1)
    cfg = tmp_path / "nolaser.toml"
    cfg.write_text(text[:start] + text[end + 1:])
    assert run("identify", cfg, "--data", EX / "tiny_data.csv", "--out", tmp_path / "o") == 2
    one_error_line(capsys, "[HS] is missing")


def test_data_with_no_usable_reading_is_refused(tmp_path, capsys):
    data = tmp_path / "nan.csv"
    data.write_text("time,probe\n" + "".join(f"{0.1 * k:.1f},nan\n" for k in range(1, 11)))
    assert run("identify", EX / "tiny.toml", "--data", data, "--out", tmp_path / "o") == 2
    one_error_line(capsys, "no usable reading")


def test_energy_balance_is_checked_after_every_run(monkeypatch):
    import mcmatlab_py.monte_carlo.run as mc
    from mcmatlab_py import Medium, Model
    from mcmatlab_py.model import EnergyBalanceError

    m = Model()
    m.G.nx = m.G.ny = m.G.nz = 4
    m.G.media = [Medium("t", mua=1.0, mus=10.0)]
    m.MC.n_photons_requested, m.MC.seed = 200, 1
    m.run_monte_carlo()
    assert abs(m.MC.energy_balance - 1) < 1e-9
    real = mc.run_monte_carlo

    def broken(model, client=None):  # a kernel that lost weight (overflow, a bug)
        real(model, client=client)
        model.MC.absorbed_fraction -= 0.25

    monkeypatch.setattr(mc, "run_monte_carlo", broken)
    with pytest.raises(EnergyBalanceError, match="lost track of its energy"):
        m.run_monte_carlo()


def test_unwritable_cache_is_found_before_the_build(tmp_path):
    from mcmatlab_py.emulator import usable_cache_dir

    blocker = tmp_path / "cache"
    blocker.write_text("a file, not a folder")
    with pytest.warns(RuntimeWarning, match="cannot be written"):
        alt = usable_cache_dir(blocker)
    assert alt.is_dir() and alt != blocker
    assert usable_cache_dir(tmp_path / "fine") == tmp_path / "fine"


def test_stale_partials_of_dead_processes_are_removed(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".out.{dead.pid}.partial"
    stale.mkdir()
    (stale / "half.csv").write_text("1,2")
    mine = tmp_path / f".other.{os.getpid()}.partial"
    mine.mkdir()
    assert remove_stale_partials(tmp_path) == [stale]
    assert not stale.exists() and mine.exists()
    with atomic_dir(tmp_path / "out") as tmp:
        assert tmp.name == f".out.{os.getpid()}.partial"
        (tmp / "a.txt").write_text("x")
    assert (tmp_path / "out" / "a.txt").exists()
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "out").stat().st_mode & 0o777 == 0o777 & ~mask


def test_sigterm_cleans_up_and_exits_143(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "enkf.app.cli", "mc", str(EX / "tiny.toml"), "--out", str(out),
         "--photons", "200000000", "--quiet", "--threads", "1"],
        stderr=subprocess.PIPE, text=True)
    time.sleep(6)  # imported and inside the Monte Carlo (200 M photons: minutes)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "terminated" in err and "Traceback" not in err
    assert not out.exists() and not list(tmp_path.glob(".*partial"))


def test_unexpected_errors_are_one_line_with_a_hint(tmp_path, capsys, monkeypatch):
    import enkf.app.cmd_model as cm

    def boom(args, heat):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(cm, "_run_model_mc", boom)
    assert run("mc", EX / "tiny.toml", "--out", tmp_path / "o") == 1
    err = capsys.readouterr().err
    assert err.startswith("error: unexpected ZeroDivisionError") and "report" in err
    assert "Traceback" not in err
    with pytest.raises(ZeroDivisionError):
        run("--debug", "mc", EX / "tiny.toml", "--out", tmp_path / "o")


def test_warnings_are_one_line(tmp_path):
    assert run("mc", EX / "tiny.toml", "--out", tmp_path / "o", "--photons", "1000") == 0
    line = warnings.formatwarning("something odd", RuntimeWarning, "file.py", 1)
    assert line == "warning: something odd\n"


def test_force_never_replaces_the_working_directory_or_a_foreign_folder(tmp_path, monkeypatch,
                                                                         capsys):
    foreign = tmp_path / "thesis"
    foreign.mkdir()
    (foreign / "chapter1.tex").write_text("years of work")
    assert run("mc", EX / "tiny.toml", "--out", foreign, "--force", "--photons", "100") == 2
    one_error_line(capsys, "no run.json")
    assert (foreign / "chapter1.tex").exists()
    monkeypatch.chdir(foreign)
    assert run("mc", EX / "tiny.toml", "--out", ".", "--force", "--photons", "100") == 2
    one_error_line(capsys, "working directory")
    assert (foreign / "chapter1.tex").exists()
