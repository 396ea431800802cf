"""Damage-driven optics (enkf.tissue.coagulation, issue #21): the algebra of the coagulated
fraction, the members' damage bookkeeping, a tiny identical twin against the random walk,
the innovations' log-likelihood, and the config's errors."""

import copy
import tomllib

import numpy as np
import pytest
from scipy.stats import multivariate_normal

import fem
from enkf import innovation_loglik
from enkf.app.config import identify_config_from_dict
from enkf.tissue import TissueForwardModel, identify
from enkf.tissue.coagulation import (
    Coagulation,
    CoagulationForwardModel,
    coagulated_fraction,
    effective_optics,
)
from enkf.tissue.pieces import assemble
from mcmatlab_py.config import ConfigError
from mcmatlab_py.heat import HeatSimulation

NATIVE_COAG = np.array([[1.0, 100.0, 1.5, 300.0]])  # mua, mus, mua_coag, mus_coag (cm^-1)
#: the tiny model's laser: 3 s of 1.5 W from 37 deg C take the surface to 75 deg C and the
#: absorbed-power-weighted coagulated fraction to 0.6 (measured)
LASER = HeatSimulation(P=1.5, duration_on=3.0, duration_off=1.0).laser_power
TIMES = 0.1 * np.arange(1, 41)


# ------------------------------------------------------------------ algebra
def test_fraction_is_zero_without_damage_and_one_when_coagulated():
    rng = np.random.default_rng(0)
    w = rng.random((3, 50))
    assert np.array_equal(coagulated_fraction(np.zeros((3, 50)), w), np.zeros(3))
    np.testing.assert_allclose(coagulated_fraction(np.full((3, 50), 800.0), w), 1.0, rtol=0,
                               atol=1e-15)
    # a node that no light reaches counts for nothing
    w[:, 0] = 0.0
    omega = np.zeros((3, 50))
    omega[:, 0] = 50.0
    assert np.array_equal(coagulated_fraction(omega, w), np.zeros(3))


def test_fraction_is_the_weighted_mean_and_monotone():
    rng = np.random.default_rng(1)
    w = rng.random(40)
    omega = rng.exponential(0.5, (1, 40))
    F = coagulated_fraction(omega, w)[0]
    assert F == pytest.approx(np.sum(w * (1 - np.exp(-omega[0]))) / w.sum(), rel=1e-14)
    # more damage anywhere never lowers F; F stays in [0, 1]
    prev = F
    for _ in range(20):
        omega = omega + rng.exponential(0.2, omega.shape) * (rng.random(omega.shape) < 0.3)
        F = coagulated_fraction(omega, w)[0]
        assert prev <= F <= 1.0
        prev = F


def test_effective_optics_interpolates_native_and_coagulated():
    native, coag = np.array([1.0, 100.0]), np.array([1.5, 300.0])
    np.testing.assert_array_equal(effective_optics(native, coag, 0.0), native)
    np.testing.assert_array_equal(effective_optics(native, coag, 1.0), coag)
    np.testing.assert_allclose(effective_optics(native, coag, 0.25), [1.125, 150.0])


@pytest.mark.parametrize("kw, message", [
    (dict(E=-1.0), "coagulation.E must be a finite number > 0"),
    (dict(A=float("inf")), "coagulation.A must be a finite number > 0"),
    (dict(nominal_factor=(1.5,)), "coagulation.nominal_factor must be two numbers > 0"),
    (dict(nominal_factor=(1.5, 0.0)), "coagulation.nominal_factor must be two numbers > 0"),
    (dict(mean_field_rel_std=-0.1), "coagulation.mean_field_rel_std must be a finite number >= 0"),
    (dict(mean_field_rel_std=float("nan")),
     "coagulation.mean_field_rel_std must be a finite number >= 0"),
])
def test_coagulation_settings_are_checked(kw, message):
    with pytest.raises(ValueError, match=message):
        Coagulation(**kw)


# ------------------------------------------------------------------ the members' damage
def _model(tissue, **kw):
    s = tissue.setup(T_initial=37.0, power=LASER, parameter_model="coagulation", **kw)
    return s, CoagulationForwardModel(TissueForwardModel(s), s.parameters.coagulation, s.parameters.names)


def test_damage_follows_the_members_and_is_never_added_twice(tissue):
    s, m = _model(tissue)
    theta = np.repeat(NATIVE_COAG, 2, axis=0)
    theta[1, 2:] = theta[1, :2]  # member 1: coagulation changes nothing
    T = np.full((2, m.mesh.p.shape[1]), 37.0)
    for t0, t1 in zip(np.r_[0.0, TIMES[:24]], TIMES[:25], strict=True):
        T = m(T, theta, t0, t1)
    F, eff = m.effective(theta, TIMES[24])
    assert 0.1 < F[0] < 1.0 and F[1] > 0.0  # both damaged; only member 0 changes optics
    np.testing.assert_allclose(eff[1], theta[1, :2])
    assert eff[0, 1] > 1.1 * theta[0, 1]
    # an ES-MDA re-run of a step starts from the same damage: the same result
    a = m(T, theta, TIMES[24], TIMES[25])
    b = m(T, theta, TIMES[24], TIMES[25])
    np.testing.assert_array_equal(a, b)
    # without coagulated optics the member follows the plain model exactly
    base = TissueForwardModel(s)
    T1 = np.full((1, m.mesh.p.shape[1]), 37.0)
    T2 = T1.copy()
    for t0, t1 in zip(np.r_[0.0, TIMES[:9]], TIMES[:10], strict=True):
        T1 = base(T1, theta[1:2, :2], t0, t1)
        T2 = m(T2, theta[1:2], t0, t1)  # a new run: its own damage starts at zero
    np.testing.assert_allclose(T2, T1, rtol=0, atol=1e-12)


def test_mean_field_model_error_grows_with_each_members_coagulated_fraction(tissue):
    """With the structured model error, a member's relative sd is the setup's plus
    ``mean_field_rel_std * sqrt(F)`` (F its coagulated fraction): no addition before any
    damage, the same correlated field scaled by it after; the random walk and
    ``mean_field_rel_std = 0`` get no addition."""
    s, _ = _model(tissue, model_error="structured")
    pieces = assemble(s)
    noise = pieces.model_noise()
    assert noise.extra_rel_std is not None
    theta = np.repeat(NATIVE_COAG, 2, axis=0)
    np.testing.assert_array_equal(pieces.model.mean_field_rel_std(theta, 0.0), [0.0, 0.0])
    T = np.full((2, pieces.model.mesh.p.shape[1]), 37.0)
    for t0, t1 in zip(np.r_[0.0, TIMES[:24]], TIMES[:25], strict=True):
        T = pieces.model(T, theta, t0, t1)
    F = pieces.model.effective(theta, TIMES[24])[0]
    assert np.all(F > 0.1)
    np.testing.assert_allclose(pieces.model.mean_field_rel_std(theta, TIMES[24]),
                               0.25 * np.sqrt(F), rtol=1e-12)
    # the noise drawn: the same correlated field, scaled by each member's relative sd
    X1 = pieces.model(T, theta, TIMES[24], TIMES[25])
    kw = dict(T_initial=37.0, power=LASER, parameter_model="coagulation",
              model_error="structured", model_noise_std=0.0)
    plain = assemble(tissue.setup(coagulation=Coagulation(mean_field_rel_std=0.0), **kw))
    assert plain.model_noise().extra_rel_std is None
    with_mf = assemble(tissue.setup(**kw))
    for p in (plain, with_mf):  # the same damage at TIMES[24]
        p.model._t, p.model._omega = TIMES[24], pieces.model._latest(TIMES[24])
    v0 = plain.model_noise()(np.random.default_rng(5), T, X1, theta, TIMES[24], TIMES[25])
    v1 = with_mf.model_noise()(np.random.default_rng(5), T, X1, theta, TIMES[24], TIMES[25])
    rel = s.model_error.rel_std
    np.testing.assert_allclose(v1, v0 * ((rel + 0.25 * np.sqrt(F)) / rel)[:, None], rtol=1e-10,
                               atol=1e-15)
    rw = assemble(tissue.setup(T_initial=37.0, power=LASER, model_error="structured"))
    assert rw.model_noise().extra_rel_std is None


# ------------------------------------------------------------------ tiny identical twin
def _twin(tissue, seed):
    s, m = _model(tissue)
    P = fem.probe_matrix(m.mesh, np.zeros((3, 1)))
    T = np.full((1, m.mesh.p.shape[1]), 37.0)
    y, eff = [], []
    for t0, t1 in zip(np.r_[0.0, TIMES[:-1]], TIMES, strict=True):
        T = m(T, NATIVE_COAG, t0, t1)
        y.append((P @ T.T)[0, 0])
        eff.append(m.effective(NATIVE_COAG, t1)[1][0])
    rng = np.random.default_rng(seed)
    return np.array(y)[:, None] + 0.1 * rng.standard_normal((len(TIMES), 1)), np.array(eff)


def test_twin_damage_driven_filter_beats_the_random_walk(tissue):
    """On data whose optics follow the damage, the damage-driven filter finds the
    coagulated absorption, follows the effective scattering closer than the project's
    walk for drifting optics, and its innovations are the likelier (three seeds; each
    run well under a second)."""
    err = {"coagulation": [], "random_walk": []}
    logev = {"coagulation": 0.0, "random_walk": 0.0}
    for seed in range(3):
        data, eff = _twin(tissue, seed)
        for model, rw in (("coagulation", 0.005), ("random_walk", [0.03, 0.10])):
            s = tissue.setup(T_initial=37.0, power=LASER, parameter_model=model, seed=seed,
                             random_walk_std=rw, random_walk_when_off=0.0)
            est = identify(s, TIMES, data)
            assert est.diverged is None
            optics = est.effective_mean if model == "coagulation" else est.param_mean
            err[model].append(np.sqrt(np.mean((optics[1:, 1] - eff[:, 1]) ** 2)))
            logev[model] += est.log_evidence()
            if model == "coagulation":
                assert est.names == ("mua", "mus", "mua_coag", "mus_coag")
                assert est.param_mean[-1, 2] == pytest.approx(1.5, rel=0.15)
    # measured (seeds 0-2): 92, 64, 46 cm^-1 against 112, 96, 109
    assert np.mean(err["coagulation"]) < 0.8 * np.mean(err["random_walk"])
    assert logev["coagulation"] > logev["random_walk"]


# ------------------------------------------------------------------ model comparison
def test_innovation_loglik_is_the_gaussian_predictive_density():
    rng = np.random.default_rng(3)
    Y, y = rng.normal(size=(7, 3)), rng.normal(size=3)
    R = np.array([0.5, 0.2, 1.0])
    C = 2.0 * np.cov(Y.T) + np.diag(R)
    assert innovation_loglik(Y, y, R, rho=2.0) == pytest.approx(
        multivariate_normal(Y.mean(0), C).logpdf(y), rel=1e-12)
    Rf = np.diag(R) + 0.1  # a full covariance; a missing component is dropped
    y[1] = np.nan
    keep = [0, 2]
    assert innovation_loglik(Y, y, Rf) == pytest.approx(multivariate_normal(
        Y.mean(0)[keep], np.cov(Y[:, keep].T) + Rf[np.ix_(keep, keep)]).logpdf(y[keep]),
        rel=1e-12)
    assert innovation_loglik(Y, np.full(3, np.nan), R) == 0.0
    # more observations than members: the (N, N) form of the same density
    Y, y, R = rng.normal(size=(3, 7)), rng.normal(size=7), rng.uniform(0.2, 1.0, 7)
    assert innovation_loglik(Y, y, R, rho=1.5) == pytest.approx(multivariate_normal(
        Y.mean(0), 1.5 * np.cov(Y.T) + np.diag(R)).logpdf(y), rel=1e-12)


# ------------------------------------------------------------------ config
@pytest.fixture(scope="module")
def tiny():
    from pathlib import Path

    return tomllib.loads((Path(__file__).parents[1] / "examples" / "tiny.toml").read_text())


def _cfg(tiny, **flt):
    cfg = copy.deepcopy(tiny)
    cfg["filter"].update(flt)
    return cfg


def test_config_builds_the_damage_driven_filter(tiny):
    c = identify_config_from_dict(_cfg(
        tiny, parameter_model="coagulation", random_walk_std=[0.005, 0.005, 0.002, 0.002],
        coagulation={"E": 4.0e5, "A": 1e60, "nominal_factor": [2.0, 4.0],
                     "mean_field_rel_std": 0.1},
        prior={"mus_coag": [150.0, 800.0]}, bounds={"mua_coag": [0.1, 50.0]}))
    s = c.setup(absorption=lambda mua, mus: None)
    assert s.parameters.names == ("mua", "mus", "mua_coag", "mus_coag")
    assert (s.parameters.coagulation.E, s.parameters.coagulation.A) == (4.0e5, 1e60)
    assert s.parameters.coagulation.mean_field_rel_std == 0.1
    lo, hi = s.parameters.prior_bounds()
    np.testing.assert_allclose(lo, [0.5, 50.0, 1.0, 150.0])  # mua_coag: 0.5 x 2 x 1
    np.testing.assert_allclose(hi, [2.0, 200.0, 4.0, 800.0])
    assert c.param_bounds.shape == (4, 2) and tuple(c.param_bounds[2]) == (0.1, 50.0)


@pytest.mark.parametrize("flt, message", [
    (dict(parameter_model="damage"), "filter.parameter_model must be one of"),
    (dict(coagulation={"E": 4e5}),
     "[filter.coagulation] is given but filter.parameter_model is 'random_walk'"),
    (dict(parameter_model="coagulation", coagulation={"E": -4e5}),
     "filter.coagulation.E must be > 0"),
    (dict(parameter_model="coagulation", coagulation={"A": 0}),
     "filter.coagulation.A must be > 0"),
    (dict(parameter_model="coagulation", coagulation={"Ea": 4e5}), "filter.coagulation"),
    (dict(parameter_model="coagulation", coagulation={"mean_field_rel_std": -0.25}),
     "filter.coagulation.mean_field_rel_std must be >= 0"),
    (dict(parameter_model="coagulation", coagulation={"nominal_factor": 3.0}),
     "filter.coagulation.nominal_factor must be [mua, mus]"),
    (dict(prior={"mus_coag": [100.0, 500.0]}),
     'filter.prior.mus_coag: mus_coag is not estimated (only with filter.parameter_model = '
     '"coagulation")'),
    (dict(parameter_model="coagulation", random_walk_std=[0.01, 0.01]),
     "filter.random_walk_std must be a number or 4 numbers"),
    (dict(parameter_model="coagulation", prior={"mus_coag": [100.0, 5000.0]}),
     "filter.emulator.mus_range = [10.0, 2000.0] must cover the prior of mus_coag"),
])
def test_config_errors(tiny, flt, message):
    with pytest.raises(ConfigError) as err:
        identify_config_from_dict(_cfg(tiny, **flt))
    assert message in str(err.value)
