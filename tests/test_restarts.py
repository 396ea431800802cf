"""Restarts of the filter from the smoother (``TissueFilterSetup.smoother_restarts``): where
they happen, that the restarted ensemble is the smoother's, that the filter before a
restart is the plain filter, the online identifier, and the checks."""

from __future__ import annotations

import numpy as np
import pytest

from enkf.tissue import TissueForwardModel, identify
from enkf.tissue.online import OnlineIdentifier
from enkf.tissue.pieces import assemble
from enkf.tissue.restart import restart_ensemble, restart_points
from enkf.tissue.smooth import smooth_constant, smooth_drifting


def _setup(tissue, **kw):
    return tissue.setup(random_walk_std=0.0, **kw)


def test_restart_points(tissue):
    """The tiny setup's laser heats for 1 s: "laser_off" restarts after the first reading
    at or after its end (1.0 s, the 10th); times restart after the first reading at or after each; none
    without the setting."""
    times = 0.1 * np.arange(1, 21)
    assert restart_points(_setup(tissue, smoother_restarts="laser_off"), times) == [10]
    assert restart_points(_setup(tissue, smoother_restarts=(0.55, 1.5, 2.0)), times) == [
        6, 15, 20]
    assert restart_points(_setup(tissue, smoother_restarts=(5.0,)), times) == []
    assert restart_points(_setup(tissue), times) == []
    # a delay after the pulse's end
    assert restart_points(_setup(tissue, smoother_restarts="laser_off",
                                 smoother_restart_delay=0.25), times) == [13]
    # no restart before the first finite reading (the smoother needs one)
    data = np.full((20, 1), np.nan)
    assert restart_points(_setup(tissue, smoother_restarts=(0.55, 1.5)), times, data) == []
    data[12] = 1.0
    assert restart_points(_setup(tissue, smoother_restarts=(0.55, 1.5)), times, data) == [15]
    # readings every 0.3 s: the first after the pulse's end is the one at 1.2 s
    assert restart_points(_setup(tissue, smoother_restarts="laser_off"),
                          0.3 * np.arange(1, 7)) == [4]


def _log_moments(theta):
    U = np.log(theta)
    return U.mean(axis=0), np.cov(U.T)


def test_the_restarted_ensemble_is_the_smoothers(tissue):
    """Up to a restart the run is the plain filter's, step for step; the row of the
    restart's reading holds the smoother's ensemble over the readings so far: its members
    (``smoother_restart_gaussian = False``), or a log-normal draw with their log mean and
    covariance exactly; the members' temperatures are re-run with their optics; a restart
    after the last reading makes the final estimate the smoother's over the whole window."""
    s0 = _setup(tissue)
    times, data = tissue.twin_data(s0, 1.3, 80.0)
    plain = identify(s0, times, data)
    s = _setup(tissue, smoother_restarts="laser_off", smoother_restart_iterations=3,
               smoother_restart_gaussian=False)
    est = identify(s, times, data)
    np.testing.assert_array_equal(est.param_mean[:10], plain.param_mean[:10])
    np.testing.assert_array_equal(est.tracked_mean[:10], plain.tracked_mean[:10])
    sm = smooth_constant(s, times[:10], data[:10], n_iter=3)
    np.testing.assert_allclose(est.param_mean[10], sm.mean, rtol=1e-12)
    np.testing.assert_allclose(est.param_std[10], sm.std, rtol=1e-12)
    g = _setup(tissue, smoother_restarts="laser_off", smoother_restart_iterations=3,
               model_noise_std=0.0)  # no model error: the re-run is the optics' own
    X, theta, _ = restart_ensemble(g, assemble(g, warm_dt=0.1), times[:10], data[:10])
    for a, b in zip(_log_moments(theta), _log_moments(sm.theta), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-14)
    assert not np.allclose(np.sort(theta, axis=0), np.sort(sm.theta, axis=0))
    np.testing.assert_allclose(identify(g, times, data).param_mean[10], theta.mean(axis=0),
                               rtol=1e-12)
    # the temperatures: each member's own run at its optics (the twin's generator at a
    # member's optics gives its surface temperature before the noise)
    model = TissueForwardModel(g)
    T = np.zeros((2, model.mesh.p.shape[1]))
    for t0, t1 in zip(np.r_[0.0, times[:9]], times[:10], strict=True):
        T = model(T, np.ascontiguousarray(theta[:2]), t0, t1)
    np.testing.assert_allclose(X[:2], T, rtol=1e-12)
    (r,) = est.restarts
    assert r["time_s"] == pytest.approx(1.0) and r["readings"] == 10 and r["wall_s"] > 0
    assert est.param_mean.shape == plain.param_mean.shape == (21, 2)
    assert est.analysed.shape == (20,) and est.step_latency_s.shape == (20,)
    assert np.all(np.isfinite(est.tracked_mean)) and np.all(np.isfinite(est.param_q_low))
    # the run goes on from the restart: the steps after it differ from the plain filter's
    assert not np.allclose(est.param_mean[11:], plain.param_mean[11:])
    # after the last reading too
    end = identify(_setup(tissue, smoother_restarts=(2.0,), smoother_restart_iterations=3,
                          smoother_restart_gaussian=False),
                   times, data)
    sm = smooth_constant(s, times, data, n_iter=3)
    np.testing.assert_allclose(end.param_mean[-1], sm.mean, rtol=1e-12)
    np.testing.assert_array_equal(end.param_mean[:-1], plain.param_mean[:-1])
    lo, hi = end.param_band(0)
    assert lo[-1] < sm.mean[0] < hi[-1]


def test_the_online_identifier_restarts_too(tissue):
    """One reading at a time: after the pulse's last reading the estimate is the
    smoother's over the readings so far."""
    s = _setup(tissue, smoother_restarts="laser_off", smoother_restart_iterations=2,
               smoother_restart_gaussian=False)
    times, data = tissue.twin_data(s, 1.3, 80.0)
    online = OnlineIdentifier(s)
    out = [online.update(t, y) for t, y in zip(times, data, strict=True)]
    assert online.restart_times == [pytest.approx(1.0)]
    sm = smooth_constant(s, times[:10], data[:10], n_iter=2)
    np.testing.assert_allclose(out[9].param_mean, sm.mean, rtol=1e-12)
    assert all(np.all(np.isfinite(o.param_mean)) for o in out)


@pytest.mark.parametrize("kw, match", [
    (dict(smoother_restarts="sometimes"), "SmootherRestarts.times must be times .s. or 'laser_off'"),
    (dict(smoother_restarts=(1.0, 0.5)), "SmootherRestarts.times must be increasing times > 0"),
    (dict(smoother_restarts=(-1.0,)), "SmootherRestarts.times must be increasing times > 0"),
    (dict(smoother_restarts=(np.nan,)), "SmootherRestarts.times must be increasing times > 0"),
    (dict(smoother_restarts="laser_off", smoother_restart_iterations=0),
     "SmootherRestarts.iterations must be an integer >= 1"),
    (dict(smoother_restarts="laser_off", smoother_restart_discrepancy=-0.1),
     "SmootherRestarts.discrepancy must be >= 0"),
    (dict(smoother_restarts="laser_off", smoother_restart_discrepancy_time=0.0),
     "SmootherRestarts.discrepancy_time must be > 0"),
    (dict(smoother_restarts=(1.0,), smoother_restart_delay=1.0),
     "SmootherRestarts.delay = 1.0 is for times = 'laser_off'"),
    (dict(smoother_restarts="laser_off", smoother_restart_delay=-1.0),
     "SmootherRestarts.delay must be >= 0"),
    (dict(smoother_restarts="laser_off", random_walk_std=0.002),
     "smoother_restarts needs constant optics"),
    (dict(smoother_restarts="laser_off", parameter_model="trend"),
     "smoother_restarts needs constant optics"),
    (dict(smoother_restarts="laser_off", sensor_offset_std=0.5),
     "smoother_restarts does not estimate sensor offsets"),
])
def test_bad_restarts_are_refused(tissue, kw, match):
    with pytest.raises(ValueError, match=match):
        tissue.setup(**{"random_walk_std": 0.0, **kw})


def test_drifting_restarts_take_the_smoothers_optics_at_the_reading(tissue):
    """``smoother_restart_knots >= 2``: optics drifting while heated; the restart's row
    holds smooth_drifting's values at the window's end, and the walk goes on after it."""
    s = tissue.setup(random_walk_std=0.03, smoother_restarts="laser_off",
                     smoother_restart_knots=2, smoother_restart_iterations=2,
                     smoother_restart_gaussian=False, model_noise_std=0.0)
    times, data = tissue.twin_data(s, 1.3, 80.0)
    est = identify(s, times, data)
    sm = smooth_drifting(s, times[:10], data[:10], knots=2, n_iter=2)
    np.testing.assert_allclose(est.param_mean[10], sm.mean, rtol=1e-12)
    # the members' temperatures: re-run along their own paths (optics linear in heated
    # time between the knots), not at their final optics
    X, theta, _ = restart_ensemble(s, assemble(s, warm_dt=0.1), times[:10], data[:10])
    np.testing.assert_allclose(theta, sm.theta, rtol=1e-12)
    model = TissueForwardModel(s)
    T, T_end = (np.zeros((2, model.mesh.p.shape[1])) for _ in range(2))
    for t0, t1 in zip(np.r_[0.0, times[:9]], times[:10], strict=True):
        w = 0.5 * (t0 + t1) / 1.0  # heated time over the 1 s pulse: the knots at 0 and 1 s
        T = model(T, np.ascontiguousarray((1 - w) * sm.knots[:2, 0] + w * sm.knots[:2, 1]),
                  t0, t1)
        T_end = model(T_end, np.ascontiguousarray(sm.theta[:2]), t0, t1)
    np.testing.assert_allclose(X[:2], T, rtol=1e-10)
    assert not np.allclose(X[:2], T_end, rtol=1e-3)
    # a log-normal ensemble of the knots' moments: its end values differ from the members'
    g = tissue.setup(random_walk_std=0.03, smoother_restarts="laser_off",
                     smoother_restart_knots=2, smoother_restart_iterations=2)
    Xg, theta_g, _ = restart_ensemble(g, assemble(g, warm_dt=0.1), times[:10], data[:10])
    assert np.all(np.isfinite(Xg)) and np.all(theta_g > 0)
    np.testing.assert_allclose(np.log(theta_g).mean(axis=0), np.log(sm.theta).mean(axis=0),
                               rtol=1e-10)
    assert len(est.restarts) == 1 and np.all(np.isfinite(est.param_mean))
    with pytest.raises(ValueError, match="SmootherRestarts.knots must be an integer >= 1"):
        tissue.setup(smoother_restarts="laser_off", smoother_restart_knots=0)


def test_a_mixture_of_drift_forms_gives_a_block_of_members_each(tissue):
    """``smoother_restart_knots = (2, 3)``: the first half of the restarted members are the
    2-knot smoother's (the same members as a 2-knot restart gives them), the second half the
    3-knot smoother's; the counts must differ and be >= 2."""
    kw = dict(random_walk_std=0.03, smoother_restarts="laser_off", smoother_restart_iterations=2,
              smoother_restart_gaussian=False)
    s = tissue.setup(smoother_restart_knots=(2, 3), **kw)
    assert s.restarts.knot_forms == (2, 3) and s.restarts.drifts
    times, data = tissue.twin_data(s, 1.3, 80.0)
    X, theta, _ = restart_ensemble(s, assemble(s, warm_dt=0.1), times[:10], data[:10])
    h = theta.shape[0] // 2
    for k, block in ((2, slice(0, h)), (3, slice(h, None))):
        one = tissue.setup(smoother_restart_knots=k, **kw)
        X1, theta1, _ = restart_ensemble(one, assemble(one, warm_dt=0.1), times[:10], data[:10])
        np.testing.assert_allclose(theta[block], theta1[block], rtol=1e-12)
        np.testing.assert_allclose(X[block], X1[block], rtol=1e-9, atol=1e-12)
    assert len(identify(s, times, data).restarts) == 1
    for bad in ((1, 3), (3, 3), ()):
        with pytest.raises(ValueError, match="SmootherRestarts.knots"):
            tissue.setup(**{**kw, "smoother_restart_knots": bad})


def test_the_restarted_members_carry_the_model_error(tissue):
    """The re-run after a restart draws the filter's model error: the structured error
    spreads the members' temperatures beyond their optics' spread (the same optics, the
    white floor at 0 then give one trace per optics)."""
    times, data = tissue.twin_data(_setup(tissue), 1.3, 80.0)
    spread = {}
    for kind in ("white", "structured"):
        s = _setup(tissue, smoother_restarts="laser_off", smoother_restart_iterations=2,
                   model_error=kind, model_noise_std=0.0, model_error_rel_std=0.2)
        X, theta, _ = restart_ensemble(s, assemble(s, warm_dt=0.1), times[:10], data[:10])
        model = TissueForwardModel(s)
        T = np.zeros_like(X)
        for t0, t1 in zip(np.r_[0.0, times[:9]], times[:10], strict=True):
            T = model(T, np.ascontiguousarray(theta), t0, t1)
        spread[kind] = np.abs(X - T).max()
    assert spread["white"] < 1e-9 < 1e-3 < spread["structured"], spread


def test_restart_settings_that_cannot_run_are_refused(tissue):
    """Drifting restarts need a walk, and the log-normal draw more members than the
    restart's free values (the parameters, and every knot of the drifting ones); the
    drifting parameters are those that walk."""
    with pytest.raises(ValueError, match="smoother_restart_knots = 3 is for drifting optics"):
        _setup(tissue, smoother_restarts="laser_off", smoother_restart_knots=3)
    with pytest.raises(ValueError, match=r"more members than the restart's free values \(6"):
        tissue.setup(random_walk_std=0.03, smoother_restarts="laser_off",
                     smoother_restart_knots=3, n_members=6)
    s = tissue.setup(random_walk_std=[0.03, 0.0], smoother_restarts="laser_off",
                     smoother_restart_knots=3, n_members=6)  # 2 + 2 free values
    assert s.parameters.walking == ("mua",)
    with pytest.raises(ValueError, match="SmootherRestarts.gaussian must be True or False"):
        _setup(tissue, smoother_restarts="laser_off", smoother_restart_gaussian="false")
    with pytest.raises(ValueError, match="SmootherRestarts.iterations must be an integer"):
        _setup(tissue, smoother_restarts="laser_off", smoother_restart_iterations=True)


def test_an_online_restart_the_smoother_refuses_is_skipped(tissue, monkeypatch):
    """A live stream too long for the discrepancy's dense covariance: the restart is
    skipped with a warning and the filter goes on."""
    import enkf.tissue.smooth as sm

    monkeypatch.setattr(sm, "MAX_DISCREPANCY_READINGS", 5)
    s = _setup(tissue, smoother_restarts="laser_off", smoother_restart_iterations=2,
               smoother_restart_discrepancy=0.01)
    times, data = tissue.twin_data(s, 1.3, 80.0)
    online = OnlineIdentifier(s)
    with pytest.warns(RuntimeWarning, match="restart after the reading at t = 1 s is skipped"):
        out = [online.update(t, y) for t, y in zip(times, data, strict=True)]
    assert online.restart_times == [] and len(out) == 20
    assert all(np.all(np.isfinite(o.param_mean)) for o in out)


def test_the_callback_sees_the_restarted_members_re_run(tissue):
    """After a restart the callback gets the restarted members' re-run from step 0
    (``replayed``), ending at the restarted ensemble, then the filter's steps: a
    RiskTracker then integrates each member's damage along its own history, which is not
    what the filter's members before the restart had."""
    from enkf.tissue.risk import RiskTracker

    s = _setup(tissue, smoother_restarts="laser_off", smoother_restart_iterations=2)
    times, data = tissue.twin_data(s, 1.3, 80.0)
    reps = []
    identify(s, times, data, callback=lambda rep: reps.append(
        (rep.step, rep.time, rep.replayed, rep.state_ensemble.copy(), rep.param_ensemble.copy())))
    steps = [(k, r) for k, _, r, _, _ in reps]
    M = len(times)
    assert steps == ([(k, False) for k in range(11)] + [(k, True) for k in range(11)]
                     + [(k, False) for k in range(11, M + 1)])
    X, theta, _ = restart_ensemble(s, assemble(s, warm_dt=0.1), times[:10], data[:10])
    replay = [r for r in reps if r[2]]
    np.testing.assert_allclose(replay[-1][3], X, rtol=1e-12)  # the restarted ensemble
    np.testing.assert_allclose(replay[-1][4], theta, rtol=1e-12)
    assert replay[0][1] == 0.0 and replay[-1][1] == pytest.approx(times[9])
    # a damage law hot enough to count at these temperatures (a few deg C above 0)
    law = dict(E=1e5, A=1e16)
    risk = RiskTracker(**law)
    for k, t, _, Xk, _ in reps:
        risk.update(t, Xk, step=k)
    fresh = RiskTracker(**law)  # only the re-run and what follows
    for k, t, _, Xk, _ in [r for r in reps if r[2] or r[0] > 10]:
        fresh.update(t, Xk, step=k)
    np.testing.assert_allclose(risk.omega, fresh.omega, rtol=1e-12)
    old = RiskTracker(**law)  # the filter's steps alone, as before the replay
    for k, t, _, Xk, _ in [r for r in reps if not r[2]]:
        old.update(t, Xk, step=k)
    assert not np.allclose(old.omega, risk.omega, rtol=1e-3)


def test_a_restarted_ensemble_that_fails_the_health_check_keeps_its_own_row(tissue,
                                                                             monkeypatch):
    """A restart whose ensemble fails the health check (here: every member the same
    optics) stops the run there, and the row of that reading is the restarted ensemble's
    in full: its optics and its members' temperatures, not the filter's before it."""
    import sys

    ti = sys.modules["enkf.tissue.identify"]  # the package exports the function identify
    real = ti.restart_ensemble

    def collapsed(*args, **kw):
        X, theta, w = real(*args, **kw)
        return X, np.repeat(theta[:1], theta.shape[0], axis=0), w

    monkeypatch.setattr(ti, "restart_ensemble", collapsed)
    s = _setup(tissue, smoother_restarts="laser_off", smoother_restart_iterations=2)
    times, data = tissue.twin_data(s, 1.3, 80.0)
    est = identify(s, times, data)
    assert est.diverged is not None and "restart" in est.diverged
    assert len(est.times) == 11 and np.all(est.param_std[10] < 1e-9 * est.param_mean[10])
    X, theta, _ = collapsed(s, assemble(s, warm_dt=0.1), times[:10], data[:10])
    T = (assemble(s).P_track @ X.T).T
    np.testing.assert_allclose(est.tracked_mean[10], T.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(est.param_mean[10], theta[0], rtol=1e-12)


def test_the_inflation_estimate_runs_across_the_restarts(tissue, monkeypatch):
    """identify, as the online identifier: the adaptive inflation's running estimate is
    one object through every segment (not a fresh one after each restart), and the
    online identifier's structured model error starts afresh with the restarted members,
    as identify's segments do."""
    import sys

    ti = sys.modules["enkf.tissue.identify"]
    real, seen = ti.run_filter, []

    def spy(*args, **kw):
        seen.append(kw.get("inflation_state"))
        return real(*args, **kw)

    monkeypatch.setattr(ti, "run_filter", spy)
    s = _setup(tissue, smoother_restarts="laser_off", smoother_restart_iterations=2,
               adaptive_inflation=True, model_error="structured")
    times, data = tissue.twin_data(s, 1.3, 80.0)
    est = identify(s, times, data)
    assert est.diverged is None and len(est.restarts) == 1
    assert len(seen) == 2 and seen[0] is not None and seen[1] is seen[0]
    online = OnlineIdentifier(s)
    for t, y in zip(times[:10], data[:10], strict=True):
        online.update(t, y)
    assert online.restart_times == [pytest.approx(1.0)] and online._noise._r is None
    online.update(times[10], data[10])
    assert online._noise._r is not None


def test_laser_off_sees_a_pulse_between_two_readings(tissue):
    """``laser_off``: a pulse that starts and ends between two readings, or a pause shorter
    than their interval, ends a pulse too (the laser looked at between the readings, not
    only at them)."""
    from mcmatlab_py.heat import HeatSimulation

    HS = HeatSimulation(P=1.0, duration_on=0.03, duration_off=1.0, n_pulses=1)
    s = _setup(tissue, smoother_restarts="laser_off", power=HS.laser_power)
    assert s.restart_after(0.0, 0.1)  # on at 0 and off at 0.1: the plain case
    late = HeatSimulation(P=1.0, duration_on=0.03, duration_off=1.0, n_pulses=1)
    s = _setup(tissue, smoother_restarts="laser_off", power=lambda t: late.laser_power(t - 1.03))
    assert not s.restart_after(0.9, 1.0)
    assert s.restart_after(1.0, 1.1)  # a 30 ms pulse from 1.03 s, between two readings
    assert not s.restart_after(1.1, 1.2)
    train = HeatSimulation(P=1.0, duration_on=0.08, duration_off=0.01, n_pulses=3)
    s = _setup(tissue, smoother_restarts="laser_off", power=train.laser_power)
    assert s.restart_after(0.05, 0.1)  # on at both readings, a 10 ms pause between them


def test_the_forecast_gives_a_step_the_energy_of_a_pulse_edge_inside_it(tissue):
    """With a HeatSimulation's laser_power the filter's heat steps get the schedule's mean
    power (the pulse ends 0.05 s into the step: half the power), a plain callable its
    value at the step's middle."""
    from mcmatlab_py.heat import HeatSimulation

    HS = HeatSimulation(P=0.5, duration_on=0.25, duration_off=1.0, n_pulses=1)
    model = TissueForwardModel(_setup(tissue, power=HS.laser_power))
    seen = []
    real = model.step

    def spy(E, theta, a, b, power):
        seen.append(power)
        return real(E, theta, a, b, power)

    model.step = spy
    X = np.zeros((1, model.mesh.p.shape[1]))
    model(X, np.array([[1.0, 100.0]]), 0.2, 0.3)
    assert seen == [pytest.approx(0.25, rel=1e-12)]
    assert _setup(tissue, power=lambda t: 0.5 if t < 0.25 else 0.0).mean_power(0.2, 0.3) == 0.0


def test_the_walk_is_reflected_at_the_health_checks_bounds_where_restarts_reset_it(tissue):
    # a filter restarted from the smoother walks in log units within the logs of the bounds
    # at which the health check stops a run; without restarts the walk is unbounded (a walk
    # that leaves them stops the run: nothing would reset it)
    pieces = assemble(_setup(tissue, smoother_restarts="laser_off"))
    np.testing.assert_allclose(pieces.walk_bounds, np.log(pieces.health.param_bounds))
    assert pieces.problem(np.array([0.1]), np.zeros((1, 1))).param_walk_bounds is not None
    assert assemble(_setup(tissue)).walk_bounds is None
