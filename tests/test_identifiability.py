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
