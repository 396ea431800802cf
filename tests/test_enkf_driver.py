"""The augmented-state driver: exact Kalman filter on a linear augmented system,
Lorenz-96 parameter estimation, NaN gaps, reproducibility, health checks, input checks.
"""

import numpy as np
import pytest

from enkf import (
    FilterConfig,
    FilterDivergence,
    FilterProblem,
    HealthCheck,
    LogTransform,
    run_filter,
    uniform_prior,
)
from enkf.toy_models import kalman_filter, lorenz96_step

# Linear state with a parameter forcing it: x_{k+1} = F x_k + g theta_k + q_k,
# theta_{k+1} = theta_k + xi_k (Arnold & Fichera's random walk). In the augmented
# variable z = [x; theta] this is linear-Gaussian, so the Kalman filter is exact.
F2 = np.array([[0.8, 0.1], [0.2, 0.7]])
G2 = np.array([0.5, 0.2])
C = np.array([0.05, 0.1])  # model-noise variances
E_RW = 0.01  # random-walk variance
H = np.array([[1.0, 0.0]])  # only x_0 is observed
R = np.array([0.2])
M0 = np.array([0.0, 1.0, 2.0])  # prior mean of [x; theta]
S0 = np.array([0.5, 0.5, 1.0])  # prior std
THETA_TRUE = 3.0


def linear_forecast(X, theta, t0, t1):
    return X @ F2.T + theta[:, :1] * G2


def gaussian_prior(rng, N):
    Z = M0 + S0 * rng.standard_normal((N, 3))
    return Z[:, :2], Z[:, 2:]


def linear_problem(M=10, gap=None, theta_true=THETA_TRUE, **kw):
    rng = np.random.default_rng(0)
    x = np.array([0.0, 1.0])
    data = np.empty((M, 1))
    for k in range(M):
        x = F2 @ x + G2 * theta_true + np.sqrt(C) * rng.standard_normal(2)
        data[k] = H @ x + np.sqrt(R) * rng.standard_normal(1)
    if gap is not None:
        data[gap] = np.nan
    args = dict(
        forecast=linear_forecast,
        observation=H,
        obs_times=np.arange(1.0, M + 1),
        obs_data=data,
        obs_cov=R,
        prior=gaussian_prior,
        model_noise=C,
        param_noise=E_RW,
        tracked=[0, 1],
    )
    args.update(kw)
    return FilterProblem(**args)


def augmented_kalman(problem):
    Fa = np.block([[F2, G2[:, None]], [np.zeros((1, 2)), np.ones((1, 1))]])
    Ha = np.hstack([H, np.zeros((1, 1))])
    return kalman_filter(M0, np.diag(S0**2), Fa, np.append(C, E_RW), Ha, R, problem.obs_data)


@pytest.mark.parametrize("method", ["enkf", "etkf"])
def test_driver_matches_augmented_kalman_filter(method):
    # N = 20000: the mean of a component with variance s^2 has standard error
    # s / sqrt(N), its std about s / sqrt(2 (N - 1)); we allow 5 of them (iid-like
    # errors, see test_enkf_analysis). A data gap at step 4 is a forecast-only step.
    N = 20000
    problem = linear_problem(gap=3)
    res = run_filter(problem, FilterConfig(n_members=N, method=method, seed=1))
    means, covs = augmented_kalman(problem)
    sd = np.sqrt(np.diagonal(covs, axis1=1, axis2=2))  # (M + 1, 3)
    mean_ens = np.hstack([res.tracked_mean, res.param_mean])
    std_ens = np.hstack([res.tracked_std, res.param_std])
    assert np.all(np.abs(mean_ens - means) < 5 * sd / np.sqrt(N))
    assert np.all(np.abs(std_ens - sd) < 5 * sd / np.sqrt(2 * (N - 1)))
    assert res.analysed.tolist() == [True] * 3 + [False] + [True] * 6
    # The parameter is learnt through its correlation with the observed state only.
    assert res.param_std[-1, 0] < 0.5 * res.param_std[0, 0]


def test_result_shapes_and_callback():
    problem = linear_problem(M=6)
    reports = []
    res = run_filter(problem, FilterConfig(n_members=20), callback=reports.append)
    assert res.times.shape == (7,) and res.times[0] == 0.0
    assert res.param_mean.shape == res.param_std.shape == (7, 1)
    assert res.tracked_mean.shape == res.tracked_std.shape == (7, 2)
    assert res.step_latency_s.shape == res.analysis_latency_s.shape == (6,)
    assert np.all(res.step_latency_s > 0) and np.all(res.analysis_latency_s <= res.step_latency_s)
    assert res.state_ensemble.shape == (20, 2) and res.param_ensemble.shape == (20, 1)
    assert [r.step for r in reports] == list(range(7))
    assert reports[-1].time == 6.0
    np.testing.assert_array_equal(reports[3].param_mean, res.param_mean[3])


def test_all_missing_data_is_a_pure_forecast():
    # No datum, no analysis: with no noise the ensemble mean follows the model.
    problem = linear_problem(M=5, obs_data=np.full((5, 1), np.nan), model_noise=0.0, param_noise=0.0)
    res = run_filter(problem, FilterConfig(n_members=30, seed=3))
    assert not res.analysed.any()
    X, th = gaussian_prior(np.random.default_rng(3), 30)
    for _ in range(5):
        X = linear_forecast(X, th, 0, 1)
    np.testing.assert_allclose(res.state_ensemble, X, atol=1e-12)
    np.testing.assert_allclose(res.param_mean[-1], th.mean(0), atol=1e-12)


@pytest.mark.parametrize("method", ["enkf", "etkf"])
def test_same_seed_same_numbers(method):
    problem = linear_problem()
    a = run_filter(problem, FilterConfig(n_members=25, method=method, seed=7))
    b = run_filter(problem, FilterConfig(n_members=25, method=method, seed=7))
    c = run_filter(problem, FilterConfig(n_members=25, method=method, seed=8))
    for name in ("param_mean", "param_std", "tracked_mean", "tracked_std", "state_ensemble"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.param_mean, c.param_mean)


def test_log_transform_keeps_parameters_positive_and_reports_physical_stats():
    # A parameter near zero with a wide prior: the identity transform pushes members
    # negative, the log transform cannot; statistics come from exp(u).
    problem = linear_problem(
        theta_true=0.05, prior=uniform_prior([0.0, 1.0], [0.01], [4.0]), param_noise=0.05
    )
    ident = run_filter(problem, FilterConfig(n_members=50, seed=2))
    assert np.any(ident.param_ensemble <= 0)
    res = run_filter(
        FilterProblem(**{**problem.__dict__, "transforms": LogTransform()}),
        FilterConfig(n_members=50, seed=2),
    )
    assert np.all(res.param_ensemble > 0)
    np.testing.assert_allclose(res.param_mean[-1], res.param_ensemble.mean(0))
    np.testing.assert_allclose(res.param_std[-1], res.param_ensemble.std(0, ddof=1))


def test_lorenz96_forcing_is_identified():
    # Nonlinear augmented test: estimate F of Lorenz-96 from half the variables.
    rng = np.random.default_rng(0)
    K, dt = 200, 0.05
    xs = [lorenz96_step(8 + rng.standard_normal(40), dt, n_steps=500)]
    for _ in range(K):
        xs.append(lorenz96_step(xs[-1], dt))
    xs = np.array(xs)
    y = xs[1:] + rng.standard_normal((K, 40))
    y[:, 1::2] = np.nan
    problem = FilterProblem(
        forecast=lambda X, th, t0, t1: lorenz96_step(X, t1 - t0, force=th[:, :1]),
        observation=np.eye(40),
        obs_times=dt * np.arange(1, K + 1),
        obs_data=y,
        obs_cov=np.ones(40),
        prior=uniform_prior(xs[0], [6.0], [10.0], state_std=1.0),
        transforms=LogTransform(),
        param_noise=1e-6,
    )
    res = run_filter(problem, FilterConfig(n_members=40, inflation=1.06, seed=1))
    assert abs(res.param_mean[-1, 0] - 8.0) < 0.25
    assert res.param_std[-1, 0] < 0.2 * res.param_std[0, 0]


def test_health_nonfinite_forecast_raises_with_step_and_time():
    def forecast(X, theta, t0, t1):
        Xn = linear_forecast(X, theta, t0, t1)
        if t1 >= 4.0:
            Xn[3, 1] = np.nan
        return Xn

    with pytest.raises(FilterDivergence) as info:
        run_filter(linear_problem(forecast=forecast), FilterConfig(n_members=10))
    err = info.value
    assert (err.step, err.time) == (4, 4.0)
    assert "non-finite state" in err.what and "columns [1]" in err.what
    assert err.result.times.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert np.all(np.isfinite(err.result.param_mean[:4]))
    assert "step 4" in str(err)


def test_health_bounds_collapse_and_custom_hook():
    problem = linear_problem()
    with pytest.raises(FilterDivergence) as info:
        run_filter(problem, FilterConfig(n_members=30), health=HealthCheck(param_bounds=[[0.0, 2.5]]))
    assert info.value.step > 0 and "parameter 0 mean" in info.value.what
    assert info.value.result.param_mean[-1, 0] > 2.5
    # Collapse: prior std 1 passes, no random walk and data shrink it below 0.3.
    with pytest.raises(FilterDivergence) as info:
        run_filter(
            linear_problem(param_noise=0.0), FilterConfig(n_members=30), health=HealthCheck(min_param_std=0.3)
        )
    assert info.value.step > 0 and "collapsed" in info.value.what

    def hook(X, theta):
        return "too warm" if X[:, 0].mean() > 1.0 else None

    with pytest.raises(FilterDivergence, match="too warm") as info:
        run_filter(problem, FilterConfig(n_members=30), health=hook)
    assert info.value.result.tracked_mean[-1, 0] > 1.0


def test_health_state_bounds_stop_a_runaway_state():
    """A state whose mean leaves ``state_bounds`` stops the run at that step (a model that
    throws its second component out at t = 4 here); inside them the run is untouched."""
    def forecast(X, theta, t0, t1):
        Xn = linear_forecast(X, theta, t0, t1)
        if t1 >= 4.0:
            Xn[:, 1] += 1e4
        return Xn

    problem = linear_problem(forecast=forecast)
    with pytest.raises(FilterDivergence) as info:
        run_filter(problem, FilterConfig(n_members=20), health=HealthCheck(state_bounds=(-1e3, 1e3)))
    assert (info.value.step, info.value.time) == (4, 4.0)
    assert "state column 1 mean" in info.value.what and "[-1000, 1000]" in info.value.what
    assert info.value.result.tracked_mean[-1, 1] > 1e3
    plain = run_filter(linear_problem(), FilterConfig(n_members=20, seed=4))
    bounded = run_filter(linear_problem(), FilterConfig(n_members=20, seed=4),
                         health=HealthCheck(state_bounds=(-1e3, 1e3)))
    np.testing.assert_array_equal(plain.state_ensemble, bounded.state_ensemble)
    with pytest.raises(ValueError, match="^state_bounds"):
        HealthCheck(state_bounds=(1.0, 0.0))


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"n_members": 1}, "n_members"),
        ({"n_members": 2.5}, "n_members"),
        ({"method": "4dvar"}, "method"),
        ({"inflation": -1.0}, "inflation"),
        ({"rtps": 1.5}, "rtps"),
        ({"rtps": True}, "rtps"),
        ({"seed": None}, "seed"),
    ],
)
def test_bad_config(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}\b"):
        FilterConfig(**kwargs)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"obs_data": np.zeros((4, 1))}, "obs_data"),  # rows differ from obs_times
        ({"obs_times": np.array([1.0, 3.0, 2.0] + list(range(4, 11)))}, "obs_times"),
        ({"obs_times": np.arange(0.0, 10.0)}, "obs_times"),  # not after t0
        ({"obs_cov": np.array([-0.2])}, "obs_cov"),
        ({"obs_cov": np.ones(2)}, "obs_cov"),
        ({"model_noise": np.array([0.1, -0.1])}, "model_noise"),
        ({"param_noise": -1.0}, "param_noise"),
        ({"observation": np.ones((2, 2))}, "observation"),
        ({"tracked": [-1]}, "tracked"),
        ({"forecast": 3}, "forecast"),
        ({"obs_error": 0.1}, "obs_error"),
    ],
)
def test_bad_problem(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}\b"):
        linear_problem(**kwargs)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"model_noise": np.ones(3)}, "model_noise"),  # n_state is 2
        ({"param_noise": np.ones(2)}, "param_noise"),  # n_par is 1
        ({"observation": np.ones((1, 3))}, "observation"),
        ({"tracked": [2]}, "tracked"),
        ({"forecast": lambda X, th, t0, t1: X[:, :1]}, "forecast"),
        ({"observation": lambda X: X}, "observation"),  # maps to 2 values, data has 1
        ({"prior": lambda rng, N: (np.zeros((N - 1, 2)), np.zeros((N - 1, 1)))}, "prior"),
        ({"transforms": [LogTransform(), LogTransform()]}, "transforms"),
        ({"obs_error": lambda y: np.ones(1)}, "obs_error"),
        ({"obs_error": lambda y: np.full((1, 1), np.nan)}, "obs_error"),
    ],
)
def test_bad_sizes_found_at_run(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}\b"):
        run_filter(linear_problem(**kwargs), FilterConfig(n_members=5))


def test_param_noise_scale_holds_the_random_walk_still():
    # Scale 0 on every step with no data: the parameters never move.
    problem = linear_problem(
        M=4, obs_data=np.full((4, 1), np.nan), param_noise=0.5, param_noise_scale=lambda t0, t1: 0.0
    )
    res = run_filter(problem, FilterConfig(n_members=10))
    np.testing.assert_array_equal(res.param_mean, np.repeat(res.param_mean[:1], 5, axis=0))
    bad = linear_problem(param_noise_scale=lambda t0, t1: -1.0)
    with pytest.raises(ValueError, match="^param_noise_scale"):
        run_filter(bad, FilterConfig(n_members=10))


def test_param_dynamics_moves_the_parameters_before_the_walk():
    # No data, no walk: the parameters follow the deterministic drift exactly.
    problem = linear_problem(
        M=4, obs_data=np.full((4, 1), np.nan), param_noise=0.0,
        param_dynamics=lambda U, t0, t1: U + 2.0 * (t1 - t0),
    )
    res = run_filter(problem, FilterConfig(n_members=10))
    drift = res.param_mean - res.param_mean[:1]
    np.testing.assert_allclose(drift[:, 0], 2.0 * (res.times - res.times[0]), atol=1e-12)
    bad = linear_problem(param_dynamics=lambda U, t0, t1: U[:, :0])
    with pytest.raises(ValueError, match="^param_dynamics"):
        run_filter(bad, FilterConfig(n_members=10))


def test_mda_on_a_linear_model_has_the_moments_of_one_analysis():
    """ES-MDA over one step (FilterConfig.mda) updates start, parameters and the step's
    noises mda times with mda x R; for a linear model with the deterministic ETKF the
    ensemble mean and spread then equal those of the one-analysis filter."""
    problem = linear_problem(M=6)
    one = run_filter(problem, FilterConfig(n_members=30, method="etkf", seed=3))
    three = run_filter(problem, FilterConfig(n_members=30, method="etkf", seed=3, mda=3))
    np.testing.assert_allclose(three.param_mean, one.param_mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(three.param_std, one.param_std, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(three.tracked_mean, one.tracked_mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(three.tracked_std, one.tracked_std, rtol=1e-9, atol=1e-9)
    with pytest.raises(ValueError, match="^mda"):
        FilterConfig(mda=0)


def test_observation_offset_is_learned_as_a_parameter():
    """y = x + b + noise with x known and b ~ N(0, 1) a parameter: the ETKF's posterior of
    b after M readings is the conjugate Gaussian one (mean and variance, within the
    ensemble's sampling error)."""
    from enkf.loop import run_filter
    from enkf.problem import FilterConfig, FilterProblem

    rng = np.random.default_rng(2)
    M, sigma, b_true, N = 30, 0.3, 0.8, 400
    y = 2.0 + b_true + sigma * rng.standard_normal((M, 1))
    problem = FilterProblem(
        forecast=lambda X, th, t0, t1: X, observation=np.array([[1.0]]),
        obs_times=np.arange(1, M + 1.0), obs_data=y, obs_cov=np.array([sigma**2]),
        prior=lambda r, n: (np.full((n, 1), 2.0), r.standard_normal((n, 1))),
        observation_offset=lambda th: th[:, :1])
    res = run_filter(problem, FilterConfig(n_members=N, method="etkf", seed=4))
    prec = 1.0 + M / sigma**2
    mean = np.sum(y - 2.0) / sigma**2 / prec
    assert res.param_mean[-1, 0] == pytest.approx(mean, abs=4 / np.sqrt(prec * N))
    assert res.param_std[-1, 0] ** 2 == pytest.approx(1 / prec, rel=4 * np.sqrt(2 / N))
    with pytest.raises(ValueError, match="observation_offset must return shape"):
        run_filter(FilterProblem(
            forecast=lambda X, th, t0, t1: X, observation=np.array([[1.0]]),
            obs_times=np.arange(1, 3.0), obs_data=y[:2], obs_cov=np.array([sigma**2]),
            prior=lambda r, n: (np.full((n, 1), 2.0), r.standard_normal((n, 1))),
            observation_offset=lambda th: th[:, 0]), FilterConfig(n_members=10, method="etkf"))
    with pytest.raises(ValueError, match="observation_offset must be callable"):
        FilterProblem(forecast=lambda X, th, t0, t1: X, observation=np.array([[1.0]]),
                      obs_times=[1.0], obs_data=[[1.0]], obs_cov=[1.0],
                      prior=lambda r, n: (np.zeros((n, 1)), None), observation_offset=3.0)


@pytest.mark.parametrize("method", ["enkf", "etkf"])
def test_obs_error_adds_to_the_observation_covariance_of_each_step(method):
    """A constant ``obs_error`` is the same filter as its sum with ``obs_cov``, to rounding
    (the full covariance goes through the dense whitening, the diagonal one through the
    diagonal branch: the last bit differs on some CPUs, 4e-16 measured on an AMD EPYC);
    one that depends on the forecast's mean observation gets that mean."""
    extra = 0.3
    a = run_filter(linear_problem(obs_error=lambda y: np.array([[extra]])),
                   FilterConfig(n_members=30, method=method, seed=2))
    b = run_filter(linear_problem(obs_cov=R + extra), FilterConfig(n_members=30, method=method,
                                                                    seed=2))
    np.testing.assert_allclose(a.param_mean, b.param_mean, rtol=1e-13, atol=0)
    np.testing.assert_allclose(a.tracked_std, b.tracked_std, rtol=1e-13, atol=0)
    # a wrong sum (obs_cov alone) is far outside that
    c = run_filter(linear_problem(), FilterConfig(n_members=30, method=method, seed=2))
    assert np.max(np.abs(c.param_mean / b.param_mean - 1)) > 1e-6
    seen = []

    def relative(y_mean):
        seen.append(y_mean.copy())
        return np.array([[0.1 * y_mean[0] ** 2]])

    res = run_filter(linear_problem(obs_error=relative), FilterConfig(n_members=30, seed=2))
    assert len(seen) == res.analysed.sum() and all(v.shape == (1,) for v in seen)
    c = run_filter(linear_problem(), FilterConfig(n_members=30, seed=2))
    assert res.param_std[-1, 0] > c.param_std[-1, 0]  # less information


@pytest.mark.parametrize("mda", [1, 3])
def test_rtps_relaxes_the_state_spread_to_the_forecast(mda):
    """With ``rtps`` the filter's analysed state spread lies the stated fraction of the way
    back to its forecast spread (re-computed here from each step's forecast and analysis
    ensembles, which the filter reports), the parameters are left alone, and alpha = 0
    is the filter without it, bit for bit."""
    problem = linear_problem(M=6)
    seen = {}

    def keep(rep):
        if rep.step and rep.forecast is not None:
            seen[rep.step] = (rep.forecast[0].copy(), rep.state_ensemble.copy())

    base = run_filter(problem, FilterConfig(n_members=30, seed=2, mda=mda))
    zero = run_filter(problem, FilterConfig(n_members=30, seed=2, mda=mda, rtps=0.0))
    np.testing.assert_array_equal(base.state_ensemble, zero.state_ensemble)
    a = 0.6
    run_filter(problem, FilterConfig(n_members=30, seed=2, mda=mda, rtps=a), callback=keep)
    assert sorted(seen) == list(range(1, 7))
    plain = {}
    run_filter(problem, FilterConfig(n_members=30, seed=2, mda=mda),
               callback=lambda r: plain.__setitem__(r.step, r.state_ensemble.copy()))
    # step 1 starts from the same prior: its plain analysis is the one RTPS relaxes
    Xf, Xa = seen[1]
    sa, sf = plain[1].std(0, ddof=1), Xf.std(0, ddof=1)
    np.testing.assert_allclose(Xa.std(0, ddof=1), (1 - a) * sa + a * sf, rtol=1e-10)
    np.testing.assert_allclose(Xa.mean(0), plain[1].mean(0), rtol=1e-12, atol=1e-12)
    for k, (Xf, Xa) in seen.items():  # never wider than the forecast, never narrower
        assert np.all(Xa.std(0, ddof=1) <= Xf.std(0, ddof=1) * (1 + 1e-12)), k


def test_reflect_folds_members_into_the_bounds():
    from enkf.loop import reflect
    b = np.array([[0.0, 1.0], [-np.inf, 1.0]])
    inside = np.array([[0.2, -5.0], [1.0, 0.5]])
    assert reflect(inside, b) is inside  # nothing to do: the same array
    U = np.array([[1.2, 1.2], [-0.3, 5.0], [2.5, -7.0], [3.7, 1.0]])
    np.testing.assert_allclose(reflect(U, b), [[0.8, 0.8], [0.3, -3.0], [0.5, -7.0],
                                               [0.3, 1.0]], atol=1e-12)


@pytest.mark.parametrize("bounded", [True, False])
def test_param_walk_bounds_keep_a_free_walk_inside(bounded):
    # No data and a wide walk: reflected at [1.5, 2.5], the members stay inside and
    # spread as a uniform on it (sd 1/sqrt(12)); unbounded, they leave it.
    seen = []
    problem = linear_problem(M=30, obs_data=np.full((30, 1), np.nan), param_noise=4.0,
                             param_walk_bounds=np.array([[1.5, 2.5]]) if bounded else None)
    run_filter(problem, FilterConfig(n_members=400, seed=3),
               callback=lambda rep: seen.append(rep.param_ensemble[:, 0].copy()))
    later = np.array(seen[1:])
    inside = (later >= 1.5) & (later <= 2.5)
    if bounded:
        assert inside.all()
        # the sd of 400 uniform members: 0.2887 with a standard error of about 0.005
        np.testing.assert_allclose(later[-1].std(ddof=1), 1 / np.sqrt(12), atol=0.025)
    else:
        assert inside.mean() < 0.5


def test_bad_param_walk_bounds():
    with pytest.raises(ValueError, match="^param_walk_bounds"):
        linear_problem(param_walk_bounds=np.array([[2.0, 1.0]]))
    with pytest.raises(ValueError, match="^param_walk_bounds"):
        run_filter(linear_problem(param_walk_bounds=np.array([[0.0, 1.0], [0.0, 1.0]])),
                   FilterConfig(n_members=5))


def test_stratified_prior_puts_one_member_in_each_stratum():
    """uniform_prior(sampling="stratified"): each parameter's N draws fall one in each
    of the N equal parts of its range (a Latin hypercube), within the bounds; the pairing
    of the parameters' strata is random (different seeds, different pairs)."""
    lo, hi = np.array([0.5, 50.0]), np.array([2.0, 200.0])
    prior = uniform_prior([0.0], lo, hi, sampling="stratified")
    N = 50
    _, th = prior(np.random.default_rng(3), N)
    strata = np.floor((th - lo) / (hi - lo) * N).astype(int)
    assert all(sorted(strata[:, j]) == list(range(N)) for j in range(2))
    _, th2 = prior(np.random.default_rng(4), N)
    pairs = {tuple(r) for r in strata}
    pairs2 = {tuple(r) for r in np.floor((th2 - lo) / (hi - lo) * N).astype(int)}
    assert pairs != pairs2
    # random draws of 50 leave some of the 50 strata empty (at random: 1 - 1/e of them filled)
    _, th3 = uniform_prior([0.0], lo, hi)(np.random.default_rng(3), N)
    assert len(set(np.floor((th3[:, 0] - lo[0]) / (hi[0] - lo[0]) * N).astype(int))) < N
    with pytest.raises(ValueError, match="sampling must be one of .*got 'lhs'"):
        uniform_prior([0.0], lo, hi, sampling="lhs")
