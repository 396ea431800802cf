"""The filter's innovations tell when its model misses the truth's physics (issue #18).

1. ``innovation_persistence`` is the lag-1 correlation of the rows it is given: exact on a
   small hand-made case (NaN components and steps left out break no pair they are not
   in), and within 4 standard errors of phi on AR(1) series (0 and 0.6).
2. On a linear toy model the filter's innovations are white when its model is the
   truth's, and persist when the truth has a dynamics the model lacks.
3. On the small tissue model: an identical twin is not flagged; data whose heat
   conduction is three times the model's, after a 1 s pulse, are (the run warns, and
   summary.json says so).
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from enkf import FilterConfig, FilterProblem, run_filter
from enkf.adaptive import (
    PERSISTENCE_THRESHOLD,
    innovation_persistence,
    normalized_innovation,
    persistence_flagged,
)
from enkf.tissue import identify
from mcmatlab_py.heat import HeatSimulation


def test_normalized_innovation_is_the_innovation_over_its_forecast_sd():
    rng = np.random.default_rng(0)
    Y, y, R = rng.normal(size=(9, 3)), rng.normal(size=3), np.array([0.5, 0.2, 1.0])
    z = normalized_innovation(Y, y, R)
    np.testing.assert_allclose(z, (y - Y.mean(0)) / np.sqrt(Y.var(0, ddof=1) + R), rtol=1e-14)
    np.testing.assert_array_equal(normalized_innovation(Y, y, np.diag(R)), z)
    y[1] = np.nan
    assert np.isnan(normalized_innovation(Y, y, R)[1])


def test_persistence_is_the_lag1_correlation_of_the_rows():
    z = np.array([[1.0, 2.0], [3.0, np.nan], [-1.0, 0.5], [2.0, 1.0]])
    # pairs (row k-1, row k) over the components finite in both
    a = np.array([3.0, -1.0, 0.5, 2.0, 1.0])
    b = np.array([1.0, 3.0, np.nan, -1.0, 0.5])
    ok = np.isfinite(b)
    r, n = innovation_persistence(z)
    assert n == 4
    assert r == pytest.approx(np.sum(a[ok] * b[ok]) / np.sqrt(np.sum(a[ok] ** 2)
                                                             * np.sum(b[ok] ** 2)), rel=1e-14)
    # leaving out step 2 leaves the pair (3, 4) alone
    r, n = innovation_persistence(z, np.array([False, False, True, True]))
    assert n == 2 and r == pytest.approx((-2.0 + 0.5) / np.sqrt(1.25 * 5.0), rel=1e-14)
    assert innovation_persistence(z, np.array([True, False, True, False])) == (
        pytest.approx(np.nan, nan_ok=True), 0)
    with pytest.raises(ValueError, match="steps"):
        innovation_persistence(z, np.ones(3, bool))
    with pytest.raises(ValueError, match=r"\(M, p\)"):
        innovation_persistence(z[0])


@pytest.mark.parametrize("phi", [0.0, 0.6])
def test_persistence_of_ar1_series_is_phi(phi):
    rng = np.random.default_rng(7)
    M, p = 2000, 4
    z = np.empty((M, p))
    z[0] = rng.standard_normal(p)
    for k in range(1, M):
        z[k] = phi * z[k - 1] + np.sqrt(1 - phi**2) * rng.standard_normal(p)
    r, n = innovation_persistence(z)
    assert n == (M - 1) * p
    se = np.sqrt((1 - phi**2) / n)  # the lag-1 estimator's sd for an AR(1) series
    assert abs(r - phi) < 4 * se, (r, se)
    assert persistence_flagged(r, n) == (phi > PERSISTENCE_THRESHOLD)


def test_flag_needs_the_threshold_and_three_sd_of_white_innovations():
    assert not persistence_flagged(0.29, 10_000)
    assert persistence_flagged(0.31, 10_000)
    assert not persistence_flagged(0.5, 25)  # 3 / sqrt(25) = 0.6
    assert persistence_flagged(0.7, 25)
    assert not persistence_flagged(float("nan"), 0)


def _toy(truth_F, seed):
    """A 1-D linear model ``x' = 0.9 x`` observed directly; the truth steps with
    ``truth_F`` (2 x 2, its first component observed) and a noise of sd 0.3."""
    rng = np.random.default_rng(seed)
    x, ys = np.array([1.0, 1.0]), []
    for _ in range(400):
        x = truth_F @ x + np.array([0.3, 0.3]) * rng.standard_normal(2)
        ys.append(x[0] + 0.3 * rng.standard_normal())
    problem = FilterProblem(
        forecast=lambda X, th, t0, t1: 0.9 * X, observation=np.array([[1.0]]),
        obs_times=np.arange(1.0, 401.0), obs_data=np.array(ys)[:, None],
        obs_cov=np.array([0.09]), prior=lambda r, N: (r.standard_normal((N, 1)),
                                                      np.zeros((N, 0))),
        model_noise=np.array([0.09]), tracked=[0])
    res = run_filter(problem, FilterConfig(n_members=40, seed=seed))
    assert res.innovation_normalized.shape == (400, 1)
    return innovation_persistence(res.innovation_normalized)


def test_the_filter_s_innovations_persist_only_when_its_model_is_wrong():
    right = [_toy(np.array([[0.9, 0.0], [0.0, 0.9]]), s) for s in range(3)]
    # the truth's observed component is driven by a slow hidden one the model lacks
    wrong = [_toy(np.array([[0.9, 0.3], [0.0, 0.99]]), s) for s in range(3)]
    for r, n in right:  # white: within 4 sd of 0 (measured 0.056, -0.035, 0.035)
        assert abs(r) < 4 / np.sqrt(n), r
        assert not persistence_flagged(r, n)
    for r, n in wrong:  # measured 0.61, 0.75, 0.65
        assert persistence_flagged(r, n), r


def test_identify_flags_a_truth_whose_conduction_the_model_misses(tissue, tmp_path):
    from enkf.tissue.estimates import persistence_summary

    power = HeatSimulation(P=0.5, duration_on=1.0, duration_off=15.0).laser_power
    s = tissue.setup(power=power, random_walk_std=0.0)
    # data of one sensor over a 1 s pulse and 15 s of cooling, from the tissue's model with
    # its conduction times `factor`; measured lag-1 (seed 2): -0.08 with the model's
    # conduction, 0.58 with three times it
    for factor, flagged in ((1.0, False), (3.0, True)):
        truth = s.with_(nominal=dict(s.parameters.nominal, TC=s.parameters.nominal["TC"] * factor))
        times, data = tissue.twin_data(truth, 1.0, 100.0, seed=2,
                                       times=np.round(0.1 * np.arange(1, 161), 10))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            est = identify(s, times, data)
        assert est.laser_on.shape == (160,) and est.laser_on.sum() == 10
        r, n = est.innovation_persistence("off")
        assert n == 149
        warned = [w for w in caught if "persist" in str(w.message)]
        assert bool(warned) == flagged, (factor, r)
        summary = persistence_summary(est)
        assert summary["flagged"] == flagged and summary["laser_off_pairs"] == 149
        assert (summary["advice"] is not None) == flagged
        json.dumps(summary)  # plain JSON
    with pytest.raises(ValueError, match="laser"):
        est.innovation_persistence("maybe")


def test_the_figure_draws_the_pixel_beside_the_first_point(tissue):
    """identify's estimates.png draws, beside the first tracked point, the first sensor's
    data; with a camera alone, the pixel whose centre is nearest the point (before: the
    first data column, a corner pixel)."""
    from enkf.app.report import _data_beside_first_point
    from enkf.tissue import ThermalImage

    cam = ThermalImage(x_range=(-0.2, 0.2), y_range=(-0.1, 0.1), shape=(2, 4))
    s = tissue.setup(sensor_positions=np.zeros((0, 3)), image=cam,
                     tracked_positions=[(0.12, 0.06, 0.0), (0.0, 0.0, 0.1)])
    col, label = _data_beside_first_point(s)
    # pixel centres: x -0.15, -0.05, 0.05, 0.15; y -0.05, 0.05 (rows in C order)
    assert col == 7 and label == "data (pixel at 0.15, 0.05 cm)"
    assert _data_beside_first_point(tissue.setup()) == (0, "data (first sensor)")
