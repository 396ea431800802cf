"""The paper's experiments end to end, on small grids (the full runs are in validation/)."""

import json

import numpy as np
import pytest

from enkf.app.cli import main
from enkf.paper import mua_ramp, mus_ramp, true_parameters

SMALL = ["--fine", "10", "10", "5", "--truth-photons", "3000", "--emulator-photons", "1500",
         "--emulator-table", "5", "--members", "12", "--quiet"]


def test_paper_ramps_are_the_papers():
    assert mua_ramp(0) == 1 and mua_ramp(5) == pytest.approx(4) and mua_ramp(7) == 4
    assert mus_ramp(0) == 100 and mus_ramp(5) == pytest.approx(500) and mus_ramp(12) == 500
    p = true_parameters("constant", np.array([0.0, 15.0]))
    assert list(p["mua"]) == [1, 1] and list(p["VHC"]) == [3.76, 3.76]


@pytest.mark.parametrize("scenario", ["constant", "all-params"])
def test_paper_command_writes_the_contract(tmp_path, scenario):
    out = tmp_path / "run"
    rc = main(["paper", scenario, "--out", str(out), "--seed", "3",
               "--cache-dir", str(tmp_path / "cache"), *SMALL])
    assert rc == 0
    assert {p.name for p in out.iterdir()} == {"estimates.csv", "truth.csv", "summary.json",
                                               "figures", "run.json"}
    assert {p.name for p in (out / "figures").iterdir()} == {"estimates.png", "data.png"}
    s = json.loads((out / "summary.json").read_text())
    names = ["mua", "mus"] + (["VHC", "TC"] if scenario == "all-params" else [])
    assert list(s["parameters"]) == names
    for p in s["parameters"].values():
        assert set(p) >= {"truth_final", "estimate_final", "std_final", "relative_error_final",
                          "rmse", "coverage_2sd"}
    assert list(s["temperatures"]) == ["z=0.0", "z=0.1", "z=0.2"]
    assert set(s["timing"]) >= {"filter_wall_s", "step_latency_median_s", "step_latency_max_s",
                                "steps", "ensemble_size"}
    assert s["timing"]["steps"] == 150 and s["timing"]["ensemble_size"] == 12
    assert s["scenario"] == scenario and s["seed"] == 3
    est = np.genfromtxt(out / "estimates.csv", delimiter=",", names=True)
    assert est.shape == (151,) and est["time_s"][-1] == pytest.approx(15.0)
    if scenario == "constant":
        # the filter learns: the final mua is far closer than the prior's spread
        assert s["parameters"]["mua"]["relative_error_final"] < 0.3


def test_paper_sensitivity(tmp_path, capsys):
    out = tmp_path / "sens"
    assert main(["paper", "sensitivity", "--out", str(out), "--fine", "8", "8", "4",
                 "--truth-photons", "2000", "--seed", "5", "--quiet"]) == 0
    table = np.genfromtxt(out / "sensitivity.csv", delimiter=",", names=True)
    peak = {k: table[k][50] for k in table.dtype.names if k != "time_s"}
    # more absorption heats the surface more; scattering matters less (the paper's Fig. 3)
    mua_peaks = [peak[f"T_mua_{v}"] for v in (1, 2, 3, 4, 5)]
    assert np.all(np.diff(mua_peaks) > 0)
    assert {p.name for p in out.iterdir()} == {"sensitivity.csv", "figures", "run.json"}
    man = json.loads((out / "run.json").read_text())
    assert man["command"] == "paper sensitivity" and man["seed"] == 5
    assert man["config"] == {"scenario": "sensitivity", "fine": [8, 8, 4],
                             "truth_photons": 2000, "mua": [1, 2, 3, 4, 5],
                             "mus": [100, 200, 300, 400, 500]}
    # the result, even with --quiet: the peaks, as in the csv
    printed = capsys.readouterr().out
    peaks = {k: table[k].max() for k in table.dtype.names if k != "time_s"}
    assert f"against mua (cm^-1; mus = 100): 1: {peaks['T_mua_1']:.2f}, 2: " in printed
    assert f"against mus (cm^-1; mua = 1): 100: {peaks['T_mus_100']:.2f}, 200: " in printed
    assert printed.rstrip().endswith(f"-> {out}")


def test_paper_bad_input(tmp_path, capsys):
    assert main(["paper", "constant", "--out", str(tmp_path / "o"), "--members", "1",
                 "--quiet"]) == 2
    assert "--members must be >= 2, got 1" in capsys.readouterr().err
    assert main(["paper", "sensitivity", "--out", str(tmp_path / "s"), "--truth-photons", "0",
                 "--quiet"]) == 2
    assert "--truth-photons must be >= 1, got 0" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


def test_truth_key_holds_the_heat_scheme():
    """The fine truth's time scheme is in its cache key; backward-Euler truths (before the
    key had it) keep their old keys, so their caches stay valid."""
    from enkf.paper import TruthConfig

    old = TruthConfig(heat_theta=1.0)
    assert TruthConfig().key() != old.key()
    assert old.key() == "256302e53539898f81bd"  # the constant truth's key before the scheme


@pytest.mark.parametrize("hotter", [1.5, 2.5])  # 2.5: stopped at the first step
def test_a_paper_run_stopped_by_the_health_check_says_so_as_identify(tmp_path, monkeypatch,
                                                                     capsys, hotter):
    """summary.json's "stopped" (identify's key), the parameter by name; no "diverged"."""
    from enkf.paper import runner

    real_identify, real_noisy = runner.identify, runner.noisy_sensor
    monkeypatch.setattr(runner, "noisy_sensor",
                        lambda truth, seed: real_noisy(truth, seed) * hotter)
    monkeypatch.setattr(runner, "identify", lambda *a, **k: real_identify(
        *a, **k, param_bounds=np.array([[0.5, 2.0], [10.0, 1000.0]])))
    out = tmp_path / "run"
    assert main(["paper", "constant", "--out", str(out), "--seed", "3",
                 "--cache-dir", str(tmp_path / "cache"), *SMALL]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert "diverged" not in s and s["stopped"].startswith("filter diverged at step ")
    assert "parameter mua mean" in s["stopped"] or "parameter mus mean" in s["stopped"]
    assert f"warning: the filter stopped early: {s['stopped']}" in capsys.readouterr().err
    assert (out / "run.json").exists() and (out / "estimates.csv").exists()


def test_the_paper_runs_advice_names_what_paper_can_change(tmp_path, monkeypatch):
    """A table too narrow for the members' mus (the paper's is fixed): the warning names
    the paper command's options, not filter.emulator.mus_range, which it cannot take."""
    import functools
    import warnings

    from enkf.paper import TruthConfig, runner

    monkeypatch.setattr(runner, "emulator_for",
                        functools.partial(runner.emulator_for, mus_range=(80.0, 150.0)))
    tcfg = TruthConfig(scenario="constant", grid=(10, 10, 5))
    tcfg.n_photons_constant = tcfg.n_photons_per_step = 3000
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = runner.run_experiment("constant", 3, n_members=12, truth_config=tcfg,
                                    emulator_photons=1500, emulator_table=5,
                                    cache_dir=tmp_path / "cache", progress=False)
    assert run.estimates.clamped  # the filter's own advice names the config key
    assert "filter.emulator.mus_range" in run.estimates.clamped["advice"]
    text = [str(w.message) for w in caught]
    clamp = [t for t in text if "clamped members' optics" in t]
    assert len(clamp) == 1 and "members' mus below 80 and above 150 cm^-1" in clamp[0]
    assert "mus [80.0, 150.0] cm^-1) and priors are fixed in `tissue-enkf paper`" in clamp[0]
    assert "--exact" in clamp[0]
    assert not any("filter.emulator" in t or "[filter.drift]" in t for t in text)
    advice = run.summary["innovation_persistence"]["advice"] or ""
    assert "[filter.drift]" not in advice


def test_paper_advice_puts_drift_in_the_paper_options():
    from enkf.paper.runner import paper_advice
    from enkf.tissue.diagnose import ADVICE

    text = ADVICE["drifting optics"].format(how="", r=0.5) + (
        '. Set [filter.drift] mode = "auto" to let the data decide')
    out = paper_advice(text)
    assert "[filter.drift]" not in out and out.endswith("Run with --drift auto to let the "
                                                       "data decide")
