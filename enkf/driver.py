r"""Sequential driver: augmented-state EnKF for joint state and parameter estimation.

This is the filter loop of Arnold & Fichera (section "Parameter Estimation via
Ensemble Kalman Filtering"), written for any model that can advance a batch of
states. Each member is the augmented vector

.. math::

    z^n = \begin{bmatrix} x^n \\ u^n \end{bmatrix}, \qquad
    x^n \in \mathbb{R}^{n_\mathrm{state}}, \quad u^n = g(\theta^n) \in \mathbb{R}^{n_\mathrm{par}},

stored as one row ``[state, parameters]`` of an ``(N, n_state + n_par)`` array,
where :math:`g` is the parameter transform (:mod:`enkf.transforms`). Step
:math:`j \to j+1` (time :math:`t_j \to t_{j+1}`):

1. Prediction (paper: :math:`T^n_{j+1\mid j} = F(T^n_j, \theta^n_j) + v^n_{j+1}`,
   :math:`\theta^n_{j+1\mid j} = \theta^n_j + \xi^n_{j+1}`):

   .. math::

       x^n \leftarrow \mathcal{F}(x^n, g^{-1}(u^n); t_j, t_{j+1}) + v^n, \quad
       v^n \sim \mathcal{N}(0, C), \qquad
       u^n \leftarrow u^n + \xi^n, \quad \xi^n \sim \mathcal{N}(0, E_\mathrm{rw}),

   with :math:`C` diagonal and the random walk applied to the *transformed*
   parameters (for a log transform its standard deviation is a relative step).
2. Analysis, if any datum at :math:`t_{j+1}` is not NaN: the ensemble
   :math:`z` is updated with :math:`Y = G(x)` by :func:`enkf.analysis.enkf_perturbed_obs`
   (default, as in the paper) or :func:`enkf.analysis.etkf`, then inflated
   (multiplicative, on the whole augmented state) if ``inflation != 1``.
3. Statistics: mean and standard deviation (``ddof=1``) of every physical
   parameter :math:`\theta = g^{-1}(u)` and of the tracked state entries;
   wall time of the step.
4. Health check (non-finite values always; spread and bounds if asked); a failed
   check raises :class:`FilterDivergence` carrying the result so far.
"""

from __future__ import annotations

import numbers
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ._validate import as_generator, cov_sqrt, covariance, float_array, variances
from .analysis import METHODS, analysis, enkf_localized, inflate, random_rotation
from .transforms import IdentityTransform, Transform, as_transforms, to_filter_space, to_physical

__all__ = [
    "FilterConfig",
    "FilterDivergence",
    "FilterProblem",
    "FilterResult",
    "HealthCheck",
    "StepReport",
    "run_filter",
    "uniform_prior",
]

#: ``forecast(E_state (N, n_state), theta (N, n_par) physical, t0, t1) -> E_state (N, n_state)``
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
    method : {"enkf", "etkf"}
        ``"enkf"``: stochastic EnKF with perturbed observations, the paper's
        analysis. ``"etkf"``: deterministic symmetric square-root ETKF.
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
        orthogonal matrix (:func:`enkf.analysis.random_rotation`; DAPPER's
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
    """

    n_members: int = 50
    method: str = "enkf"
    inflation: float = 1.0
    center_perturbations: bool = True
    seed: int = 0
    rotate: bool = False
    mda: int = 1

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
    model_noise : float or ndarray, shape (n_state,)
        Diagonal of :math:`C`: variances of the additive state noise, per filter
        step, in state units squared. Zero entries get no noise.
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
    localization : (rho_xy, rho_yy), optional
        Schur-product tapers for :func:`enkf.analysis.enkf_localized`, rows of
        ``rho_xy`` over the augmented state (the state, then the parameters). Only
        with ``method="enkf"``.
    """

    forecast: Forecast
    observation: object
    obs_times: np.ndarray
    obs_data: np.ndarray
    obs_cov: np.ndarray
    prior: Prior
    model_noise: float | np.ndarray = 0.0
    param_noise: float | np.ndarray = 0.0
    transforms: Transform | Sequence[Transform] = field(default_factory=IdentityTransform)
    t0: float = 0.0
    tracked: Sequence[int] = ()
    #: optional ``scale(t0, t1) -> float >= 0`` multiplying the random-walk standard
    #: deviation of the step from t0 to t1 (e.g. 0 while nothing can change the parameters)
    param_noise_scale: Callable[[float, float], float] | None = None
    #: optional ``dynamics(U, t0, t1) -> U`` on the transformed parameters (a drift)
    param_dynamics: Callable[[np.ndarray, float, float], np.ndarray] | None = None
    #: optional covariance localization ``(rho_xy (n_state + n_par, p), rho_yy (p, p))``
    #: for method "enkf" (see :func:`enkf.analysis.enkf_localized`)
    localization: tuple | None = None

    def __post_init__(self):
        set_ = object.__setattr__  # frozen: store the validated arrays
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
        set_(self, "model_noise", variances(self.model_noise, "model_noise"))
        pn = float_array(self.param_noise, "param_noise", (0, 1, 2))
        if pn.ndim < 2 and np.any(pn < 0):
            raise ValueError(f"param_noise must be non-negative, got min {pn.min()!r}")
        set_(self, "param_noise", pn)
        tracked = np.asarray(self.tracked)
        if tracked.size == 0:
            tracked = np.zeros(0, dtype=np.intp)
        if tracked.ndim != 1 or not np.issubdtype(tracked.dtype, np.integer) or np.any(tracked < 0):
            raise ValueError(f"tracked must be a sequence of non-negative ints, got {self.tracked!r}")
        set_(self, "tracked", tracked.astype(np.intp))


@dataclass(frozen=True)
class HealthCheck:
    """The default health check, called after every step with ``(E_state, theta)``.

    Non-finite values anywhere in the ensemble always fail. Optional checks:

    Parameters
    ----------
    param_bounds : ndarray, shape (n_par, 2), optional
        ``[lo, hi]`` per parameter in physical units; fails when an ensemble
        *mean* leaves the interval (single members may wander; the mean is the
        estimate). Use ``-inf``/``inf`` for an open side.
    min_param_std : float or ndarray, shape (n_par,), optional
        Fails when a parameter's ensemble std (physical units) falls below it:
        a collapsed ensemble no longer learns from data.

    Any callable ``health(E_state, theta) -> str | None`` can replace this class in
    :func:`run_filter`; a returned string describes the failure.
    """

    param_bounds: np.ndarray | None = None
    min_param_std: float | np.ndarray | None = None

    def __post_init__(self):
        if self.param_bounds is not None:
            b = float_array(self.param_bounds, "param_bounds", 2, finite=False)
            if b.shape[1] != 2 or np.any(np.isnan(b)) or np.any(b[:, 0] >= b[:, 1]):
                raise ValueError(f"param_bounds must be (n_par, 2) with lo < hi, got {b!r}")
            object.__setattr__(self, "param_bounds", b)
        if self.min_param_std is not None:
            object.__setattr__(self, "min_param_std", variances(self.min_param_std, "min_param_std"))

    def __call__(self, E_state: np.ndarray, theta: np.ndarray) -> str | None:
        for name, X in (("state", E_state), ("parameter", theta)):
            bad = ~np.isfinite(X)
            if bad.any():
                cols = np.flatnonzero(bad.any(axis=0))
                return (
                    f"non-finite {name} values in {bad.any(axis=1).sum()} member(s), "
                    f"{name} columns {cols[:10].tolist()}{'...' if cols.size > 10 else ''}"
                )
        if self.param_bounds is not None:
            if self.param_bounds.shape[0] != theta.shape[1]:
                raise ValueError(
                    f"param_bounds must have {theta.shape[1]} rows, got {self.param_bounds.shape[0]}"
                )
            m = theta.mean(axis=0)
            out = (m < self.param_bounds[:, 0]) | (m > self.param_bounds[:, 1])
            if out.any():
                i = int(np.flatnonzero(out)[0])
                return (
                    f"parameter {i} mean {m[i]:.6g} outside bounds "
                    f"[{self.param_bounds[i, 0]:.6g}, {self.param_bounds[i, 1]:.6g}]"
                )
        if self.min_param_std is not None and theta.shape[1]:
            s = theta.std(axis=0, ddof=1)
            low = s < np.broadcast_to(self.min_param_std, s.shape)
            if low.any():
                i = int(np.flatnonzero(low)[0])
                return (
                    f"parameter {i} spread collapsed: std {s[i]:.3g} < "
                    f"{np.broadcast_to(self.min_param_std, s.shape)[i]:.3g}"
                )
        return None


def uniform_prior(
    state_mean: np.ndarray,
    theta_low: np.ndarray,
    theta_high: np.ndarray,
    state_std: float | np.ndarray = 0.0,
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

    Returns
    -------
    callable
        ``prior(rng, N) -> (E_state (N, n_state), theta (N, n_par))``.
    """
    mean = float_array(state_mean, "state_mean", 1)
    lo = float_array(theta_low, "theta_low", 1)
    hi = float_array(theta_high, "theta_high", 1)
    if lo.shape != hi.shape or np.any(lo > hi):
        raise ValueError(f"theta_low must not exceed theta_high (same shape), got {lo}, {hi}")
    sd = np.sqrt(variances(np.square(state_std), "state_std", mean.shape[0]))

    def prior(rng: np.random.Generator, N: int) -> tuple[np.ndarray, np.ndarray]:
        X = mean + sd * rng.standard_normal((N, mean.shape[0]))
        return X, lo + (hi - lo) * rng.random((N, lo.shape[0]))

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


# ------------------------------------------------------------------------------- loop


def _observe(observation, X: np.ndarray) -> np.ndarray:
    if callable(observation):
        return np.asarray(observation(X), dtype=float)
    return np.asarray((observation @ X.T).T, dtype=float)


def _stats(X: np.ndarray, ddof: int = 1) -> tuple[np.ndarray, np.ndarray]:
    with np.errstate(invalid="ignore", over="ignore"):
        return X.mean(axis=0), X.std(axis=0, ddof=ddof)


def run_filter(
    problem: FilterProblem,
    config: FilterConfig | None = None,
    *,
    health: Callable[[np.ndarray, np.ndarray], str | None] | None = None,
    callback: Callable[[StepReport], None] | None = None,
) -> FilterResult:
    """Run the augmented-state ensemble Kalman filter over all observation times.

    Parameters
    ----------
    problem : FilterProblem
        Model, data, noise, prior, transforms, tracked entries.
    config : FilterConfig, optional
        Ensemble size, analysis method, inflation, seed (defaults: N = 50,
        perturbed observations, no inflation, seed 0).
    health : callable, optional
        ``health(E_state, theta) -> str | None`` called after the prior draw and
        after every step; default :class:`HealthCheck()` (non-finite values only).
    callback : callable, optional
        Called with a :class:`StepReport` after the prior draw and every step
        (progress bars, streaming to a plot or a socket).

    Returns
    -------
    FilterResult

    Raises
    ------
    FilterDivergence
        When ``health`` reports a problem; carries the result so far.
    ValueError
        When the prior, the forecast or the observation operator return arrays
        of the wrong shape, or sizes disagree with the problem's noise settings.
    """
    config = FilterConfig() if config is None else config
    health = HealthCheck() if health is None else health
    rng = as_generator(config.seed, "seed")
    N = config.n_members
    P = problem
    M, p = P.obs_data.shape

    X, theta = P.prior(rng, N)
    X = float_array(X, "prior state", 2, finite=False)
    theta = np.zeros((N, 0)) if theta is None else float_array(theta, "prior theta", 2, finite=False)
    if X.shape[0] != N or theta.shape[0] != N:
        raise ValueError(f"prior must return {N} rows (n_members), got state {X.shape}, theta {theta.shape}")
    n_state, n_par = X.shape[1], theta.shape[1]
    transforms = as_transforms(P.transforms, n_par)
    U = to_filter_space(transforms, theta)
    sd_model = np.sqrt(variances(P.model_noise, "model_noise", n_state))
    noisy = np.flatnonzero(sd_model)  # draw only where there is noise
    rw = covariance(P.param_noise, "param_noise", n_par)
    rw_root = cov_sqrt(rw)
    rw_on = bool(n_par) and np.any(rw != 0)
    if not callable(P.observation) and P.observation.shape[1] != n_state:
        raise ValueError(
            f"observation must have shape ({p}, {n_state}) (n_state from the "
            f"prior), got {P.observation.shape}"
        )
    if P.localization is not None:
        if config.method != "enkf" or config.mda != 1:
            raise ValueError(f"localization needs method='enkf' and mda=1, got method="
                             f"{config.method!r}, mda={config.mda}")
        rxy, ryy = (np.asarray(r) for r in P.localization)
        if rxy.shape != (n_state + n_par, p) or ryy.shape != (p, p):
            raise ValueError(f"localization must be (rho_xy ({n_state + n_par}, {p}), rho_yy "
                             f"({p}, {p})), got {rxy.shape} and {ryy.shape}")
    tracked = P.tracked
    if tracked.size and tracked.max() >= n_state:
        raise ValueError(f"tracked indices must be < n_state = {n_state}, got max {tracked.max()}")

    times = np.concatenate([[P.t0], P.obs_times])
    param_mean = np.full((M + 1, n_par), np.nan)
    param_std = np.full((M + 1, n_par), np.nan)
    tr_mean = np.full((M + 1, tracked.size), np.nan)
    tr_std = np.full((M + 1, tracked.size), np.nan)
    analysed = np.zeros(M, dtype=bool)
    latency = np.full(M, np.nan)
    ana_latency = np.zeros(M)

    def result(k: int) -> FilterResult:
        return FilterResult(
            times[: k + 1].copy(),
            param_mean[: k + 1].copy(),
            param_std[: k + 1].copy(),
            tr_mean[: k + 1].copy(),
            tr_std[: k + 1].copy(),
            analysed[:k].copy(),
            latency[:k].copy(),
            ana_latency[:k].copy(),
            X,
            theta,
        )

    def record(k: int, step_s: float) -> None:
        param_mean[k], param_std[k] = _stats(theta)
        tr_mean[k], tr_std[k] = _stats(X[:, tracked])
        what = health(X, theta)
        if what:
            raise FilterDivergence(k, float(times[k]), what, result(k))
        if callback is not None:
            callback(
                StepReport(
                    k,
                    float(times[k]),
                    bool(analysed[k - 1]) if k else False,
                    step_s,
                    param_mean[k],
                    param_std[k],
                    tr_mean[k],
                    tr_std[k],
                    X,
                    theta,
                )
            )

    def advance(X0, U0, theta0, t_a, t_b, v, dU):
        """Members from t_a to t_b: forecast, model noise, parameter dynamics and walk."""
        X1 = np.asarray(P.forecast(X0, theta0, t_a, t_b), dtype=float)
        if X1.shape != (N, n_state):
            raise ValueError(f"forecast must return shape ({N}, {n_state}), got {X1.shape}")
        if v is not None:
            X1 = X1.copy()  # the forecast may hand back a view of its own buffers
            X1[:, noisy] += v
        U1 = U0
        if P.param_dynamics is not None:
            U1 = np.asarray(P.param_dynamics(U0, t_a, t_b), dtype=float)
            if U1.shape != (N, n_par):
                raise ValueError(f"param_dynamics must return shape ({N}, {n_par}), "
                                 f"got {U1.shape}")
        if dU is not None:
            U1 = U1 + dU
        return X1, U1

    def checked_observe(Xf, Uf, k, tic):
        Y = _observe(P.observation, Xf)
        if Y.shape != (N, p):
            raise ValueError(f"observation must map the ensemble to shape ({N}, {p}), got {Y.shape}")
        if not (np.all(np.isfinite(Xf)) and np.all(np.isfinite(Uf)) and np.all(np.isfinite(Y))):
            nonlocal theta
            theta = to_physical(transforms, Uf)
            latency[k - 1] = time.perf_counter() - tic
            record(k, latency[k - 1])  # the health check names what went wrong
            raise FilterDivergence(k, float(times[k]), "non-finite forecast", result(k))
        return Y

    def spread_out(Z):
        """Inflation and rotation of an analysed augmented ensemble; (X, U) back."""
        if config.inflation != 1.0:
            Z = inflate(Z, config.inflation)
        if config.rotate:
            Z = random_rotation(Z, rng)
        return Z[:, :n_state], Z[:, n_state:]

    record(0, 0.0)
    for k in range(1, M + 1):
        tic = time.perf_counter()
        t_a, t_b = float(times[k - 1]), float(times[k])
        # this step's noises, drawn once (they belong to the step, not to an iteration)
        v = sd_model[noisy] * rng.standard_normal((N, noisy.size)) if noisy.size else None
        dU = None
        if rw_on:
            xi = rng.standard_normal((N, n_par))
            if P.param_noise_scale is not None:
                scale = float(P.param_noise_scale(t_a, t_b))
                if not (np.isfinite(scale) and scale >= 0):
                    raise ValueError(f"param_noise_scale must return a number >= 0, got {scale!r}")
                xi *= scale
            dU = xi * rw_root if rw_root.ndim == 1 else xi @ rw_root.T

        y = P.obs_data[k - 1]
        observed = not np.all(np.isnan(y))
        if observed and config.mda > 1:
            # one-step ensemble smoother with multiple data assimilation (Emerick & Reynolds
            # 2013): update the members' start (state, parameters and this step's noises)
            # config.mda times with the error variance times mda, re-running the step from
            # the updated start each time; for a linear model the result has the moments of
            # one analysis, for a nonlinear one each update is a small, nearly linear move
            tic_a = time.perf_counter()
            # the step's noises are unknowns of the step too: they are updated with the start
            V = v if v is not None else np.zeros((N, 0))
            D = dU if dU is not None else np.zeros((N, 0))
            cuts = np.cumsum([n_state, n_par, V.shape[1]])
            X0, U0 = X, U
            for _ in range(config.mda):
                Xf, Uf = advance(X0, U0, to_physical(transforms, U0), t_a, t_b,
                                 V if v is not None else None, D if dU is not None else None)
                Y = checked_observe(Xf, Uf, k, tic)
                Z = analysis(np.concatenate([X0, U0, V, D], axis=1), Y, y, config.mda * P.obs_cov,
                             config.method, rng, center=config.center_perturbations)
                X0, U0, V, D = np.split(Z, cuts, axis=1)
            v = V if v is not None else None
            dU = D if dU is not None else None
            with np.errstate(over="ignore"):
                X, U = advance(X0, U0, to_physical(transforms, U0), t_a, t_b, v, dU)
            X, U = spread_out(np.concatenate([X, U], axis=1))
            analysed[k - 1] = True
            ana_latency[k - 1] = time.perf_counter() - tic_a
        else:
            X, U = advance(X, U, theta, t_a, t_b, v, dU)
            if observed:
                tic_a = time.perf_counter()
                Y = checked_observe(X, U, k, tic)
                Z = np.concatenate([X, U], axis=1)  # augmented state z = [x; u], paper eq. (z)
                if P.localization is not None:
                    Z = enkf_localized(Z, Y, y, P.obs_cov, *P.localization, rng,
                                       center=config.center_perturbations)
                else:
                    Z = analysis(Z, Y, y, P.obs_cov, config.method, rng,
                                 center=config.center_perturbations)
                X, U = spread_out(Z)
                analysed[k - 1] = True
                ana_latency[k - 1] = time.perf_counter() - tic_a
        with np.errstate(over="ignore"):
            theta = to_physical(transforms, U)
        latency[k - 1] = time.perf_counter() - tic
        record(k, latency[k - 1])
    return result(M)
