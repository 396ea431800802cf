"""The filter's problem definition: settings, the problem, the prior, and the results.

Glossary: see :mod:`enkf`. The loop that uses these is :func:`enkf.loop.run_filter`.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from .adaptive import AdaptiveInflation
from .analysis import METHODS
from .checks import as_generator, covariance, float_array, fraction, variances
from .transforms import IdentityTransform, Transform

__all__ = [
    "DEFAULT_METHOD",
    "FilterConfig",
    "FilterDivergence",
    "FilterProblem",
    "FilterResult",
    "Forecast",
    "Prior",
    "StepReport",
    "PRIOR_SAMPLINGS",
    "stratified_uniform",
    "uniform_prior",
]

#: the analysis scheme used when none is named, everywhere (library, config, paper, CLI):
#: the deterministic square-root ETKF (no sampling noise from perturbed observations)
DEFAULT_METHOD = "etkf"

Forecast = Callable[[np.ndarray, np.ndarray, float, float], np.ndarray]
#: ``prior(rng, N) -> (E_state (N, n_state), theta (N, n_par) physical)``
Prior = Callable[[np.random.Generator, int], tuple[np.ndarray, np.ndarray]]


# ----------------------------------------------------------------------------- inputs


@dataclass(frozen=True)
class FilterConfig:
    """Settings of the filter itself (not of the problem).

    Parameters
    ----------
    n_members : int
        Ensemble size :math:`N \\ge 2` (the paper uses 50).
    method : {"etkf", "enkf"}
        ``"etkf"`` (:data:`DEFAULT_METHOD`): deterministic symmetric square-root ETKF.
        ``"enkf"``: stochastic EnKF with perturbed observations, the paper's analysis.
    inflation : float
        Multiplicative inflation :math:`\\lambda > 0` of the analysis anomalies
        (1 = none, the paper's setting).
    center_perturbations : bool
        Passed to :func:`enkf.analysis.enkf_perturbed_obs` as ``center``
        (default True; False reproduces the paper's plain perturbations).
    seed : int
        Seed of the single Generator that draws the prior, model noise, random
        walk and observation perturbations (and rotations), in that order each step.
    rotate : bool
        After each analysis, rotate the anomalies by a random mean-preserving
        orthogonal matrix (:func:`enkf.spread.random_rotation`; DAPPER's
        ``rot=True``). Recommended for long ETKF runs with little inflation.
    mda : int
        Analysis iterations per observed step (1: the usual filter). With ``mda > 1``
        each observed step is an ensemble smoother with multiple data assimilation
        over that one step (Emerick & Reynolds 2013): the members' start (state and
        parameters) is updated ``mda`` times with the observation-error covariance
        times ``mda``, and the step is re-run from the updated start each time, so
        ``mda + 1`` forecasts per step. Equal to one analysis for a linear model;
        for a strongly nonlinear one (a parameter that acts only through a
        saturating map) it replaces one large linear jump by several small ones.
    adaptive_inflation : AdaptiveInflation, optional
        Estimate a factor on the forecast covariance from the innovations
        (:mod:`enkf.adaptive`) and apply it before each analysis (after it with
        ``mda > 1``), on top of ``inflation``. Default: none.
    rtps : float
        Relaxation to prior spread of the state part after each analysis,
        :math:`\\alpha \\in [0, 1]` (:func:`enkf.spread.relax_to_prior_spread`;
        0 = none, the default). The parameters keep their random walk.
    """

    n_members: int = 50
    method: str = DEFAULT_METHOD
    inflation: float = 1.0
    center_perturbations: bool = True
    seed: int = 0
    rotate: bool = False
    mda: int = 1
    adaptive_inflation: AdaptiveInflation | None = None
    rtps: float = 0.0

    def __post_init__(self):
        if (
            not isinstance(self.n_members, numbers.Integral)
            or isinstance(self.n_members, bool)
            or self.n_members < 2
        ):
            raise ValueError(f"n_members must be an int >= 2, got {self.n_members!r}")
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if not (
            isinstance(self.inflation, numbers.Real) and np.isfinite(self.inflation) and self.inflation > 0
        ):
            raise ValueError(f"inflation must be a finite number > 0, got {self.inflation!r}")
        if not isinstance(self.mda, numbers.Integral) or isinstance(self.mda, bool) or self.mda < 1:
            raise ValueError(f"mda must be an int >= 1, got {self.mda!r}")
        as_generator(self.seed, "seed")
        fraction(self.rtps, "rtps")
        if self.adaptive_inflation is not None and not isinstance(self.adaptive_inflation,
                                                                  AdaptiveInflation):
            raise ValueError("adaptive_inflation must be an enkf.AdaptiveInflation or None, got "
                             f"{type(self.adaptive_inflation).__name__}")


@dataclass(frozen=True)
class FilterProblem:
    """What is filtered: model, observations, noise, prior and parameter transforms.

    Parameters
    ----------
    forecast : callable
        ``forecast(E_state, theta, t0, t1) -> E_state``: advance all members,
        ``E_state`` of shape ``(N, n_state)``, ``theta`` ``(N, n_par)`` in
        physical units, from ``t0`` to ``t1`` (s).
    observation : ndarray or scipy.sparse matrix of shape (p, n_state), or callable
        The observation operator :math:`G` on the state part: a matrix ``P``
        (``Y = E_state @ P.T``), or ``G(E_state) -> Y`` of shape ``(N, p)``.
    obs_times : ndarray, shape (M,)
        Filter step end times, strictly increasing and after ``t0``.
    obs_data : ndarray, shape (M, p)
        Data at ``obs_times``; NaN marks a missing value (a fully NaN row means
        a forecast-only step).
    obs_cov : ndarray, shape (p,) or (p, p)
        Observation-error covariance :math:`D` (or its diagonal), positive definite.
    prior : callable
        ``prior(rng, N) -> (E_state (N, n_state), theta (N, n_par))``, theta in
        physical units (see :func:`uniform_prior`).
    model_noise : float or ndarray, shape (n_state,), or callable
        Diagonal of :math:`C`: variances of the additive state noise, per filter
        step, in state units squared. Zero entries get no noise. Or a structured
        model error ``noise(rng, X0, X1, theta, t0, t1) -> v (N, n_state)`` drawn
        from the loop's Generator after the forecast ``X1`` of the start ``X0``
        (e.g. time-correlated, proportional to the step's tendency
        ``X1 - X0``; :class:`enkf.tissue.StructuredModelError`), added to ``X1``.
    param_noise : float or ndarray, shape (n_par,) or (n_par, n_par)
        Random-walk covariance :math:`E_\\mathrm{rw}` per step, in *transformed*
        units, diagonal or full (positive semi-definite).
    transforms : Transform or sequence of Transform
        One for all parameters or one per parameter (default identity).
    t0 : float
        Time of the prior ensemble (s).
    tracked : sequence of int
        Indices into the state whose mean and std are recorded every step
        (e.g. probe nodes).
    param_noise_scale : callable, optional
        ``scale(t0, t1) -> float >= 0`` multiplying the random-walk standard
        deviation of the step from ``t0`` to ``t1``, e.g. 0 while nothing can
        change the parameters (laser off). Default: 1 for every step.
    param_dynamics : callable, optional
        ``dynamics(U, t0, t1) -> U``: a deterministic move of the parameter ensemble
        ``U`` (N, n_par), in *transformed* units, applied after the state forecast
        and before the random walk, e.g. a drift ``u += v (t1 - t0)`` whose rate
        ``v`` is itself a filtered parameter (a local linear trend). Default: none
        (the pure random walk of the paper).
    param_walk_bounds : ndarray, shape (n_par, 2), optional
        Bounds of each parameter in *transformed* units at which the random walk is
        reflected (a walk on a bounded interval): a member that the step's walk carries
        past a bound comes back by as much. A walk that the data do not hold back (a
        parameter the readings barely see) then stays in the range the health check
        allows. Default: none (an unbounded walk).
    localization : (rho_xy, rho_yy), optional
        Schur-product tapers for :func:`enkf.analysis.enkf_localized`, rows of
        ``rho_xy`` over the augmented state (the state, then the parameters). Only
        with ``method="enkf"``.
    observation_offset : callable, optional
        ``offset(theta) -> (N, p)``: a term of the observation that depends on the
        parameters (physical units), added to ``observation``'s: ``Y = G(E_state) +
        offset(theta)``, e.g. an unknown calibration offset of each sensor carried as a
        parameter of the ensemble. Default: none.
    obs_error : callable, optional
        ``obs_error(y_mean) -> (p, p)``: a covariance added to ``obs_cov`` at each
        analysis, from the forecast's mean observation ``y_mean`` (p,), e.g. a model error
        in observation space that grows with the predicted signal
        (:meth:`enkf.tissue.image.ThermalImage.error_covariance`). Default: none.
    """

    forecast: Forecast
    observation: object
    obs_times: np.ndarray
    obs_data: np.ndarray
    obs_cov: np.ndarray
    prior: Prior
    model_noise: float | np.ndarray | Callable = 0.0
    param_noise: float | np.ndarray = 0.0
    transforms: Transform | Sequence[Transform] = field(default_factory=IdentityTransform)
    t0: float = 0.0
    tracked: Sequence[int] = ()
    #: optional ``scale(t0, t1) -> float >= 0`` multiplying the random-walk standard
    #: deviation of the step from t0 to t1 (e.g. 0 while nothing can change the parameters)
    param_noise_scale: Callable[[float, float], float] | None = None
    #: optional ``dynamics(U, t0, t1) -> U`` on the transformed parameters (a drift)
    param_dynamics: Callable[[np.ndarray, float, float], np.ndarray] | None = None
    #: optional (n_par, 2) transformed bounds that reflect the random walk
    param_walk_bounds: np.ndarray | None = None
    #: optional covariance localization ``(rho_xy (n_state + n_par, p), rho_yy (p, p))``
    #: for method "enkf" (see :func:`enkf.analysis.enkf_localized`)
    localization: tuple | None = None
    #: optional ``offset(theta) -> (N, p)`` added to the observation (sensor offsets)
    observation_offset: Callable[[np.ndarray], np.ndarray] | None = None
    #: optional ``obs_error(y_mean (p,)) -> (p, p)`` added to obs_cov at each analysis
    obs_error: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self):
        set_ = object.__setattr__  # frozen: store the validated arrays
        if self.obs_error is not None and not callable(self.obs_error):
            raise ValueError(f"obs_error must be callable or None, got "
                             f"{type(self.obs_error).__name__}")
        if self.observation_offset is not None and not callable(self.observation_offset):
            raise ValueError(f"observation_offset must be callable or None, got "
                             f"{type(self.observation_offset).__name__}")
        if not callable(self.forecast):
            raise ValueError(f"forecast must be callable, got {self.forecast!r}")
        if not callable(self.prior):
            raise ValueError(f"prior must be callable, got {self.prior!r}")
        if not (callable(self.observation) or hasattr(self.observation, "shape")):
            raise ValueError(
                "observation must be a (p, n_state) matrix or a callable, "
                f"got {type(self.observation).__name__}"
            )
        t0 = float(self.t0)
        if not np.isfinite(t0):
            raise ValueError(f"t0 must be finite, got {self.t0!r}")
        set_(self, "t0", t0)
        times = float_array(self.obs_times, "obs_times", 1)
        if times.size == 0:
            raise ValueError("obs_times must hold at least one time, got shape (0,)")
        if times[0] <= t0 or np.any(np.diff(times) <= 0):
            raise ValueError(
                f"obs_times must be strictly increasing and after t0 = {t0}, "
                f"got {times[:5]}{'...' if times.size > 5 else ''}"
            )
        set_(self, "obs_times", times)
        data = float_array(self.obs_data, "obs_data", (1, 2), finite=False)
        if data.ndim == 1:
            data = data[:, None]
        if data.shape[0] != times.shape[0]:
            raise ValueError(
                f"obs_data must have one row per obs_times entry ({times.shape[0]}), got shape {data.shape}"
            )
        if np.any(np.isinf(data)):
            raise ValueError("obs_data must be finite or NaN (missing), got an infinite entry")
        set_(self, "obs_data", data)
        p = data.shape[1]
        set_(self, "obs_cov", covariance(self.obs_cov, "obs_cov", p, allow_singular=False))
        if hasattr(self.observation, "shape") and not callable(self.observation):
            if len(self.observation.shape) != 2 or self.observation.shape[0] != p:
                raise ValueError(
                    f"observation must have shape ({p}, n_state) to match "
                    f"obs_data, got {self.observation.shape}"
                )
        if not callable(self.model_noise):
            set_(self, "model_noise", variances(self.model_noise, "model_noise"))
        pn = float_array(self.param_noise, "param_noise", (0, 1, 2))
        if pn.ndim < 2 and np.any(pn < 0):
            raise ValueError(f"param_noise must be non-negative, got min {pn.min()!r}")
        set_(self, "param_noise", pn)
        if self.param_walk_bounds is not None:
            b = float_array(self.param_walk_bounds, "param_walk_bounds", 2, finite=False)
            if b.shape[1] != 2 or np.any(np.isnan(b)) or np.any(b[:, 0] >= b[:, 1]):
                raise ValueError(f"param_walk_bounds must be (n_par, 2) with lo < hi, got "
                                 f"{self.param_walk_bounds!r}")
            set_(self, "param_walk_bounds", b)
        tracked = np.asarray(self.tracked)
        if tracked.size == 0:
            tracked = np.zeros(0, dtype=np.intp)
        if tracked.ndim != 1 or not np.issubdtype(tracked.dtype, np.integer) or np.any(tracked < 0):
            raise ValueError(f"tracked must be a sequence of non-negative ints, got {self.tracked!r}")
        set_(self, "tracked", tracked.astype(np.intp))


#: how :func:`uniform_prior` draws the parameters
PRIOR_SAMPLINGS = ("random", "stratified")


def stratified_uniform(rng: np.random.Generator, N: int, n: int) -> np.ndarray:
    """(N, n) draws of the unit cube, a Latin hypercube: each column holds one draw in each
    of the N equal strata of [0, 1), the columns' strata paired at random (McKay, Beckman
    & Conover 1979). Each draw is uniform on [0, 1), as with ``rng.random``, but no part
    of a parameter's range is left empty or crowded by chance."""
    rank = np.argsort(rng.random((N, n)), axis=0)
    return (rank + rng.random((N, n))) / N


def uniform_prior(
    state_mean: np.ndarray,
    theta_low: np.ndarray,
    theta_high: np.ndarray,
    state_std: float | np.ndarray = 0.0,
    *,
    sampling: str = "random",
) -> Prior:
    """A prior sampler: Gaussian state, independent uniform parameters.

    Arnold & Fichera start from a known temperature and draw each optical
    property uniformly in [0.5, 2] times its nominal value; that is
    ``uniform_prior(T0, 0.5 * theta_nom, 2 * theta_nom)``.

    Parameters
    ----------
    state_mean : ndarray, shape (n_state,)
    theta_low, theta_high : ndarray, shape (n_par,)
        Bounds of the uniform prior, physical units.
    state_std : float or ndarray, shape (n_state,)
        Standard deviation of the Gaussian state prior (0: all members equal).
    sampling : {"random", "stratified"}
        ``"random"``: independent draws. ``"stratified"``: a Latin hypercube
        (:func:`stratified_uniform`), the same prior drawn with less sampling error: with
        50 members a corner of the prior's box holds about as many members as its volume
        asks for, where random draws leave it nearly empty on some seeds.

    Returns
    -------
    callable
        ``prior(rng, N) -> (E_state (N, n_state), theta (N, n_par))``.
    """
    if sampling not in PRIOR_SAMPLINGS:
        raise ValueError(f"sampling must be one of {PRIOR_SAMPLINGS}, got {sampling!r}")
    mean = float_array(state_mean, "state_mean", 1)
    lo = float_array(theta_low, "theta_low", 1)
    hi = float_array(theta_high, "theta_high", 1)
    if lo.shape != hi.shape or np.any(lo > hi):
        raise ValueError(f"theta_low must not exceed theta_high (same shape), got {lo}, {hi}")
    sd = np.sqrt(variances(np.square(state_std), "state_std", mean.shape[0]))

    def prior(rng: np.random.Generator, N: int) -> tuple[np.ndarray, np.ndarray]:
        X = mean + sd * rng.standard_normal((N, mean.shape[0]))
        u = (stratified_uniform(rng, N, lo.shape[0]) if sampling == "stratified"
             else rng.random((N, lo.shape[0])))
        return X, lo + (hi - lo) * u

    return prior


# ---------------------------------------------------------------------------- outputs


@dataclass
class FilterResult:
    """Per-step statistics of a filter run (step 0 is the prior).

    Attributes
    ----------
    times : ndarray, shape (M + 1,)
        ``t0`` followed by ``obs_times`` (s).
    param_mean, param_std : ndarray, shape (M + 1, n_par)
        Ensemble mean and std (``ddof=1``) of each parameter in physical units,
        from the back-transformed ensemble, after the analysis.
    tracked_mean, tracked_std : ndarray, shape (M + 1, n_tracked)
        The same for the tracked state entries.
    analysed : ndarray of bool, shape (M,)
        Whether step ``k + 1`` had data to assimilate.
    step_latency_s : ndarray, shape (M,)
        Wall time of each step: forecast, noise, analysis and back-transform;
        not the statistics, health check or callback (s).
    analysis_latency_s : ndarray, shape (M,)
        The analysis (and inflation) part of it (s).
    state_ensemble : ndarray, shape (N, n_state)
        Last ensemble, state part.
    param_ensemble : ndarray, shape (N, n_par)
        Last ensemble, parameters in physical units.
    inflation : ndarray, shape (M,)
        Factor on the forecast covariance of each step from
        ``FilterConfig.adaptive_inflation`` (1 without it).
    innovation_loglik : ndarray, shape (M,)
        Log-density of each step's data under its forecast
        (:func:`enkf.adaptive.innovation_loglik`; NaN where nothing was analysed):
        the sum over a run compares models on the same data.
    innovation_normalized : ndarray of float32, shape (M, p)
        Each step's innovation over its forecast sd, component by component
        (:func:`enkf.adaptive.normalized_innovation`; NaN where nothing was analysed):
        white when the model is right; :func:`enkf.adaptive.innovation_persistence`
        measures how much it persists from step to step.
    """

    times: np.ndarray
    param_mean: np.ndarray
    param_std: np.ndarray
    tracked_mean: np.ndarray
    tracked_std: np.ndarray
    analysed: np.ndarray
    step_latency_s: np.ndarray
    analysis_latency_s: np.ndarray
    state_ensemble: np.ndarray
    param_ensemble: np.ndarray
    inflation: np.ndarray | None = None
    innovation_loglik: np.ndarray | None = None
    innovation_normalized: np.ndarray | None = None


@dataclass(frozen=True)
class StepReport:
    """What the per-step callback receives (arrays are views: copy to keep)."""

    step: int  #: 0 for the prior, then 1..M
    time: float  #: (s)
    analysed: bool
    latency_s: float  #: wall time of this step (s), 0 for the prior
    param_mean: np.ndarray  #: (n_par,) physical units
    param_std: np.ndarray  #: (n_par,)
    tracked_mean: np.ndarray  #: (n_tracked,)
    tracked_std: np.ndarray  #: (n_tracked,)
    state_ensemble: np.ndarray  #: (N, n_state)
    param_ensemble: np.ndarray  #: (N, n_par) physical units
    #: of an analysed step, ``(X_f (N, n_state), Y_f (N, p), y (p,), R)``: the forecast
    #: state and observations as the analysis saw them (after prior inflation; with
    #: ``mda > 1`` the first forecast), the data, and the observation-error covariance
    #: ((p, p), or (p,) variances); None otherwise
    #: (:func:`enkf.discrepancy.discrepancy_posterior` uses it)
    forecast: tuple | None = None
    #: True for the steps an application replays after replacing the ensemble (e.g. the
    #: tissue filter's restarts from the smoother: each restarted member's re-run from
    #: step 0, so that what a callback integrates follows the members it now holds)
    replayed: bool = False
    #: the filter of a bank that made this step (e.g. ``"still"`` or ``"drifting"`` of
    #: :class:`enkf.tissue.drift.DriftBank`); None for a single filter
    component: str | None = None


class FilterDivergence(RuntimeError):
    """The health check failed at ``step`` (time ``time``) because of ``what``.

    ``result`` is a :class:`FilterResult` with the steps ``0..step`` (the failing
    step included, its statistics possibly NaN) and the failing ensemble.
    """

    def __init__(self, step: int, time: float, what: str, result: FilterResult | None = None):
        super().__init__(f"filter diverged at step {step} (t = {time:g}): {what}")
        self.step = step
        self.time = time
        self.what = what
        self.result = result
