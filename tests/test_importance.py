"""Adaptive multiple importance sampling (enkf.importance): the posterior itself, checked
against Gaussian moments and posteriors integrated on a grid; and the smoother's use of it
on the small tissue model, against the grid posterior of the same model."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import logsumexp

from enkf.importance import amis, student_t_logpdf, weighted_quantile
from enkf.tissue import TissueForwardModel
from enkf.tissue.smooth import smooth_constant


def _gaussian(d=3):
    rng = np.random.default_rng(7)
    A = rng.standard_normal((d, d))
    S = A @ A.T + 0.5 * np.eye(d)
    m = rng.standard_normal(d)
    Si = np.linalg.inv(S)
    return m, S, lambda U: -0.5 * np.einsum("ij,jk,ik->i", U - m, Si, U - m)


def test_amis_gives_the_moments_of_a_gaussian_from_a_poor_first_guess():
    """From an ensemble that is too narrow (half the sd) and off by one sd, the weighted
    samples have the target's mean within 4 standard errors sqrt(S_ii / ESS) and its
    variances within 4 sqrt(2 / ESS) relative; the first guess itself is far off."""
    m, S, logp = _gaussian()
    rng = np.random.default_rng(1)
    sd = np.sqrt(np.diag(S))
    U0 = rng.multivariate_normal(m + sd, 0.25 * S, size=50)
    res = amis(logp, U0, rng, n_samples=3000, n_rounds=6)
    assert res.U.shape == (3000, 3) and np.isclose(res.weights.sum(), 1.0)
    assert 500 < res.ess <= 3000
    assert np.all(np.abs(res.mean - m) <= 4 * sd / np.sqrt(res.ess)), (res.mean - m) / sd
    var = np.diag(res.cov)
    assert np.all(np.abs(var / sd ** 2 - 1) <= 4 * np.sqrt(2 / res.ess)), var / sd ** 2
    assert np.all(np.abs(U0.mean(0) - m) > 4 * sd / np.sqrt(res.ess))  # the test can fail


def _banana_grid():
    """A curved posterior on a box (a bounded prior): its log density and its moments and
    quantiles integrated on a fine grid."""
    lo, hi = np.array([-2.0, -1.0]), np.array([2.0, 3.0])

    def logp(U):
        inside = np.all((U >= lo) & (U <= hi), axis=1)
        val = -0.5 * (U[:, 0] ** 2 / 0.5 + (U[:, 1] - U[:, 0] ** 2) ** 2 / 0.05)
        return np.where(inside, val, -np.inf)

    x, y = np.linspace(*[lo[0], hi[0]], 801), np.linspace(*[lo[1], hi[1]], 801)
    X, Y = np.meshgrid(x, y, indexing="ij")
    P = np.exp(logp(np.column_stack([X.ravel(), Y.ravel()]))).reshape(X.shape)
    P /= P.sum()
    mean = np.array([(P * X).sum(), (P * Y).sum()])
    sd = np.sqrt([(P * (X - mean[0]) ** 2).sum(), (P * (Y - mean[1]) ** 2).sum()])
    cdf_y = np.cumsum(P.sum(axis=0))
    q = np.interp([0.05, 0.95], cdf_y, y)
    return lo, hi, logp, mean, sd, q


def test_amis_gives_a_curved_bounded_posterior_integrated_on_a_grid():
    """A banana-shaped posterior cut by a box: the weighted mean within 4 standard errors
    sd / sqrt(ESS) of the grid's, the 5% and 95% quantiles of the second coordinate within
    4 standard errors of a quantile, sqrt(q (1 - q) / ESS) / density; no weight outside
    the box. An ensemble from a Gaussian fit (as a smoother gives) misses the curvature."""
    lo, hi, logp, mean, sd, q = _banana_grid()
    rng = np.random.default_rng(5)
    U0 = rng.multivariate_normal([0.0, 0.5], np.diag([0.5, 0.6]), size=50)
    res = amis(logp, U0, rng, n_samples=4000, n_rounds=6)
    assert np.all(np.abs(res.mean - mean) <= 4 * sd / np.sqrt(res.ess)), (res.mean, mean)
    outside = ~np.all((res.U >= lo) & (res.U <= hi), axis=1)
    assert outside.any() and np.all(res.weights[outside] == 0)
    # the density of y at the quantiles, from the samples' weighted histogram
    yq = res.quantile([0.05, 0.95], 1)
    dens = []
    for v in q:
        near = np.abs(res.U[:, 1] - v) < 0.1
        dens.append(res.weights[near].sum() / 0.2)
    se = np.sqrt(0.05 * 0.95 / res.ess) / np.array(dens)
    assert np.all(np.abs(yq - q) <= 4 * se), (yq, q, se)


def test_weighted_quantile_and_the_student_t_density():
    x = np.arange(10.0)
    np.testing.assert_allclose(weighted_quantile(x, np.ones(10), [0.05, 0.5, 0.95]),
                               [0.0, 4.5, 9.0])
    np.testing.assert_allclose(weighted_quantile(x, np.r_[np.zeros(9), 1.0], 0.3), 9.0)
    # the Student-t density integrates to 1 (1-D, on a wide grid) and has the scipy value
    from scipy.stats import t as student

    u = np.linspace(-60, 60, 200_001)[:, None]
    L = np.array([[2.0]])
    lp = student_t_logpdf(u, np.array([0.5]), L, 5.0)
    np.testing.assert_allclose(lp, student.logpdf(u[:, 0], 5.0, loc=0.5, scale=2.0), rtol=1e-10)


def test_amis_checks_its_inputs():
    m, S, logp = _gaussian()
    U0 = np.random.default_rng(0).multivariate_normal(m, S, size=20)
    rng = np.random.default_rng(1)
    with pytest.raises(ValueError, match="U0 must have more members than dimensions"):
        amis(logp, U0[:3], rng)
    with pytest.raises(ValueError, match="n_rounds must be an integer >= 1"):
        amis(logp, U0, rng, n_rounds=0)
    with pytest.raises(ValueError, match="n_samples must be an integer >= 48"):
        amis(logp, U0, rng, n_samples=40)
    with pytest.raises(ValueError, match="df must be > 0"):
        amis(logp, U0, rng, df=0.0)
    with pytest.raises(ValueError, match="spread must be >= 1"):
        amis(logp, U0, rng, spread=0.5)
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator"):
        amis(logp, U0, None)
    with pytest.raises(FloatingPointError, match="log_target gave NaN"):
        amis(lambda U: np.full(len(U), np.nan), U0, rng)
    with pytest.raises(FloatingPointError, match="every sample has zero posterior density"):
        amis(lambda U: np.full(len(U), -np.inf), U0, rng)
    with pytest.raises(ValueError, match=r"log_target must return shape \(500,\)"):
        amis(lambda U: np.zeros(3), U0, rng)
    with pytest.warns(RuntimeWarning, match="effective sample size"):
        amis(lambda U: -1e4 * np.sum((U - 50.0) ** 2, axis=1), U0, rng, n_samples=600)


@pytest.mark.parametrize("mode_search", [None, 0])
def test_smoother_importance_gives_the_grid_posterior_of_the_tissue_model(tissue, mode_search):
    """Few noisy readings (sd 0.1 deg C, 1.5 s) leave mus poorly determined: its posterior
    is skewed and cut by the prior's box. The smoother with importance sampling has the
    grid posterior's mean and sd of log mua, log mus (the same coarse model evaluated on a
    100 x 100 grid of the prior box in logs) within 4 standard errors sd / sqrt(ESS) (the
    mean) and 4 sd sqrt(2 / ESS) (the sd), plus half a grid cell; the ensemble of one ES
    update it starts from does not. With the default mode search (``None``: 256 points of
    the prior box) and without it (0)."""
    import fem

    sigma = 0.1
    s = tissue.setup(n_members=50, sensor_noise_var=sigma ** 2)
    times = 0.1 * np.arange(1, 16)
    model = TissueForwardModel(s)
    P = fem.probe_matrix(model.mesh, np.zeros((3, 1)))
    lo, hi = np.log(s.parameters.prior_bounds()[0]), np.log(s.parameters.prior_bounds()[1])
    a, b = np.linspace(lo[0], hi[0], 100), np.linspace(lo[1], hi[1], 100)
    A, B = np.meshgrid(a, b, indexing="ij")
    theta = np.exp(np.column_stack([A.ravel(), B.ravel()]))

    def traces(theta):
        T = np.full((len(theta), model.mesh.p.shape[1]), s.T_initial)
        out, edges = [], np.r_[0.0, times]
        for t0, t1 in zip(edges[:-1], edges[1:], strict=True):
            T = model(T, theta, t0, t1)
            out.append((P @ T.T)[0])
        return np.array(out).T  # (M, steps)

    truth = np.array([[1.3, 70.0]])
    data = traces(truth)[0] + sigma * np.random.default_rng(2).standard_normal(times.size)
    # the grid posterior: uniform prior in (mua, mus), so density exp(sum of logs) in logs
    lp = -0.5 * np.sum((traces(theta) - data) ** 2, axis=1) / sigma ** 2 + A.ravel() + B.ravel()
    w = np.exp(lp - logsumexp(lp))
    U = np.log(theta)
    g_mean = w @ U
    g_sd = np.sqrt(w @ (U - g_mean) ** 2)
    assert g_sd[1] > 0.15  # mus poorly determined: the case the test is about
    # from one ES update (a linear step: a poor first guess here)
    seen = []
    est = smooth_constant(s, times, data[:, None], n_iter=1, importance=3000,
                          mode_search=mode_search,
                          callback=lambda f, note: seen.append((f, note)))
    # progress: one report per update, for the mode search and per round, rising to the
    # whole work
    assert len(seen) == 1 + (mode_search is None) + 6 and seen[-1][0] == pytest.approx(1.0)
    assert (est.n_modes is None) == (mode_search == 0)
    assert np.all(np.diff([f for f, _ in seen]) > 0) and "ESS" in seen[-1][1]
    assert est.weights is not None and np.isclose(est.weights.sum(), 1.0)
    assert est.theta.shape[0] == est.weights.size and np.all(est.theta > 0)
    logs = np.log(est.theta)
    mean = est.weights @ logs
    sd = np.sqrt(est.weights @ (logs - mean) ** 2)
    cell = 0.5 * np.array([a[1] - a[0], b[1] - b[0]])
    assert np.all(np.abs(mean - g_mean) <= 4 * g_sd / np.sqrt(est.ess) + cell), (mean, g_mean)
    assert np.all(np.abs(sd - g_sd) <= 4 * g_sd * np.sqrt(2 / est.ess) + cell), (sd, g_sd)
    # the first guess alone misses the grid's mean by more than the tolerance
    first = np.log(smooth_constant(s, times, data[:, None], n_iter=1).theta).mean(axis=0)
    assert np.any(np.abs(first - g_mean) > 4 * g_sd / np.sqrt(est.ess) + cell), first
    lo_b, hi_b = est.band(1)
    assert lo_b < est.mean[1] < hi_b
    with pytest.raises(ValueError, match="importance must be an integer >= 0"):
        smooth_constant(s, times, data[:, None], importance=-1)
