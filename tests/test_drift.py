"""The drift bank (``enkf.tissue.drift``): a still and a drifting filter weighed by their
evidence. The weights against Bayes' rule, the mixture's moments and quantiles against
pooled samples, the still filter of the bank against the plain filter, the bank telling
still from drifting twins, online and in batch, and the config's ``[filter.drift]``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import fem
from enkf.tissue import OnlineIdentifier, TissueForwardModel, identify
from enkf.tissue.drift import DriftBank, bank_weights, mix_moments, weighted_quantiles


def test_bank_weights_are_bayes_without_switching():
    """With no switching the weights are the posterior model probabilities: the prior
    odds times the likelihood ratio of the readings so far; the mixture's log-density
    summed is the log of the prior-weighted evidences."""
    rng = np.random.default_rng(0)
    ll = rng.normal(-1.0, 2.0, (30, 2))
    w, pred, mix = bank_weights(ll, [0.7, 0.3], 0.0)
    log_odds = np.log(0.3 / 0.7) + np.cumsum(ll[:, 1] - ll[:, 0])
    np.testing.assert_allclose(w[1:, 1], 1 / (1 + np.exp(-log_odds)), rtol=1e-12)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, rtol=1e-14)
    np.testing.assert_allclose(pred[1:], w[1:-1], rtol=1e-14)
    evidence = np.log(0.7 * np.exp(ll[:, 0].sum()) + 0.3 * np.exp(ll[:, 1].sum()))
    np.testing.assert_allclose(mix.sum(), evidence, rtol=1e-12)


def test_bank_weights_switch_stop_and_skip():
    """A switch moves pi of each weight to the other model before a reading (only where
    ``switching`` allows); a reading not analysed (NaN) changes nothing else; a model
    that stopped (-inf) has weight 0 from then on, whatever the switching."""
    ll = np.zeros((4, 2))
    ll[1] = np.nan
    ll[2:, 0] = -np.inf
    w, pred, mix = bank_weights(ll, [0.9, 0.1], 0.1, np.array([True, True, True, False]))
    np.testing.assert_allclose(w[1], [0.9 * 0.9 + 0.1 * 0.1, 0.1 * 0.9 + 0.9 * 0.1])
    np.testing.assert_allclose(w[2], [0.82 * 0.9 + 0.18 * 0.1, 0.18 * 0.9 + 0.82 * 0.1])
    assert np.isnan(mix[1])
    np.testing.assert_array_equal(w[3:], [[0.0, 1.0], [0.0, 1.0]])
    with pytest.raises(AssertionError):  # the check above can fail: switching off
        np.testing.assert_allclose(bank_weights(ll, [0.9, 0.1], 0.0)[0][1], w[1])


def test_weighted_quantiles_and_moments_of_a_mixture():
    """One ensemble: numpy's Hazen quantiles; a weight of 0 drops an ensemble; equal
    sizes and weights: the pooled members' quantiles and moments (population moments)."""
    rng = np.random.default_rng(1)
    a, b = rng.normal(0, 1, (50, 2)), rng.normal(3, 2, (50, 2))
    q = [0.02275, 0.5, 0.97725]
    np.testing.assert_allclose(weighted_quantiles([a], [1.0], q),
                               np.quantile(a, q, axis=0, method="hazen"), rtol=1e-12)
    np.testing.assert_allclose(weighted_quantiles([a, b], [1.0, 0.0], q),
                               np.quantile(a, q, axis=0, method="hazen"), rtol=1e-12)
    pooled = np.vstack([a, b])
    np.testing.assert_allclose(weighted_quantiles([a, b], [0.5, 0.5], q),
                               np.quantile(pooled, q, axis=0, method="hazen"), rtol=1e-12)
    m, s = mix_moments(np.array([a.mean(0), b.mean(0)]), np.array([a.std(0), b.std(0)]),
                        np.array([0.5, 0.5]))
    np.testing.assert_allclose(m, pooled.mean(0), rtol=1e-12)
    np.testing.assert_allclose(s, pooled.std(0), rtol=1e-12)


def test_the_default_forms_follow_a_step_of_the_optics():
    """A step of the optics over a tenth of the heated time (mua x 2.5 over 0.5 s of a 5 s
    pulse, the onset of coagulation), at onset times spread over the pulse: the
    least-squares path through the default's densest form (its knots evenly spread in
    heated time, as the restarts' smoother places them) ends within 0.1 log units of the
    step's final value at every onset and within 0.02 on average; the 6 knots it replaced
    missed by up to 0.29 (0.05 on average), the restarts then settling on the wrong side
    of the mua-mus ridge (``validation/reports/drift_bank.md``)."""
    h = np.linspace(0.0, 5.0, 501)

    def end_errors(n_knots):
        tk = np.linspace(0.0, 5.0, n_knots)
        B = np.stack([np.interp(h, tk, e) for e in np.eye(n_knots)], axis=1)  # hat basis
        out = []
        for onset in np.linspace(0.5, 4.0, 36):
            path = np.log(1.0 + 1.5 * np.clip((h - onset) / 0.5, 0.0, 1.0))
            fit = B @ np.linalg.lstsq(B, path, rcond=None)[0]
            out.append(abs(fit[-1] - path[-1]))
        return np.array(out)

    dense = end_errors(max(k for k in DriftBank().restart_knots if k != "logistic"))
    assert dense.max() < 0.1 and dense.mean() < 0.02
    old = end_errors(6)
    assert old.max() > 0.25 and old.mean() > 0.04


def test_drift_bank_checks_its_settings():
    for kw, what in ((dict(walk_std=(0.03, -1.0)), "walk_std"), (dict(switch_prob=0.7), "switch_prob"),
                     (dict(prior_weight=1.0), "prior_weight"), (dict(restart_knots=(1, 2)), "knots"),
                     (dict(restart_knots=(2, 2)), "knots"), (dict(rtps=2.0), "rtps"),
                     (dict(restart_delay=float("nan")), "restart_delay")):
        with pytest.raises(ValueError, match=what):
            DriftBank(**kw)
    assert DriftBank(walk_std=0.05).walk_std == (0.05, 0.05)


def _drifting_twin(s, times, path, seed=0):
    """One sensor at the origin, the setup's own model with optics ``path(t)`` (the
    twin of a drift), noise var 0.01."""
    model = TissueForwardModel(s)
    P = fem.probe_matrix(model.mesh, np.zeros((3, 1)))
    T = np.zeros((1, model.mesh.p.shape[1]))
    out, t0 = [], 0.0
    for t1 in times:
        T = model(T, np.array([path(0.5 * (t0 + t1))]), t0, t1)
        out.append((P @ T.T)[0, 0])
        t0 = t1
    return np.array(out)[:, None] + 0.1 * np.random.default_rng(seed).standard_normal((len(times), 1))


def _ramp(t):  # doubles both optics over the 2 s pulse, then holds them
    h = min(t, 2.0) / 2.0
    return [1.0 + 1.0 * h, 100.0 + 100.0 * h]


BANK = DriftBank(restart_delay=0.3)


@pytest.fixture(scope="module")
def runs():
    """The bank on a still and on a drifting twin of the small model (a 2 s pulse, 3.5 s)."""
    import sys
    from pathlib import Path

    from mcmatlab_py.heat import HeatSimulation

    sys.path.insert(0, str(Path(__file__).parent))
    from conftest import make_setup, twin_data

    s = make_setup(drift=BANK, power=HeatSimulation(P=0.5, duration_on=2.0,
                                                    duration_off=2.0).laser_power)
    times, still = twin_data(s, 1.3, 80.0, times=0.1 * np.arange(1, 36))
    drift = _drifting_twin(s, times, _ramp)
    return s, times, {"still": (still, identify(s, times, still)),
                      "drifting": (drift, identify(s, times, drift))}


def test_the_bank_tells_still_from_drifting_optics(runs):
    """On the still twin the drift's probability ends below one half (3.5 s of one
    sensor on the small model leave the drifting filter a fair share), on the drifting
    twin above 0.95; the reported estimates follow the supported filter (the drifting one
    restarted from the smoother after the pulse), and the bands hold the truth."""
    s, times, r = runs
    est = r["still"][1]
    assert est.drift_weight.shape == (len(times) + 1,) and est.drift_weight[0] == pytest.approx(0.5)
    assert est.drift_weight[-1] < 0.5 and est.drift_behaviour == "still"
    # a drifting filter restarts where, and only where, its weight against still optics is
    # above the setting
    drifting = [n for n in est.components if n != "still"]
    assert drifting == ["drifting-2", "drifting-9", "drifting-logistic"]
    always = identify(s.with_(drift=replace(BANK, restart_weight=0.0)), times, r["still"][0])
    assert sorted(x["component"] for x in always.restarts) == drifting
    never = identify(s.with_(drift=replace(BANK, restart_weight=1.0)), times, r["still"][0])
    assert not never.restarts
    assert all(not never.components[n].restarts for n in drifting)
    # without a restart the drifting filters are one filter, run once
    assert never.components["drifting-9"] is never.components["drifting-2"]
    est = r["drifting"][1]
    assert est.drift_weight[-1] > 0.95 and est.drift_behaviour == "drifting"
    assert sorted(x["component"] for x in est.restarts) == ["drifting-2", "drifting-9",
                                                            "drifting-logistic"]
    np.testing.assert_allclose(sum(est.component_weights.values()), 1.0, rtol=1e-12)
    np.testing.assert_allclose(est.drift_weight, 1.0 - est.component_weights["still"])
    lo, hi = est.param_band(0)
    assert lo[-1] <= 2.0 <= hi[-1]
    lo, hi = est.param_band(1)
    assert lo[-1] <= 200.0 <= hi[-1]
    lead = est.leading_component
    assert lead.startswith("drifting")
    np.testing.assert_allclose(est.param_mean[-1], est.components[lead].param_mean[-1],
                               rtol=0.05 / est.component_weights[lead][-1])


def test_the_banks_still_filter_is_the_plain_filter(runs):
    """The bank's still filter is the setup's own filter, number for number; the mixture's
    mean is the filters' means weighed by their final weights."""
    s, times, r = runs
    data, est = r["still"]
    plain = identify(s.with_(drift=None), times, data)
    np.testing.assert_array_equal(est.components["still"].param_mean, plain.param_mean)
    np.testing.assert_array_equal(est.components["still"].tracked_std, plain.tracked_std)
    mixed = sum(est.component_weights[n][-1] * e.param_mean[-1]
                for n, e in est.components.items())
    np.testing.assert_allclose(est.param_mean[-1], mixed, rtol=1e-12)


def test_the_drifting_filters_share_their_run_up_to_the_first_restart(runs):
    """The drifting filters are one filter until their first restart: the later forms
    resume the first one's run there (identify_bank's RunHead) and give, number for
    number, what each gives run from the first reading."""
    from enkf.tissue.drift import identify_bank
    from enkf.tissue.identify import identify_single

    s, times, r = runs
    data, est = r["drifting"]

    def from_the_start(*args, head=None, on_head=None, **kw):
        return identify_single(*args, **kw)

    alone = identify_bank(s, times, data, from_the_start)
    first = est.components["drifting-2"].restarts[0]["readings"]
    assert est.component_forks == {"drifting-9": ("drifting-2", first),
                                   "drifting-logistic": ("drifting-2", first)}
    assert alone.component_forks is None
    for name, e in est.components.items():
        a = alone.components[name]
        for key in ("param_mean", "param_std", "tracked_mean", "tracked_std", "param_members",
                    "innovation_loglik"):
            np.testing.assert_array_equal(getattr(e, key), getattr(a, key), err_msg=f"{name} {key}")
        assert [x["readings"] for x in e.restarts] == [x["readings"] for x in a.restarts]
    np.testing.assert_array_equal(est.param_mean, alone.param_mean)
    np.testing.assert_array_equal(est.drift_weight, alone.drift_weight)
    # the resumed filters' steps before their restart are not counted again
    forked = est.components["drifting-9"].step_latency_s[:first].sum()
    assert forked > 0
    assert est.step_latency_s.sum() == pytest.approx(
        sum(e.step_latency_s.sum() for e in est.components.values())
        - 2 * forked, rel=1e-9)


def test_online_bank(runs):
    """One reading at a time: each estimate carries the drift's probability, and it ends
    on the side the batch run ends (the random numbers differ: see OnlineIdentifier)."""
    s, times, r = runs
    for case, side in (("still", False), ("drifting", True)):
        ident = OnlineIdentifier(s)
        for t, y in zip(times, r[case][0], strict=True):
            e = ident.update(t, y)
        assert (e.drift_weight > 0.5) == side
        assert np.all(np.isfinite(e.param_mean)) and e.param_mean.shape == (2,)
        assert len(ident.history) == len(times)
    np.testing.assert_allclose(ident.restart_times, [2.3])


def test_online_drifting_filters_run_once_up_to_the_first_restart(runs):
    """One reading at a time the later drifting filters follow the first one (run once)
    up to its first restart, where each branches off with its own restart: the same
    estimates, weights and members as when each runs from the first reading."""
    s, times, r = runs
    shared, alone = OnlineIdentifier(s), OnlineIdentifier(s)
    assert shared._followers == [2, 3]
    alone._followers = []  # each filter runs every reading
    for t, y in zip(times, r["drifting"][0], strict=True):
        a, b = shared.update(t, y), alone.update(t, y)
        np.testing.assert_array_equal(a.param_mean, b.param_mean)
        np.testing.assert_array_equal(a.tracked_std, b.tracked_std)
        assert a.drift_weight == b.drift_weight
        if not shared.restart_times:
            assert shared._followers == [2, 3]
    assert shared._followers == [] and shared.restart_times == alone.restart_times
    np.testing.assert_allclose(shared.restart_times, [2.3])
    for (na, wa, Xa, ta), (nb, wb, Xb, tb) in zip(shared.filter_ensembles(),
                                                  alone.filter_ensembles(), strict=True):
        assert na == nb and wa == wb
        np.testing.assert_array_equal(Xa, Xb)
        np.testing.assert_array_equal(ta, tb)


def test_setup_refuses_a_bank_it_cannot_run(tissue):
    with pytest.raises(ValueError, match="needs kind = .random_walk."):
        tissue.setup(drift=DriftBank(), parameter_model="trend")
    with pytest.raises(ValueError, match="DriftBank"):
        tissue.setup(drift="auto")


def test_config_drift_table(tmp_path):
    """``[filter.drift]``: "auto" by default (a DriftBank), "none" the filter alone, the
    trend and coagulation models without a bank unless asked (then refused), and bad
    values refused naming the key."""
    from conftest import EXAMPLES

    from enkf.app.config import identify_config_from_dict
    from mcmatlab_py.config import ConfigError, read_toml

    raw = read_toml(EXAMPLES / "tiny.toml")
    raw.pop("data", None)

    def parse(**drift):
        cfg = {**raw, "filter": {**raw.get("filter", {}), **drift}}
        return identify_config_from_dict(cfg).setup_kw.get("drift")

    assert isinstance(parse(), DriftBank)
    assert parse(drift={"mode": "none"}) is None
    bank = parse(drift={"walk_std": [0.05, 0.2], "restart_knots": [2, 4], "restart_delay": 1.0})
    assert bank.walk_std == (0.05, 0.2) and bank.restart_knots == (2, 4)
    assert parse(parameter_model="trend") is None
    for bad, key in (({"mode": "yes"}, "filter.drift.mode"),
                     ({"walk_std": [0.1]}, "filter.drift.walk_std"),
                     ({"switch_prob": 0.9}, "filter.drift.switch_prob"),
                     ({"restart_knots": [1, 2]}, "filter.drift.restart_knots"),
                     ({"typo": 1}, "filter.drift.typo")):
        with pytest.raises(ConfigError, match=key):
            parse(drift=bad)
    with pytest.raises(ConfigError, match="parameter_model"):
        parse(parameter_model="trend", drift={"mode": "auto"})


def _fake(z, laser_on, drift=None):
    from types import SimpleNamespace

    from enkf.tissue.estimates import laser_persistence

    est = SimpleNamespace(innovation_normalized=z, laser_on=laser_on, sensor_offset_mean=None,
                          drift_weight=None if drift is None else np.array([0.5, drift]))
    est.innovation_persistence = lambda laser="off": laser_persistence(z, laser_on, laser)
    return est


def test_the_likely_cause_from_the_innovations():
    """White innovations: no cause. Persistent ones while the laser is off: the model's
    physics. The same with the first readings all high: a sensor offset. Persistent while
    heated only, with no bank: drifting optics. A bank that supports a drift: drifting
    optics, and no advice; if the innovations persist while cooling too, the model's
    physics (the optics act on nothing then)."""
    from enkf.tissue.estimates import persistence_summary

    rng = np.random.default_rng(3)
    on = np.arange(150) < 50
    white = rng.standard_normal((150, 1))
    assert persistence_summary(_fake(white, on))["likely_cause"] is None
    slow = np.cumsum(rng.standard_normal((150, 1)), axis=0) * 0.3
    slow -= slow[:5].mean()
    s = persistence_summary(_fake(slow, on))
    assert s["likely_cause"] == "model physics" and "docs/beyond.md" in s["advice"]
    s = persistence_summary(_fake(slow + 3.0 * (np.arange(150) < 10)[:, None], on))
    assert s["likely_cause"] == "sensor offset" and "sensor_offset_std" in s["advice"]
    heated = np.where(on[:, None], slow, white)
    s = persistence_summary(_fake(heated, on))
    assert s["likely_cause"] == "drifting optics" and "[filter.drift]" in s["advice"]
    s = persistence_summary(_fake(white, on, drift=0.99))
    assert s["likely_cause"] == "drifting optics" and s["advice"] is None and not s["flagged"]
    # persistent while the laser is off: the heat model's, whatever the bank says
    s = persistence_summary(_fake(slow, on, drift=0.99))
    assert s["likely_cause"] == "model physics" and s["flagged"] and "P = 0.99" in s["advice"]


def test_the_command_line_reports_the_drift(tmp_path):
    """identify's default is the bank: estimates.csv's drift_weight column, summary.json's
    drift (behaviour, final weight, each filter's estimates), the printed line; with
    --follow the same column in the live estimates and run.json's drift; mode = "none"
    gives the filter alone, as before."""
    import json

    from conftest import EXAMPLES

    from enkf.app.cli import main

    cache = str(tmp_path / "cache")
    out = tmp_path / "run"
    assert main(["identify", str(EXAMPLES / "tiny.toml"), "--data",
                 str(EXAMPLES / "tiny_data.csv"), "--out", str(out), "--quiet",
                 "--cache-dir", cache]) == 0
    header = (out / "estimates.csv").read_text().splitlines()[0].split(",")
    assert "drift_weight" in header
    d = json.loads((out / "summary.json").read_text())["drift"]
    assert d["behaviour"] in ("still", "drifting") and 0 <= d["weight_final"] <= 1
    assert set(d["components"]) == {"still", "drifting-2", "drifting-9", "drifting-logistic"}
    assert sum(c["weight_final"] for c in d["components"].values()) == pytest.approx(1.0)
    live = tmp_path / "live"
    assert main(["identify", str(EXAMPLES / "tiny.toml"), "--follow",
                 str(EXAMPLES / "tiny_data.csv"), "--out", str(live), "--quiet",
                 "--cache-dir", cache, "--idle-timeout", "1"]) == 0
    rows = (live / "estimates.csv").read_text().splitlines()
    assert rows[0].endswith(",drift_weight") and len(rows) > 10
    w = [float(r.split(",")[-1]) for r in rows[1:]]
    assert all(0 <= x <= 1 for x in w)
    assert json.loads((live / "run.json").read_text())["drift"]["weight_final"] == pytest.approx(
        w[-1], rel=1e-6)
    cfg = tmp_path / "none.toml"
    cfg.write_text((EXAMPLES / "tiny.toml").read_text() + "\n[filter.drift]\nmode = \"none\"\n")
    assert main(["identify", str(cfg), "--data", str(EXAMPLES / "tiny_data.csv"), "--out",
                 str(tmp_path / "none"), "--quiet", "--cache-dir", cache]) == 0
    assert "drift" not in json.loads((tmp_path / "none" / "summary.json").read_text())


def test_paper_filter_with_the_bank(tissue):
    """``filter_setup(..., drift="auto")``: the constant scenario's filter inside a bank
    (walk 0.002, no relaxation), whatever the scenario; "paper" keeps the scenario's walk."""
    from enkf.paper import filter_setup

    s = filter_setup("time-varying", tissue.absorption, drift="auto")
    assert isinstance(s.parameters.drift, DriftBank) and s.parameters.random_walk_std == 0.002
    assert s.model_error.rtps == 0.0
    assert filter_setup("time-varying", tissue.absorption).parameters.drift is None
    with pytest.raises(ValueError, match="drift"):
        filter_setup("constant", tissue.absorption, drift="maybe")
