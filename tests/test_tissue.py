"""The tissue-identification application (enkf.tissue) on a small, fast model."""

import numpy as np
import pytest

import fem
from enkf.tissue import TissueFilterSetup, TissueForwardModel, identify
from mcmatlab_py.heat import HeatSimulation

GRID = fem.BoxGrid(6, 6, 4, 0.5, 0.5, 0.25)
NOMINAL = {"mua": 1.0, "mus": 100.0, "VHC": 3.76, "TC": 0.0037}


def absorption(mua, mus):
    """A smooth stand-in for the emulator: NA ~ mua exp(-mu_eff z), W/cm^3/W."""
    z = GRID.z[None, None, None, :]
    mueff = np.sqrt(3 * mua * (mua + 0.1 * mus))[:, None, None, None]
    return np.broadcast_to(40 * mua[:, None, None, None] * np.exp(-mueff * z),
                           (len(mua), *GRID.shape)).copy()


def setup(**kw):
    args = dict(grid=GRID, absorption=absorption,
                power=HeatSimulation(P=0.5, duration_on=1.0, duration_off=1.0).laser_power,
                nominal=NOMINAL, n_members=20, seed=1, method="etkf",
                tracked_positions=[(0, 0, 0), (0, 0, 0.125)])
    args.update(kw)
    return TissueFilterSetup(**args)


def twin_data(s, mua, mus, seed=0):
    """Synthetic data from the filter's own model (an identical twin), noise var 0.01."""
    model = TissueForwardModel(s)
    P = fem.probe_matrix(model.mesh, np.zeros((3, 1)))
    T = np.zeros((1, model.mesh.p.shape[1]))
    times = 0.1 * np.arange(1, 21)
    out, t0 = [], 0.0
    for t1 in times:
        T = model(T, np.array([[mua, mus]]), t0, t1)
        out.append((P @ T.T)[0, 0])
        t0 = t1
    rng = np.random.default_rng(seed)
    return times, np.array(out)[:, None] + 0.1 * rng.standard_normal((len(times), 1))


def test_identical_twin_recovers_mua():
    s = setup()
    times, data = twin_data(s, 1.4, 100.0)
    est = identify(s, times, data)
    assert est.param_mean.shape == (21, 2) and est.tracked_mean.shape == (21, 2)
    assert abs(est.param_mean[-1, 0] - 1.4) < 3 * est.param_std[-1, 0] + 0.05
    assert est.param_std[-1, 0] < est.param_std[0, 0] / 2  # the data taught it something
    assert est.diverged is None and np.all(est.step_latency_s > 0)


def test_missing_data_skip_the_analysis():
    s = setup()
    times, data = twin_data(s, 1.0, 100.0)
    data[5:10] = np.nan
    est = identify(s, times, data)
    assert not est.analysed[5:10].any() and est.analysed[:5].all() and est.analysed[10:].all()


def test_random_walk_held_when_the_laser_is_off():
    """random_walk_when_off = 0 and no data: parameters move only while the laser is on."""
    s = setup(random_walk_std=0.05, random_walk_when_off=0.0)
    times = 0.1 * np.arange(1, 21)
    est = identify(s, times, np.full((20, 1), np.nan))
    on, off = est.param_mean[1:11], est.param_mean[11:]
    assert np.ptp(on[:, 0]) > 0 and np.ptp(off, axis=0).max() == 0


def test_trend_model_follows_a_steady_drift_with_no_data():
    """parameter_model="trend" and no data: log mua drifts at each member's rate while
    the laser is on, and holds still when it is off (random_walk_when_off = 0)."""
    s = setup(parameter_model="trend", random_walk_std=0.0, trend_noise_std=0.0,
              trend_prior_std=0.5, random_walk_when_off=0.0, n_members=200)
    times = 0.1 * np.arange(1, 21)
    est = identify(s, times, np.full((20, 1), np.nan))
    assert est.param_mean.shape == (21, 2)  # the rates are filtered but not reported
    on, off = est.param_std[1:11, 0], est.param_mean[11:]
    assert np.all(np.diff(on) > 0)  # members drift apart at their own rates
    assert np.ptp(off, axis=0).max() == 0


def test_divergence_is_reported_with_the_estimates_so_far():
    s = setup()
    times, data = twin_data(s, 1.0, 100.0)
    est = identify(s, times, data, param_bounds=np.array([[0.99, 1.01], [1.0, 1e4]]))
    assert est.diverged and "outside bounds" in est.diverged
    assert len(est.times) < 21


@pytest.mark.parametrize("kw, pattern", [
    (dict(estimate=("mua",)), "estimate must be"),
    (dict(nominal={**NOMINAL, "mua": -1.0}), r"nominal\['mua'\] must be > 0"),
    (dict(prior_range=(2.0, 0.5)), "prior_range"),
    (dict(model_noise_std=float("nan")), "model_noise_std"),
    (dict(parameter_model="spline"), "parameter_model must be"),
])
def test_bad_setup(kw, pattern):
    with pytest.raises(ValueError, match=pattern):
        setup(**kw)
