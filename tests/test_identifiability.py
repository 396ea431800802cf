"""The Cramér-Rao machinery of validation/identifiability.py on models with known answers."""

import numpy as np
import pytest
from scipy.stats import norm

from enkf.app.suite import load_script, validation_dir


def _module():
    return load_script(validation_dir(), "identifiability")


class _LinearSensor:
    """A sensor reading mua(t) + 0.01 mus(t) + VHC + 1000 TC at 10 times: d/dlog phi known."""

    times = np.linspace(0.0, 9.0, 10)

    def series(self, mua, mus, vhc, tc):
        return np.vstack([mua(t) + 0.01 * mus(t) + vhc + 1000 * tc for t in self.times])


def test_fisher_is_the_sensitivity_gram_matrix():
    mod = _module()
    names, logphi, prior_sd, tk = mod.layout("time-varying", ("mua", "mus", "VHC", "TC"), 3)
    assert names[:3] == ["mua(t=0)", "mua(t=2.5)", "mua(t=5)"]
    # the prior constrains the start and the constants, never a later knot
    assert np.isinf(prior_sd).tolist() == [False, True, True, False, True, True, False, False]
    sensor = _LinearSensor()
    F = mod.fisher(sensor, logphi, tk, ("mua", "mus", "VHC", "TC"), noise_var=0.04, h=1e-4)
    # exact sensitivities: the interpolation weight of each knot times its value
    t = np.minimum(sensor.times, 5.0)
    w = np.column_stack([np.interp(t, tk, np.eye(3)[i]) for i in range(3)])
    val = np.exp(logphi)
    S = np.hstack([w * val[:3], 0.01 * w * val[3:6], np.full((10, 1), val[6]),
                   np.full((10, 1), 1000 * val[7])])
    np.testing.assert_allclose(F, S.T @ S / 0.04, rtol=1e-6, atol=1e-9)


def test_chance_within_matches_the_normal_law():
    mod = _module()
    sd = np.array([0.05, 0.2])
    draws = 200_000
    got = mod.chance_within(np.diag(sd**2), [0, 1], [0.1, 0.1], draws, seed=3)
    # |exp(e) - 1| < 0.1  <=>  log(0.9) < e < log(1.1)
    p = [norm.cdf(np.log1p(0.1) / s) - norm.cdf(np.log1p(-0.1) / s) for s in sd]
    exact = p[0] * p[1]
    # binomial standard error of the sampled fraction, 4 sigma
    assert got == pytest.approx(exact, abs=4 * np.sqrt(exact * (1 - exact) / draws))


def test_walk_smoother_error_is_that_of_the_posterior_mean_of_a_linear_model():
    """validation/walk_bound.py: the error's mean and covariance from its formula against
    posterior means computed directly (stacked least squares) for many noise draws."""
    wb = load_script(validation_dir(), "walk_bound")
    rng = np.random.default_rng(11)
    k, n_obs, sigma = 6, 15, wb.SIGMA
    J = wb.walk_precision(k, 0.2, 0.5)
    D = np.diff(np.eye(k), axis=0)
    # the walk's precision: the differences over q^2 and the start's prior
    np.testing.assert_allclose(J, D.T @ D / 0.04 + np.diag([4.0] + [0.0] * (k - 1)))
    S = rng.standard_normal((n_obs, k))
    x_true = np.linspace(0.0, 1.0, k)  # a ramp: the walk lags it
    prior_mean = np.zeros(k)
    r = 0.05 * rng.standard_normal(n_obs)  # a fixed model error
    mean, cov = wb.smoother_error(S, r, J, x_true, prior_mean)
    L = np.linalg.cholesky(J)  # J = L L^T: the prior as rows L^T (x - prior_mean) ~ N(0, I)
    A = np.vstack([S / sigma, L.T])
    draws = 4000
    errs = np.empty((draws, k))
    for i in range(draws):
        y = S @ x_true + r + sigma * rng.standard_normal(n_obs)
        b = np.concatenate([y / sigma, L.T @ prior_mean])
        errs[i] = np.linalg.lstsq(A, b, rcond=None)[0] - x_true
    se = np.sqrt(np.diag(cov) / draws)
    assert np.all(np.abs(errs.mean(axis=0) - mean) < 4.5 * se)
    emp = np.cov(errs.T)
    # the sample variance's standard error is about var * sqrt(2 / draws)
    assert np.all(np.abs(np.diag(emp) - np.diag(cov)) < 4.5 * np.diag(cov) * np.sqrt(2 / draws))
    assert np.any(np.abs(mean) > 10 * se)  # the lag is there, and the test can see it
