"""The generic ensemble Kalman filter: exact Kalman filter, NaN data, transforms, seeds.

(Lorenz-96 against Sakov & Oke is in test_enkf_lorenz96.py.)
"""

import numpy as np
import pytest

from enkf import (
    FilterConfig,
    FilterDivergence,
    FilterProblem,
    HealthCheck,
    LogitTransform,
    LogTransform,
    enkf_perturbed_obs,
    etkf,
    run_filter,
    uniform_prior,
)
from enkf.toy_models import kalman_analysis

MU = np.array([1.0, -1.0, 0.5])
P = np.array([[1.0, 0.3, 0.0], [0.3, 2.0, 0.2], [0.0, 0.2, 0.5]])
H = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
R = np.array([[0.5, 0.1], [0.1, 0.3]])
Y_OBS = np.array([0.4, 1.1])


def prior_ensemble(N, seed=0):
    return np.random.default_rng(seed).multivariate_normal(MU, P, size=N)


def test_etkf_is_the_kalman_update_of_the_ensemble_moments():
    """With the ensemble's own mean and covariance, the square-root filter is exact."""
    E = prior_ensemble(200)
    Ea = etkf(E, E @ H.T, Y_OBS, R)
    mu_a, P_a = kalman_analysis(E.mean(0), np.cov(E.T), H, R, Y_OBS)
    np.testing.assert_allclose(Ea.mean(0), mu_a, atol=1e-10)
    np.testing.assert_allclose(np.cov(Ea.T), P_a, atol=1e-10)


def test_perturbed_obs_enkf_matches_the_kalman_filter_within_sampling_error():
    N = 20_000
    E = prior_ensemble(N, seed=1)
    Ea = enkf_perturbed_obs(E, E @ H.T, Y_OBS, R, np.random.default_rng(2))
    mu_a, P_a = kalman_analysis(E.mean(0), np.cov(E.T), H, R, Y_OBS)
    # centred perturbations: the mean is the Kalman update of the ensemble mean exactly
    np.testing.assert_allclose(Ea.mean(0), mu_a, atol=1e-10)
    # the covariance carries the perturbations' sampling error: a few standard errors
    se = np.sqrt((P_a**2 + np.outer(np.diag(P_a), np.diag(P_a))) / (N - 1))
    assert np.all(np.abs(np.cov(Ea.T) - P_a) < 4 * se)
    # against the exact (population) Kalman filter: prior and perturbation sampling
    mu_x, P_x = kalman_analysis(MU, P, H, R, Y_OBS)
    assert np.all(np.abs(Ea.mean(0) - mu_x) < 4 * np.sqrt(np.diag(P) / N))


def _linear_problem(data, **kw):
    F = np.array([[0.9, 0.1], [0.0, 0.95]])
    args = dict(
        forecast=lambda X, theta, t0, t1: X @ F.T + theta[:, :1] * 0.1,
        observation=np.array([[1.0, 0.0]]), obs_times=np.arange(1, len(data) + 1) * 1.0,
        obs_data=data, obs_cov=np.array([0.1]),
        prior=uniform_prior(np.zeros(2), np.array([0.5]), np.array([2.0]), state_std=0.5),
        model_noise=1e-3, param_noise=1e-4, transforms=LogTransform(), tracked=[0, 1])
    args.update(kw)
    return FilterProblem(**args)


def test_nan_data_skip_the_analysis_and_seeds_reproduce():
    data = np.sin(np.arange(20.0))[:, None]
    data[3:7] = np.nan
    res = run_filter(_linear_problem(data), FilterConfig(n_members=30, seed=5))
    assert not res.analysed[3:7].any() and res.analysed[:3].all() and res.analysed[7:].all()
    again = run_filter(_linear_problem(data), FilterConfig(n_members=30, seed=5))
    np.testing.assert_array_equal(res.param_mean, again.param_mean)
    other = run_filter(_linear_problem(data), FilterConfig(n_members=30, seed=6))
    assert not np.array_equal(res.param_mean, other.param_mean)
    assert np.all(res.param_mean > 0)  # the log transform keeps the parameter positive


def test_health_check_stops_with_when_and_what():
    data = np.full((10, 1), 1e3)  # data the model cannot follow
    with pytest.raises(FilterDivergence) as info:
        run_filter(_linear_problem(data), FilterConfig(n_members=20, seed=1),
                   health=HealthCheck(param_bounds=np.array([[0.4, 2.5]])))
    err = info.value
    assert err.step >= 1 and "parameter 0" in err.what and len(err.result.times) == err.step + 1


@pytest.mark.parametrize("transform, theta", [(LogTransform(), np.array([1e-3, 1.0, 500.0])),
                                              (LogitTransform(0.0, 2.0), np.array([0.1, 1.9]))])
def test_transforms_round_trip(transform, theta):
    np.testing.assert_allclose(transform.inverse(transform.forward(theta)), theta, rtol=1e-12)
    assert np.all(transform.inverse(np.array([-50.0, 50.0])) > 0)


def test_bad_input_names_the_field():
    E = prior_ensemble(10)
    with pytest.raises(ValueError):
        etkf(E, E[:5] @ H.T, Y_OBS, R)
    with pytest.raises(ValueError, match="n_members"):
        FilterConfig(n_members=1)
    with pytest.raises(ValueError, match="obs_times"):
        _linear_problem(np.zeros((3, 1)), obs_times=np.array([1.0, 1.0, 2.0]))
    with pytest.raises(ValueError, match="obs_data"):
        _linear_problem(np.array([[np.inf], [0.0]]))
    with pytest.raises(ValueError, match="param_noise"):
        _linear_problem(np.zeros((3, 1)), param_noise=-1.0)
