"""Limits and messages (issue 51): option errors in one line, and what cannot fit or finish
refused or announced by the library itself, not only by the command line.

The library refuses a heat run of more than 10^6 steps (``HS.dt = 1e-9``) or a mesh
larger than the memory (``HS.mesh_divisions = [2000] * 3``) before it allocates,
naming the field and its value; a Monte Carlo run expected to take long
(``MC.n_photons_requested = 1e12``) says how long, once, after its first round.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

import mcmatlab_py.budget as budget
from enkf.app.cli import main
from mcmatlab_py.budget import format_seconds
from mcmatlab_py.config import model_from_config, read_toml

EX = Path(__file__).parents[1] / "examples"


@pytest.mark.parametrize("argv, needle", [
    (["identify", EX / "tiny.toml", "--seed", "x", "--out", "o"],
     "tissue-enkf identify: argument --seed: invalid int value: 'x'"),
    (["identify", "--out", "o"], "the following arguments are required: config"),
    (["mc", EX / "tiny.toml", "--out", "o", "--photons", "1e300"],
     "tissue-enkf mc: argument --photons: invalid int value: '1e300'"),
    (["paper", "nonsense", "--out", "o"], "argument scenario: invalid choice: 'nonsense'"),
    (["bogus"], "argument command: invalid choice: 'bogus'"),
    (["heat", EX / "tiny.toml", "--out", "o", "--nope"], "unrecognized arguments: --nope"),
])
def test_option_errors_are_one_line_naming_the_option(tmp_path, capsys, argv, needle):
    with pytest.raises(SystemExit) as exc:
        main([str(a) for a in argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("error: tissue-enkf") and err.count("\n") == 1, err
    assert needle in err and "--help)" in err and "usage:" not in err
    assert len(err) < 400


def test_a_huge_thread_count_is_refused_naming_the_option(tmp_path, capsys):
    assert main(["mc", str(EX / "tiny.toml"), "--out", str(tmp_path / "o"), "--threads",
                 "9" * 500]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --threads must be <= 1e+06, got 999") and len(err) < 160


def test_a_huge_voxel_count_is_one_short_line(tmp_path, capsys):
    cfg = tmp_path / "big.toml"
    text = (EX / "tiny.toml").read_text()
    cfg.write_text(text.replace("nx = 10", "nx = 1e300", 1))
    assert main(["mc", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: G.nx * G.ny * G.nz = 5e+301 voxels") and len(err) < 160, err


def _tiny():
    model = model_from_config(read_toml(EX / "tiny.toml"))
    model.MC.progress = model.HS.progress = False
    return model


def test_the_library_refuses_a_heat_run_of_too_many_steps():
    model = _tiny()
    model.HS.dt = 1e-9
    with pytest.raises(ValueError, match=r"in steps of HS\.dt = 1e-09 s\) would take .* time "
                                         r"steps \(limit 1000000\): change HS\.dt"):
        model.simulate_heat_distribution()  # refused before the Monte Carlo's NA is needed


def test_the_library_refuses_a_mesh_larger_than_the_memory():
    model = _tiny()
    model.HS.mesh_divisions = [2000] * 3
    with pytest.raises(ValueError, match=r"the heat mesh of 8.01e\+09 nodes needs about 16.4 TB"
                                         r".*: reduce HS\.mesh_divisions = \[2000, 2000, 2000\]"):
        model.simulate_heat_distribution()


def test_a_long_monte_carlo_says_how_long_before_it_goes_on():
    """1e12 photons: the warning after the first round; as an error here, it ends the run."""
    model = _tiny()
    model.MC.n_photons_requested = 10**12
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(RuntimeWarning, match=r"MC\.n_photons_requested = 1e\+12 will take "
                                                 r"about .* more \(.* photons/s on the first "
                                                 r".*\): Ctrl-C stops it; request fewer"):
            model.run_monte_carlo()


def test_a_short_monte_carlo_says_nothing(monkeypatch):
    model = _tiny()
    model.MC.n_photons_requested = 20_000
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        model.run_monte_carlo()
    monkeypatch.setattr(budget, "LONG_RUN_S", 0.0)  # every run is "long": the warning, once
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        model.run_monte_carlo()
    assert len([w for w in rec if "will take about" in str(w.message)]) <= 1


@pytest.mark.parametrize("s, text", [(42.0, "42 s"), (600.0, "10 min"), (7200.0, "2 h"),
                                     (3 * 86400.0, "3 days"), (1e9, "31.7 years")])
def test_durations_read_well(s, text):
    assert format_seconds(s) == text


@pytest.mark.parametrize("value, needle", [(float("nan"), "must be finite, got nan"),
                                           (-1.0, "must be >= 0"), ("2", "must be a number")])
def test_a_power_function_returning_nonsense_is_named(value, needle):
    """HS.P(t) returning NaN gave NaN temperatures and no error."""
    model = _tiny()
    model.MC.n_photons_requested = 1000
    model.run_monte_carlo()
    model.HS.P = lambda t: value
    with pytest.raises(ValueError, match=rf"HS\.P\(t\) at t = .* s {needle}.*HS\.P is a "
                                         r"function of time"):
        model.simulate_heat_distribution()


def test_steps_chosen_by_accuracy_are_not_counted_from_the_stability_bound():
    """HS.step_control = "accuracy" takes as many steps as the temperatures need: a long
    run is not refused from the stability bound's count, which "stability" runs take."""
    from mcmatlab_py.heat import check_heat

    model = _tiny()
    model.HS.dt = None
    model.HS.duration_on = 1e6  # s: about 1e8 steps of the stability bound
    model.HS.validate(model.G)
    check_heat(model.G, model.HS)
    model.HS.step_control = "stability"
    with pytest.raises(ValueError, match=r"in steps of the automatic step .* would take"):
        check_heat(model.G, model.HS)
