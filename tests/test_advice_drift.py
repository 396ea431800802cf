"""The advice's forecast under drifting optics (enkf.tissue.advice, issue #53): the members'
optics carried on piece by piece against the forward model run by hand with the same
optics, the walk's spread against the filter's own walk, each member's trend recovered
from a linear drift, still optics held, and the bank's filters told apart."""

import sys
from pathlib import Path

import numpy as np
import pytest

from enkf.problem import StepReport
from enkf.tissue import TissueForwardModel
from enkf.tissue.advice import Advisor, Plan
from enkf.tissue.advice.forecast import heat
from enkf.tissue.drift import DriftBank

sys.path.insert(0, str(Path(__file__).parent))
from test_advice import LIMITS, hot_setup, members  # noqa: E402

WALK = (0.03, 0.10)  # log units a heated step: the drift bank's drifting walk


def test_plan_on_time():
    plan = Plan(1.0, ((0.0, 1.0), (2.0, 2.5)))
    assert plan.on_time(0.5, 2.2) == pytest.approx(0.7)
    assert plan.on_time(1.0, 2.0) == 0.0
    assert Plan(0.0, ((0.0, 1.0),)).on_time(0.0, 1.0) == 0.0  # no power: nothing heats


@pytest.mark.parametrize("engine", ["adjoint", "direct"])
def test_drifting_optics_forecast_is_the_forward_model_run_by_hand(tissue, engine):
    adv = Advisor(hot_setup(tissue, random_walk_std=list(WALK)), engine=engine, **LIMITS)
    X, theta = members(adv)
    t0, K = 0.4, adv.K - 4
    thetas, seg = adv.optics_paths(None, theta, t0, K)
    assert thetas.shape[1:] == theta.shape and len(thetas) == 6  # 0.4-3 s in 0.5 s pieces
    assert not np.allclose(thetas[-1], theta)
    H, _ = adv.forecast.responses(X, theta, K)
    G = np.stack([adv.forecast.load_responses(th, K) for th in thetas], axis=1)
    P = np.array([adv.plan.mean_power(t0 + k * 0.1, t0 + (k + 1) * 0.1) for k in range(K)])
    model = TissueForwardModel(adv.setup)
    for c in (K, 0, 9):  # the plan, off now, off after 9 steps
        T, want = np.array(X), [adv.P @ X.T]
        for k in range(K):  # each step at the optics of its piece
            T = model.step(T, thetas[seg[k]], 0.0, 0.1, P[k] if k < c else 0.0)
            want.append(adv.P @ T.T)
        np.testing.assert_allclose(heat(H, G, P, np.full(len(X), c), seg),
                                   np.array(want).transpose(2, 0, 1), rtol=0, atol=1e-7)
    # one piece for every step: the held optics' forecast
    Gh = adv.forecast.load_responses(theta, K)
    np.testing.assert_allclose(heat(H, Gh[:, None], P, np.full(len(X), K), np.zeros(K, int)),
                               heat(H, Gh, P, np.full(len(X), K)), rtol=0, atol=1e-12)


def test_the_walk_spreads_as_the_filters_own_walk(tissue):
    adv = Advisor(hot_setup(tissue, random_walk_std=list(WALK)), drift="walk", **LIMITS)
    N = 4000
    theta = np.tile([1.0, 100.0], (N, 1))
    thetas, seg = adv.optics_paths(None, theta, 0.0, adv.K)
    assert len(thetas) == 6 and seg.max() == 5  # the pulse's 3 s; nothing drifts off
    d = np.log(thetas / theta)
    for s, steps in enumerate((2.5, 7.5, 12.5, 17.5, 22.5, 27.5)):  # walk steps to the middle
        sd = np.array(WALK) * np.sqrt(steps)
        se = sd / np.sqrt(2 * N)  # the sd's standard error
        np.testing.assert_array_less(np.abs(d[s].std(axis=0) - sd), 4 * se)
        np.testing.assert_array_less(np.abs(d[s].mean(axis=0)), 4 * sd / np.sqrt(N))
    # the same seed draws the same walk; another seed another
    again = adv.optics_paths(None, theta, 0.0, adv.K)[0]
    np.testing.assert_array_equal(again, thetas)
    other = Advisor(hot_setup(tissue, random_walk_std=list(WALK)), drift="walk", seed=1,
                    **LIMITS).optics_paths(None, theta, 0.0, adv.K)[0]
    assert not np.allclose(other, thetas)


def _report(k, t, theta, X):
    return StepReport(k, t, True, 0.0, theta.mean(0), theta.std(0), np.zeros(2), np.zeros(2),
                      X, theta, component=None)


def test_the_trend_is_each_members_slope(tissue):
    setup = hot_setup(tissue, random_walk_std=list(WALK))
    adv = Advisor(setup, **LIMITS)  # drift="walk+trend"
    rng = np.random.default_rng(3)
    N = 6
    v = np.column_stack([rng.uniform(-0.5, 0.5, N), rng.uniform(-0.5, 0.5, N)])  # 1/s
    base = np.column_stack([rng.uniform(0.8, 1.2, N), rng.uniform(80, 120, N)])
    X = np.full((N, adv.model.mesh.p.shape[1]), 37.0)
    assert np.all(adv.trend(None) == 0)
    for k in range(16):  # 1.5 s of heating, readings every 0.1 s
        t = 0.1 * k
        adv(_report(k, t, base * np.exp(v * t), X))
        if k == 0:  # the start alone: no slope yet
            assert np.all(adv.trend(None) == 0)
        else:  # from the second reading, over the readings so far (then the last 1 s)
            np.testing.assert_allclose(adv.trend(None), v, rtol=0, atol=1e-10)
    # the trend moves each member's optics by its slope times the heated time ahead
    theta = base * np.exp(v * 1.5)
    with_trend, seg = adv.optics_paths(None, theta, 1.5, adv.K)
    walk_only = Advisor(setup, drift="walk", **LIMITS).optics_paths(None, theta, 1.5, adv.K)[0]
    h_mid = np.array([0.25, 0.75, 1.25])  # heated s to the middles of 1.5-2, 2-2.5, 2.5-3 s
    np.testing.assert_allclose(np.log(with_trend / walk_only), h_mid[:, None, None] * v,
                               rtol=0, atol=1e-10)


def test_still_optics_hold(tissue):
    adv = Advisor(hot_setup(tissue), **LIMITS)  # the default walk, 0.002: still optics
    X, theta = members(adv)
    assert adv.optics_paths(None, theta, 0.0, adv.K) is None
    held = Advisor(hot_setup(tissue), drift="hold", **LIMITS)
    for a in (adv, held):
        a(_report(0, 0.0, theta, X))
    a, b = adv.tracks[None].advice[0], held.tracks[None].advice[0]
    np.testing.assert_array_equal(a.target_time, b.target_time)
    np.testing.assert_array_equal(a.stop_time, b.stop_time)


def test_the_banks_still_filter_holds_and_its_drifting_ones_drift(tissue):
    adv = Advisor(hot_setup(tissue, drift=DriftBank(restart_knots=(2,))), **LIMITS)
    X, theta = members(adv)
    assert set(adv.walks) == {"still", "drifting-2"}
    assert adv.optics_paths("still", theta, 0.0, adv.K) is None
    thetas, _ = adv.optics_paths("drifting-2", theta, 0.0, adv.K)
    assert not np.allclose(thetas[-1], theta)


def test_bad_drift_arguments_are_refused(tissue):
    with pytest.raises(ValueError, match="Advisor.drift must be one of"):
        Advisor(hot_setup(tissue), drift="trend", **LIMITS)
    for name in ("trend_window", "drift_step", "hold_below"):
        with pytest.raises(ValueError, match=f"Advisor.{name} must be"):
            Advisor(hot_setup(tissue), **{name: 0.0}, **LIMITS)
    with pytest.raises(ValueError, match="random_walk.*coagulation"):
        Advisor(hot_setup(tissue, parameter_model="coagulation"), **LIMITS)


def test_the_online_identifiers_filters_for_the_advice(tissue):
    from enkf.tissue import OnlineIdentifier

    ident = OnlineIdentifier(hot_setup(tissue))
    ident.update(0.1, [37.5])
    ((name, w, X, theta),) = ident.filter_ensembles()
    assert name is None and w == 1.0
    assert X is ident.state_ensemble and theta is ident.param_ensemble
    bank = OnlineIdentifier(hot_setup(tissue, drift=DriftBank(restart_knots=(2,))))
    bank.update(0.1, [37.5])
    parts = bank.filter_ensembles()
    assert [p[0] for p in parts] == ["still", "drifting-2"]
    assert sum(p[1] for p in parts) == pytest.approx(1.0)
    lead = max(parts, key=lambda p: p[1])
    assert bank.param_ensemble is lead[3] and bank.state_ensemble is lead[2]


def test_drifting_loads_in_single_precision_agree_with_double(tissue):
    # the drifting optics' S x N load responses take the product over the nodes in float32
    # (Advisor.drift_dtype): each response within float32's rounding of that sum and of
    # its inputs, lambda sqrt(n) u |Q| |B| |q| with lambda = 2 (u = 2^-24; the probabilistic
    # bound of Higham & Mary 2019, SIAM J. Sci. Comput. 41; measured up to 0.8 of it at
    # lambda = 1)
    adv = Advisor(hot_setup(tissue, random_walk_std=list(WALK)), drift="walk", **LIMITS)
    assert adv.drift_dtype == np.float32
    X, theta = members(adv, n=20, seed=4)
    X = np.minimum(X, 40.0)  # every member needs the laser
    t0, K = 0.4, adv.K - 4
    thetas, _ = adv.optics_paths(None, theta, t0, K)
    flat = thetas.reshape(-1, theta.shape[1])
    G32 = adv.forecast.load_responses(flat, K, np.float32)
    G64 = adv.forecast.load_responses(flat, K)
    assert G32.dtype == np.float64
    (Q, B), q = adv.forecast.W, adv.model.loads(flat, 1.0)
    bound = 2 * np.sqrt(B.shape[1]) * 2.0 ** -24 * (np.abs(Q[:K * G64.shape[2]])
                                               @ (np.abs(B) @ np.abs(q).T)).T.reshape(G64.shape)
    np.testing.assert_array_less(np.abs(G32 - G64), bound)
    # the advice: the same walk drawn (seeded by the reading), times within 1e-4 s (7e-7 s
    # measured), the risks the same; the members' own spread of the target time (the
    # walk's Monte Carlo, 0.5 s) is more than 4 orders larger
    tr = adv._track("x", t0, X, 0, theta)
    single = adv.member_advice(tr, X, theta)
    adv.drift_dtype = np.float64
    double = adv.member_advice(tr, X, theta)
    assert np.isfinite(double.target_time).all()
    dt = np.abs(single.target_time - double.target_time).max()
    np.testing.assert_allclose(single.target_time, double.target_time, rtol=0, atol=1e-4)
    np.testing.assert_allclose(single.stop_time, double.stop_time, rtol=0, atol=1e-4)
    assert np.std(double.target_time) > 1e4 * dt
    for k in double.risks:
        np.testing.assert_array_equal(single.risks[k], double.risks[k])
