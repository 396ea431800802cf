"""The ES-MDA smoother: the exact posterior of a linear-Gaussian problem, its checks, and
constant optics from a whole window on the small tissue model."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from enkf.smoother import es_mda, mda_alphas
from enkf.tissue import TissueForwardModel
from enkf.tissue.smooth import heated_time, smooth_constant, smooth_drifting

N_BIG = 4000


def _linear_problem():
    rng = np.random.default_rng(3)
    G = rng.standard_normal((30, 2))
    m0, C0 = np.array([1.0, -0.5]), np.array([[1.0, 0.3], [0.3, 0.5]])
    R = np.full(30, 0.5)
    u_true = np.array([1.4, -0.2])
    y = G @ u_true + np.sqrt(R) * rng.standard_normal(30)
    Ci = np.linalg.inv(C0) + G.T @ (G / R[:, None])
    C = np.linalg.inv(Ci)
    m = C @ (np.linalg.solve(C0, m0) + G.T @ (y / R))
    return G, m0, C0, R, y, m, C


@pytest.mark.parametrize("method", ["enkf", "etkf"])
@pytest.mark.parametrize("n_iter", [1, 4])
def test_es_mda_gives_the_linear_gaussian_posterior(n_iter, method):
    """For a linear model and a Gaussian prior, ES-MDA's ensemble has the posterior's
    mean and covariance whatever the number of updates. Tolerances from the ensemble
    size: the mean within 4 standard errors sqrt(2 C_ii / N) (the prior draw and the
    perturbed data each add C/N at most), the variances within 4 sqrt(2 / N) n_iter
    relative (the sampling error of a variance, compounded over the updates)."""
    G, m0, C0, R, y, m, C = _linear_problem()
    rng = np.random.default_rng(11)
    U0 = rng.multivariate_normal(m0, C0, size=N_BIG)
    U = es_mda(lambda U: U @ G.T, U0, y, R, rng, n_iter=n_iter, method=method)
    se = np.sqrt(2 * np.diag(C) / N_BIG)
    assert np.all(np.abs(U.mean(0) - m) <= 4 * se), (U.mean(0), m, se)
    var = U.var(0, ddof=1)
    assert np.all(np.abs(var / np.diag(C) - 1) <= 4 * np.sqrt(2 / N_BIG) * n_iter), var / np.diag(C)
    # the data moved the ensemble: the prior's mean is many standard errors away
    assert np.all(np.abs(m0 - m) > 10 * se)


def test_es_mda_checks_its_inputs():
    G, m0, C0, R, y, m, C = _linear_problem()
    U0 = np.random.default_rng(0).multivariate_normal(m0, C0, size=50)
    rng = np.random.default_rng(1)
    sim = lambda U: U @ G.T  # noqa: E731
    with pytest.raises(ValueError, match="alphas must be > 0 with inverses summing to 1"):
        es_mda(sim, U0, y, R, rng, alphas=[2.0, 3.0])
    with pytest.raises(ValueError, match="n_iter must be an integer >= 1"):
        mda_alphas(0)
    with pytest.raises(ValueError, match="y must be finite"):
        es_mda(sim, U0, np.r_[y[:-1], np.nan], R, rng)
    with pytest.raises(ValueError, match=r"simulate must return shape \(50, 30\)"):
        es_mda(lambda U: U @ G[:5].T, U0, y, R, rng)
    with pytest.raises(ValueError, match="method must be one of"):
        es_mda(sim, U0, y, R, rng, method="iterative")
    with pytest.raises(FloatingPointError, match="ES-MDA update 1: a member's predictions"):
        es_mda(lambda U: np.full((50, 30), np.inf), U0, y, R, rng)
    np.testing.assert_array_equal(mda_alphas(4), [4.0, 4.0, 4.0, 4.0])


def _trace(s, times, theta):
    """(M,) the surface readings of the coarse model at ``theta`` (mua, mus): constant, or
    a function of the step's middle heated time."""
    import fem

    model = TissueForwardModel(s)
    P = fem.probe_matrix(model.mesh, np.zeros((3, 1)))
    T = np.full((1, model.mesh.p.shape[1]), s.T_initial)
    out, edges = [], np.r_[0.0, times]
    heated = heated_time(s.power, edges)
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        th = theta(0.5 * (heated[k] + heated[k + 1])) if callable(theta) else theta
        T = model(T, np.asarray(th, float)[None, :], a, b)
        out.append((P @ T.T)[0, 0])
    return np.array(out)


def test_smooth_constant_finds_the_least_squares_optics(tissue):
    """On a twin with constant optics and readings precise enough for a nearly Gaussian
    posterior (noise sd 0.01 deg C: Laplace sd about 0.5% for mua and 5% for mus), the
    smoother's ensemble mean is the least-squares fit of the same model (by Gauss-Newton,
    another method) within half its Laplace sd (5 standard errors of an ensemble of 100),
    and its +-2 sd band holds the truth."""
    sigma, truth = 0.01, (1.3, 70.0)
    s = tissue.setup(n_members=100, sensor_noise_var=sigma ** 2)
    times = 0.1 * np.arange(1, 21)
    rng = np.random.default_rng(4)
    data = (_trace(s, times, truth) + sigma * rng.standard_normal(times.size))[:, None]
    est = smooth_constant(s, times, data, n_iter=4)
    fit = least_squares(lambda x: (_trace(s, times, np.exp(x)) - data[:, 0]) / sigma,
                        np.log([1.0, 100.0]), diff_step=1e-5, xtol=1e-12)
    sd = np.sqrt(np.diag(np.linalg.inv(fit.jac.T @ fit.jac)))
    assert sd[0] < 0.01 and sd[1] < 0.1  # the nearly Gaussian case the test is about
    assert est.names == ("mua", "mus")
    assert np.all(np.abs(np.log(est.mean) - fit.x) <= 0.5 * sd), (np.log(est.mean), fit.x, sd)
    for i, true in enumerate(truth):
        lo, hi = est.band(i)
        assert lo <= true <= hi
    assert est.theta.shape == (100, 2) and np.all(est.theta > 0)


def test_smooth_constant_checks_its_setup(tissue):
    times, data = tissue.twin_data(tissue.setup(), 1.0, 100.0)
    with pytest.raises(ValueError, match="needs parameter_model = .random_walk."):
        smooth_constant(tissue.setup(parameter_model="trend"), times, data)
    with pytest.raises(ValueError, match="set sensor_offset_std = 0"):
        smooth_constant(tissue.setup(sensor_offset_std=0.5), times, data)
    with pytest.raises(ValueError, match=r"data must have shape \(20, 1\)"):
        smooth_constant(tissue.setup(), times, data[:-1])
    with pytest.raises(ValueError, match="times must be strictly increasing and after 0"):
        smooth_constant(tissue.setup(), times[::-1], data)
    with pytest.raises(ValueError, match="data has no finite reading"):
        smooth_constant(tissue.setup(), times, np.full_like(data, np.nan))


def test_heated_time_counts_the_seconds_with_the_laser_on(tissue):
    """The tiny setup's laser is on for 1 s, then off: heated time is min(t, 1)."""
    edges = 0.1 * np.arange(21)
    np.testing.assert_allclose(heated_time(tissue.setup().power, edges),
                               np.minimum(edges, 1.0), atol=1e-12)


def _drift(tau):
    """The twin's optics: linear in heated time from (1.0, 80) to (1.6, 120) over 1 s."""
    return (1.0 + 0.6 * tau, 80.0 + 40.0 * tau)


def test_smooth_drifting_follows_optics_that_drift_while_heated(tissue):
    """On a twin whose optics drift while the laser is on and hold after it (precise
    readings, noise sd 0.01 deg C), the smoother's bands at the end of the window and at
    the first knot hold the truth, and its mua error at the end is well below the drift
    (a constant fit, for contrast, leaves the end value outside its band)."""
    sigma = 0.01
    s = tissue.setup(n_members=100, sensor_noise_var=sigma ** 2)
    times = 0.1 * np.arange(1, 21)
    rng = np.random.default_rng(5)
    data = (_trace(s, times, _drift) + sigma * rng.standard_normal(times.size))[:, None]
    est = smooth_drifting(s, times, data, knots=3, n_iter=8)
    np.testing.assert_allclose(est.knot_times, [0.0, 0.5, 1.0])
    assert est.knots.shape == (100, 3, 2) and est.theta.shape == (100, 2)
    np.testing.assert_array_equal(est.theta, est.knots[:, -1])
    end, start = _drift(1.0), _drift(0.0)
    for i in range(2):
        lo, hi = est.band(i)
        assert lo <= end[i] <= hi, (i, lo, hi, end[i])
        q = np.quantile(est.knots[:, 0, i], [0.02275, 0.97725])
        assert q[0] <= start[i] <= q[1], (i, q, start[i])
    # mua is well determined here (sd about 3% against a drift of 60%); the stand-in's
    # mus much less (sd about 30%): its bands are the check
    assert abs(est.mean[0] - end[0]) < min(0.25 * (end[0] - start[0]), 3 * est.std[0])
    const = smooth_constant(s, times, data, n_iter=4)
    assert not const.band(0)[0] <= end[0] <= const.band(0)[1]


def test_smoother_discrepancy_widens_the_bands_and_is_checked(tissue, monkeypatch):
    s = tissue.setup(n_members=50)
    times, data = tissue.twin_data(s, 1.0, 100.0)
    plain = smooth_constant(s, times, data)
    wide = smooth_constant(s, times, data, discrepancy=0.05)
    assert np.all(wide.std > plain.std)
    with pytest.raises(ValueError, match="discrepancy must be >= 0"):
        smooth_constant(s, times, data, discrepancy=-0.1)
    with pytest.raises(ValueError, match="discrepancy_time must be > 0 s"):
        smooth_drifting(s, times, data, discrepancy_time=0.0)
    with pytest.raises(ValueError, match="knots must be an integer >= 2"):
        smooth_drifting(s, times, data, knots=1)
    with pytest.raises(ValueError, match="drift_log_std must be > 0"):
        smooth_drifting(s, times, data, drift_log_std=np.nan)
    with pytest.raises(ValueError, match="drifting must name estimated parameters"):
        smooth_drifting(s, times, data, drifting=("mua", "TC"))
    import enkf.tissue.smooth as sm

    monkeypatch.setattr(sm, "MAX_DISCREPANCY_READINGS", 10)
    with pytest.raises(ValueError, match=r"with 20 readings needs a dense 20\^2 covariance"):
        smooth_constant(s, times, data, discrepancy=0.01)
    off = tissue.setup(power=lambda t: 0.0)
    with pytest.raises(ValueError, match="no heated time in the window"):
        smooth_drifting(off, times, data)


def test_smoother_estimates_at_heated_times(tissue):
    """``at``: the knots' linear interpolation per member (the knots themselves at the knot
    times); constant optics give ``theta`` at every time."""
    s = tissue.setup()
    times, data = tissue.twin_data(s, 1.0, 100.0)
    est = smooth_drifting(s, times, data, knots=3, n_iter=2)
    np.testing.assert_allclose(est.at(est.knot_times), est.knots.transpose(1, 0, 2))
    mid = est.at([0.25])[0]
    np.testing.assert_allclose(mid, 0.5 * (est.knots[:, 0] + est.knots[:, 1]))
    const = smooth_constant(s, times, data, n_iter=2)
    np.testing.assert_array_equal(const.at([0.0, 0.7])[1], const.theta)


def test_the_forward_model_reads_the_absorption_once_for_constant_optics(tissue):
    """Steps with the same optics (a smoother's window, a twin) reuse the last values of
    the absorption model (its evaluation costs 15 times a heat step on the layered block);
    other optics, or another number of members, are evaluated afresh; the temperatures are
    those of a model that evaluates every step."""
    calls = []

    def counted(mua, mus):
        calls.append(len(mua))
        return tissue.absorption(mua, mus)

    s = tissue.setup(absorption=counted)
    model, fresh = TissueForwardModel(s), TissueForwardModel(tissue.setup())
    theta = np.array([[1.0, 100.0], [1.5, 60.0]])
    T = F = np.full((2, model.mesh.p.shape[1]), s.T_initial)
    for k in range(3):
        T = model(T, theta, 0.1 * k, 0.1 * (k + 1))
        fresh._last_optics = None  # noqa: SLF001 - the reference evaluates every step
        F = fresh(F, theta, 0.1 * k, 0.1 * (k + 1))
    assert calls == [2]
    np.testing.assert_array_equal(T, F)
    model(T, theta * [1.0, 1.01], 0.3, 0.4)
    model(T[:1], theta[:1] * [1.0, 1.01], 0.4, 0.5)
    assert calls == [2, 2, 1]


def test_es_mda_with_a_whitening_map_is_es_mda_with_the_covariance():
    """``whiten``: readings made unit and independent by a map at each update's forecast;
    with a fixed map L^-1 the update is the dense covariance L L^T's."""
    rng = np.random.default_rng(3)
    G = rng.standard_normal((6, 2))
    A = rng.standard_normal((6, 6))
    R = A @ A.T + 0.5 * np.eye(6)
    L = np.linalg.cholesky(R)
    y = rng.standard_normal(6)
    U0 = rng.standard_normal((30, 2))
    seen = []

    def whiten(Y):
        seen.append(Y.shape)
        return lambda Z: np.linalg.solve(L, Z.T).T

    for method in ("etkf", "enkf"):
        dense = es_mda(lambda U: U @ G.T, U0, y, R, np.random.default_rng(1), n_iter=3,
                       method=method)
        white = es_mda(lambda U: U @ G.T, U0, y, np.ones(6), np.random.default_rng(1),
                       n_iter=3, method=method, whiten=whiten)
        if method == "etkf":  # no perturbations: the same numbers
            np.testing.assert_allclose(white, dense, rtol=1e-10)
        else:  # perturbations drawn in the whitened space: the same distribution
            assert white.shape == dense.shape
    assert seen == [(30, 6)] * 6
    with pytest.raises(ValueError, match="with whiten the readings' error R must be 1"):
        es_mda(lambda U: U @ G.T, U0, y, R, rng, whiten=whiten)


def test_the_smoother_reads_a_camera_with_its_model_error(tissue, monkeypatch):
    """With the camera's model error each update whitens the frames by their covariance,
    the pixels' noise plus ThermalImage.error_covariance at the members' mean prediction
    (the filter's forecast mean; not the data, whose noise would bias the weights), a lost
    pixel left out; the bands are wider than the pixels' noise alone gives."""
    import dataclasses

    from test_image import CAMERA, twin_image

    import enkf.tissue.smooth as sm

    cam = dataclasses.replace(CAMERA, model_error_rel_std=0.3)
    s = tissue.setup(sensor_positions=np.zeros((0, 3)), image=cam, n_members=20)
    times, frames = twin_image(s, 1.4, 100.0)
    frames[4, 2] = np.nan  # a dead pixel
    keep = np.isfinite(frames).ravel()
    means, at = [], []
    real_es, real_factors = sm.es_mda, sm.frame_factors

    def spy_es(simulate, *a, **kw):
        def spied(U):
            Y = simulate(U)
            means.append(Y.mean(axis=0))
            return Y
        return real_es(spied, *a, **kw)

    def spy_factors(obs_error, noise_var, predicted):
        at.append(predicted.copy())
        out = real_factors(obs_error, noise_var, predicted)
        R = 0.01 * np.eye(cam.n_pixels) + cam.error_covariance(
            np.nan_to_num(predicted[4]), 0.0)
        m = np.isfinite(predicted[4])
        np.testing.assert_allclose(out[4][1] @ out[4][1].T, R[np.ix_(m, m)], rtol=1e-12)
        return out

    monkeypatch.setattr(sm, "es_mda", spy_es)
    monkeypatch.setattr(sm, "frame_factors", spy_factors)
    wide = smooth_constant(s, times, frames, n_iter=2)
    assert len(at) == len(means) == 2
    for p, m in zip(at, means, strict=True):
        assert np.array_equal(np.isfinite(p.ravel()), keep)
        np.testing.assert_allclose(p.ravel()[keep], m, rtol=1e-12)
    monkeypatch.undo()
    plain = smooth_constant(tissue.setup(sensor_positions=np.zeros((0, 3)), image=CAMERA,
                                         n_members=20), times, frames, n_iter=2)
    # mua: twice as wide; mus, which these 20 frames hardly tell, wider too
    assert wide.std[0] > 1.5 * plain.std[0] and wide.std[1] > plain.std[1]
    with pytest.raises(ValueError, match="discrepancy = 0.01 with the camera's model error"):
        smooth_constant(s, times, frames, discrepancy=0.01)
