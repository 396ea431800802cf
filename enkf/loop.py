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
   :math:`z` is updated with :math:`Y = G(x)` by :func:`enkf.analysis.etkf`
   (:data:`enkf.problem.DEFAULT_METHOD`) or :func:`enkf.analysis.enkf_perturbed_obs`
   (the paper's analysis), then inflated
   (multiplicative, on the whole augmented state) if ``inflation != 1``.
3. Statistics: mean and standard deviation (``ddof=1``) of every physical
   parameter :math:`\theta = g^{-1}(u)` and of the tracked state entries;
   wall time of the step.
4. Health check (non-finite values always; spread and bounds if asked); a failed
   check raises :class:`FilterDivergence` carrying the result so far.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .adaptive import InflationEstimator, innovation_loglik, normalized_innovation
from .analysis import analysis, enkf_localized
from .checks import as_generator, cov_sqrt, covariance, float_array, rows_times, variances
from .health import HealthCheck
from .problem import FilterConfig, FilterDivergence, FilterProblem, FilterResult, StepReport
from .random import PendingNormals, standard_normal, standard_normal_later
from .spread import inflate, random_rotation, relax_to_prior_spread
from .transforms import as_transforms, to_filter_space, to_physical

__all__ = ["run_filter"]

Health = Callable[[np.ndarray, np.ndarray], "str | None"]


def _stats(X: np.ndarray, ddof: int = 1) -> tuple[np.ndarray, np.ndarray]:
    with np.errstate(invalid="ignore", over="ignore"):
        return X.mean(axis=0), X.std(axis=0, ddof=ddof)


def reflect(U: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """``U`` (N, n_par) with each column folded into ``[bounds[i, 0], bounds[i, 1]]`` by
    reflection at the ends (a walk that crosses a bound comes back by as much; a column
    with an open end, -inf or inf, is reflected once at its finite end); ``U`` itself
    where every member is inside."""
    lo, hi = bounds[:, 0], bounds[:, 1]
    if np.all((U >= lo) & (U <= hi)):
        return U
    U = U.copy()
    closed = np.isfinite(lo) & np.isfinite(hi)
    if closed.any():
        a, w = lo[closed], hi[closed] - lo[closed]
        y = np.mod(U[:, closed] - a, 2.0 * w)
        U[:, closed] = a + np.where(y > w, 2.0 * w - y, y)
    for i in np.flatnonzero(~closed):
        u = U[:, i]
        if np.isfinite(lo[i]):
            u = np.where(u < lo[i], 2.0 * lo[i] - u, u)
        if np.isfinite(hi[i]):
            u = np.where(u > hi[i], 2.0 * hi[i] - u, u)
        U[:, i] = u
    return U


class _Record:
    """Per-step statistics of a run, filled step by step (step 0 is the prior)."""

    def __init__(self, times: np.ndarray, n_par: int, n_tracked: int, n_obs: int):
        M = times.size - 1
        self.times = times
        self.param_mean = np.full((M + 1, n_par), np.nan)
        self.param_std = np.full((M + 1, n_par), np.nan)
        self.tracked_mean = np.full((M + 1, n_tracked), np.nan)
        self.tracked_std = np.full((M + 1, n_tracked), np.nan)
        self.analysed = np.zeros(M, dtype=bool)
        self.latency = np.full(M, np.nan)
        self.analysis_latency = np.zeros(M)
        self.inflation = np.ones(M)
        self.loglik = np.full(M, np.nan)
        # single precision: a correlation needs no more, and a long run of a large camera
        # keeps M x p of them
        self.innovation = np.full((M, n_obs), np.nan, dtype=np.float32)

    def result(self, k: int, X: np.ndarray, theta: np.ndarray) -> FilterResult:
        """Steps ``0..k`` with the ensemble ``(X, theta)``."""
        return FilterResult(
            self.times[: k + 1].copy(), self.param_mean[: k + 1].copy(),
            self.param_std[: k + 1].copy(), self.tracked_mean[: k + 1].copy(),
            self.tracked_std[: k + 1].copy(), self.analysed[:k].copy(),
            self.latency[:k].copy(), self.analysis_latency[:k].copy(), X, theta,
            self.inflation[:k].copy(), self.loglik[:k].copy(), self.innovation[:k].copy())


class _Filter:
    """One run of the augmented filter: the ensemble and the steps that move it."""

    def __init__(self, problem: FilterProblem, config: FilterConfig, health: Health,
                 callback: Callable[[StepReport], None] | None,
                 inflation_state: InflationEstimator | None = None):
        self.P, self.config, self.health, self.callback = problem, config, health, callback
        self.rng = as_generator(config.seed, "seed")
        self.N = N = config.n_members
        self.p = problem.obs_data.shape[1]
        X, theta = problem.prior(self.rng, N)
        X = float_array(X, "prior state", 2, finite=False)
        theta = np.zeros((N, 0)) if theta is None else float_array(theta, "prior theta", 2,
                                                                   finite=False)
        if X.shape[0] != N or theta.shape[0] != N:
            raise ValueError(f"prior must return {N} rows (n_members), got state {X.shape}, "
                             f"theta {theta.shape}")
        self.X, self.theta = X, theta
        self.n_state, self.n_par = X.shape[1], theta.shape[1]
        self.transforms = as_transforms(problem.transforms, self.n_par)
        self.U = to_filter_space(self.transforms, theta)
        # a structured model error is drawn after the forecast (it may depend on it)
        self.noise_fn = problem.model_noise if callable(problem.model_noise) else None
        if self.noise_fn is None:
            sd_model = np.sqrt(variances(problem.model_noise, "model_noise", self.n_state))
            self.noisy = np.flatnonzero(sd_model)  # draw only where there is noise
            self.sd_noisy = sd_model[self.noisy]
        else:
            self.noisy, self.sd_noisy = np.arange(self.n_state), None
        # noise on every state variable (the usual case): a plain add, no gather and scatter
        self.noisy_all = self.noisy.size == self.n_state
        ai = config.adaptive_inflation
        self.adaptive = None if ai is None else (
            inflation_state if inflation_state is not None else InflationEstimator(ai))
        rw = covariance(problem.param_noise, "param_noise", self.n_par)
        self.rw_root = cov_sqrt(rw)
        self.rw_on = bool(self.n_par) and bool(np.any(rw != 0))
        self.walk_bounds = problem.param_walk_bounds
        self._check_sizes()
        # the next step's model noise can be drawn during this step's analysis when
        # nothing between the two draws takes numbers from the generator
        self._draw_ahead = (self.noise_fn is None and bool(self.noisy.size)
                            and config.method == "etkf" and config.mda == 1 and not config.rotate
                            and problem.localization is None)
        self._ahead: dict = {}
        self.seen = None  #: the analysed forecast of the current step (StepReport.forecast)
        self.rec = _Record(np.concatenate([[problem.t0], problem.obs_times]), self.n_par,
                           problem.tracked.size, self.p)

    def _check_sizes(self) -> None:
        P, n_state, p = self.P, self.n_state, self.p
        if not callable(P.observation) and P.observation.shape[1] != n_state:
            raise ValueError(f"observation must have shape ({p}, {n_state}) (n_state from the "
                             f"prior), got {P.observation.shape}")
        if P.localization is not None:
            if self.config.method != "enkf" or self.config.mda != 1:
                raise ValueError(f"localization needs method='enkf' and mda=1, got method="
                                 f"{self.config.method!r}, mda={self.config.mda}")
            rxy, ryy = (np.asarray(r) for r in P.localization)
            n = n_state + self.n_par
            if rxy.shape != (n, p) or ryy.shape != (p, p):
                raise ValueError(f"localization must be (rho_xy ({n}, {p}), rho_yy ({p}, {p})), "
                                 f"got {rxy.shape} and {ryy.shape}")
        if P.param_walk_bounds is not None and P.param_walk_bounds.shape != (self.n_par, 2):
            raise ValueError(f"param_walk_bounds must have shape ({self.n_par}, 2), got "
                             f"{P.param_walk_bounds.shape}")
        tracked = P.tracked
        if tracked.size and tracked.max() >= n_state:
            raise ValueError(f"tracked indices must be < n_state = {n_state}, got max "
                             f"{tracked.max()}")

    # ------------------------------------------------------------------ pieces of a step

    def noises(self, t_a: float, t_b: float, later: bool = False):
        """This step's model noise ``v`` (N, n_noisy) and parameter walk ``dU`` (N, n_par),
        drawn once: they belong to the step, not to an iteration of it. With ``later``,
        ``v`` is drawn on the worker thread (a :class:`~enkf.random.PendingNormals` that
        ``advance`` waits for); the numbers are the same."""
        N, rng = self.N, self.rng
        v = None
        if self.noise_fn is None and self.noisy.size:
            if later:
                v = standard_normal_later(rng, (N, self.noisy.size), self.sd_noisy)
            else:
                v = standard_normal(rng, (N, self.noisy.size))
                v *= self.sd_noisy  # in place: the same numbers, one (N, n) temporary fewer
        if not self.rw_on:
            return v, None
        xi = rng.standard_normal((N, self.n_par))
        if self.P.param_noise_scale is not None:
            scale = float(self.P.param_noise_scale(t_a, t_b))
            if not (np.isfinite(scale) and scale >= 0):
                raise ValueError(f"param_noise_scale must return a number >= 0, got {scale!r}")
            xi *= scale
        root = self.rw_root
        return v, (xi * root if root.ndim == 1 else xi @ root.T)

    def physical(self, U: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore"):
            return to_physical(self.transforms, U)

    def advance(self, X0, U0, theta0, t_a, t_b, v, dU):
        """Members from t_a to t_b: forecast, model noise, parameter dynamics and walk.

        Returns ``(X1, U1, v)``: ``v`` is the model noise added (drawn here from a
        structured model error when ``v`` is None and the problem has one)."""
        N, n_state, n_par, P = self.N, self.n_state, self.n_par, self.P
        X1 = np.asarray(P.forecast(X0, theta0, t_a, t_b), dtype=float)
        if X1.shape != (N, n_state):
            raise ValueError(f"forecast must return shape ({N}, {n_state}), got {X1.shape}")
        if isinstance(v, PendingNormals):
            v = v.result()
        if v is None and self.noise_fn is not None:
            v = np.asarray(self.noise_fn(self.rng, X0, X1, theta0, t_a, t_b), dtype=float)
            if v.shape != (N, n_state):
                raise ValueError(f"model_noise must return shape ({N}, {n_state}), got {v.shape}")
        if v is not None:
            if self.noisy_all:  # a new array: the forecast may hand back its own buffers
                X1 = X1 + v
            else:
                X1 = X1.copy()
                X1[:, self.noisy] += v
        U1 = U0
        if P.param_dynamics is not None:
            U1 = np.asarray(P.param_dynamics(U0, t_a, t_b), dtype=float)
            if U1.shape != (N, n_par):
                raise ValueError(f"param_dynamics must return shape ({N}, {n_par}), "
                                 f"got {U1.shape}")
        if dU is not None:
            U1 = U1 + dU
            if self.walk_bounds is not None:
                U1 = reflect(U1, self.walk_bounds)
        return X1, U1, v

    def observe(self, Xf, Uf, k: int, tic: float) -> np.ndarray:
        """The forecast in observation space; a non-finite forecast stops the run."""
        obs = self.P.observation
        Y = np.asarray(obs(Xf) if callable(obs) else rows_times(obs, Xf), dtype=float)
        if Y.shape != (self.N, self.p):
            raise ValueError(f"observation must map the ensemble to shape ({self.N}, {self.p}), "
                             f"got {Y.shape}")
        if self.P.observation_offset is not None:
            off = np.asarray(self.P.observation_offset(self.physical(Uf)), dtype=float)
            if off.shape != (self.N, self.p):
                raise ValueError(f"observation_offset must return shape ({self.N}, {self.p}), "
                                 f"got {off.shape}")
            Y = Y + off
        if not (np.all(np.isfinite(Xf)) and np.all(np.isfinite(Uf)) and np.all(np.isfinite(Y))):
            self.X, self.theta = Xf, to_physical(self.transforms, Uf)
            self.rec.latency[k - 1] = time.perf_counter() - tic
            self.record(k)  # the health check names what went wrong
            raise FilterDivergence(k, float(self.rec.times[k]), "non-finite forecast",
                                   self.rec.result(k, self.X, self.theta))
        return Y

    def obs_cov_for(self, Y: np.ndarray) -> np.ndarray:
        """The observation-error covariance of this step: ``obs_cov``, plus
        ``obs_error`` of the forecast's mean observation when the problem has one."""
        if self.P.obs_error is None:
            return self.P.obs_cov
        ym = Y.mean(axis=0)
        extra = np.asarray(self.P.obs_error(ym), dtype=float)
        if extra.shape != (self.p, self.p) or not np.all(np.isfinite(extra)):
            raise ValueError(f"obs_error must return a finite ({self.p}, {self.p}) covariance, "
                             f"got shape {extra.shape}")
        R = self.P.obs_cov
        return (np.diag(R) if R.ndim == 1 else R) + extra

    def adapt(self, k: int, Y: np.ndarray, y: np.ndarray, R: np.ndarray) -> float:
        """Update the adaptive inflation with this step's forecast innovations; the
        factor on the covariance (1 without adaptive inflation)."""
        if self.adaptive is None:
            return 1.0
        rho = self.adaptive.update(Y, y, R)
        self.rec.inflation[k - 1] = rho
        return rho

    def evidence(self, k: int, Y: np.ndarray, y: np.ndarray, rho: float, R: np.ndarray) -> None:
        """Record the log-density of this step's data under the forecast the analysis uses
        (with the adaptive factor ``rho``, error covariance ``R``): summed, the model's log
        evidence; and its normalized innovation (before the factor: what the raw forecast
        missed)."""
        self.rec.loglik[k - 1] = innovation_loglik(Y, y, R, rho)
        self.rec.innovation[k - 1] = normalized_innovation(Y, y, R)

    def inflate_by(self, Z: np.ndarray, rho: float) -> np.ndarray:
        """Anomalies of the augmented ensemble times sqrt(rho): the state part, or all."""
        if rho == 1.0:
            return Z
        if self.config.adaptive_inflation.target == "all":
            return inflate(Z, np.sqrt(rho))
        Z = Z.copy()
        Z[:, :self.n_state] = inflate(Z[:, :self.n_state], np.sqrt(rho))
        return Z

    def spread_out(self, Z: np.ndarray, rho: float = 1.0,
                   forecast: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Relaxation to the ``forecast``'s spread (the state part, ``config.rtps``),
        inflation and rotation of an analysed augmented ensemble; (X, U) back."""
        if self.config.rtps > 0 and forecast is not None:
            # Z is the analysis's own new array (or a concatenation): written in place
            Z[:, :self.n_state] = relax_to_prior_spread(forecast, Z[:, :self.n_state],
                                                        self.config.rtps)
        Z = self.inflate_by(Z, rho)
        if self.config.inflation != 1.0:
            Z = inflate(Z, self.config.inflation)
        if self.config.rotate:
            Z = random_rotation(Z, self.rng)
        return Z[:, :self.n_state], Z[:, self.n_state:]

    def analyse(self, Z, Y, y, obs_cov):
        """One analysis of the augmented ensemble ``Z`` (paper: z = [x; u])."""
        c = self.config
        if self.P.localization is not None:
            return enkf_localized(Z, Y, y, obs_cov, *self.P.localization, self.rng,
                                  center=c.center_perturbations)
        return analysis(Z, Y, y, obs_cov, c.method, self.rng, center=c.center_perturbations)

    def step_mda(self, k, t_a, t_b, v, dU, y, tic):
        """One-step ES-MDA (Emerick & Reynolds 2013): update the members' start (state,
        parameters and this step's noises) ``mda`` times with the error variance times
        ``mda``, re-running the step from the updated start each time. For a linear model
        the result has the moments of one analysis; for a nonlinear one each update is a
        small, nearly linear move."""
        mda = self.config.mda
        X0, U0 = self.X, self.U
        # a structured model error is drawn with the first forecast, then belongs to the step
        Xf, Uf, v = self.advance(X0, U0, self.physical(U0), t_a, t_b, v, dU)
        X_forecast = Xf
        Y = self.observe(Xf, Uf, k, tic)
        R = self.obs_cov_for(Y)
        rho = self.adapt(k, Y, y, R)
        self.evidence(k, Y, y, rho, R)
        self.seen = (Xf, Y, y, R)
        V = v if v is not None else np.zeros((self.N, 0))
        D = dU if dU is not None else np.zeros((self.N, 0))
        cuts = np.cumsum([self.n_state, self.n_par, V.shape[1]])
        for i in range(mda):
            if i:
                Xf, Uf, _ = self.advance(X0, U0, self.physical(U0), t_a, t_b,
                                         V if v is not None else None, D if dU is not None else None)
            Y = self.observe(Xf, Uf, k, tic)
            Z = self.analyse(np.concatenate([X0, U0, V, D], axis=1), Y, y, mda * R)
            X0, U0, V, D = np.split(Z, cuts, axis=1)
        X, U, _ = self.advance(X0, U0, self.physical(U0), t_a, t_b, V if v is not None else None,
                               D if dU is not None else None)
        # with ES-MDA the estimated factor widens the analysis (posterior inflation)
        return self.spread_out(np.concatenate([X, U], axis=1), rho, X_forecast)

    def step(self, k: int) -> None:
        """Step ``k - 1 -> k``: noises, forecast, analysis (if any datum), statistics."""
        tic = time.perf_counter()
        times = self.rec.times
        t_a, t_b = float(times[k - 1]), float(times[k])
        v, dU = self._ahead.pop(k) if k in self._ahead else self.noises(t_a, t_b)
        y = self.P.obs_data[k - 1]
        observed = not np.all(np.isnan(y))
        self.seen = None
        if observed and self.config.mda > 1:
            tic_a = time.perf_counter()
            self.X, self.U = self.step_mda(k, t_a, t_b, v, dU, y, tic)
        else:
            self.X, self.U, _ = self.advance(self.X, self.U, self.theta, t_a, t_b, v, dU)
            if self._draw_ahead and k < times.size - 1:
                # the next step's noises, drawn on the worker during this analysis: the
                # generator moves as it would at the next step (the analysis draws nothing)
                self._ahead[k + 1] = self.noises(t_b, float(times[k + 1]), later=True)
            if observed:
                tic_a = time.perf_counter()
                Y = self.observe(self.X, self.U, k, tic)
                Z = np.concatenate([self.X, self.U], axis=1)
                R = self.obs_cov_for(Y)
                rho = self.adapt(k, Y, y, R)
                self.evidence(k, Y, y, rho, R)
                if rho != 1.0:  # prior inflation: widen the forecast, observe it again
                    Z = self.inflate_by(Z, rho)
                    Y = self.observe(Z[:, :self.n_state], Z[:, self.n_state:], k, tic)
                self.seen = (Z[:, :self.n_state], Y, y, R)
                self.X, self.U = self.spread_out(self.analyse(Z, Y, y, R),
                                                 forecast=Z[:, :self.n_state])
        if observed:
            self.rec.analysed[k - 1] = True
            self.rec.analysis_latency[k - 1] = time.perf_counter() - tic_a
        self.theta = self.physical(self.U)
        self.rec.latency[k - 1] = time.perf_counter() - tic
        self.record(k)

    def record(self, k: int) -> None:
        """Statistics of step ``k``, the health check, then the callback."""
        r, X, theta = self.rec, self.X, self.theta
        r.param_mean[k], r.param_std[k] = _stats(theta)
        r.tracked_mean[k], r.tracked_std[k] = _stats(X[:, self.P.tracked])
        what = self.health(X, theta)
        if what:
            raise FilterDivergence(k, float(r.times[k]), what, r.result(k, X, theta))
        if self.callback is not None:
            self.callback(StepReport(
                k, float(r.times[k]), bool(r.analysed[k - 1]) if k else False,
                float(r.latency[k - 1]) if k else 0.0, r.param_mean[k], r.param_std[k],
                r.tracked_mean[k], r.tracked_std[k], X, theta,
                self.seen if k and r.analysed[k - 1] else None))


def run_filter(
    problem: FilterProblem,
    config: FilterConfig | None = None,
    *,
    health: Health | None = None,
    callback: Callable[[StepReport], None] | None = None,
    inflation_state: InflationEstimator | None = None,
) -> FilterResult:
    """Run the augmented-state ensemble Kalman filter over all observation times.

    Parameters
    ----------
    problem : FilterProblem
        Model, data, noise, prior, transforms, tracked entries.
    config : FilterConfig, optional
        Ensemble size, analysis method, inflation, seed (defaults: N = 50,
        :data:`~enkf.problem.DEFAULT_METHOD`, no inflation, seed 0).
    health : callable, optional
        ``health(E_state, theta) -> str | None`` called after the prior draw and
        after every step; default :class:`~enkf.health.HealthCheck` (non-finite values only).
    callback : callable, optional
        Called with a :class:`~enkf.problem.StepReport` after the prior draw and every
        step (progress bars, streaming to a plot or a socket).
    inflation_state : enkf.adaptive.InflationEstimator, optional
        The running estimate of ``config.adaptive_inflation`` to continue (a filter run
        one reading at a time); default: a fresh one.

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
    run = _Filter(problem, FilterConfig() if config is None else config,
                  HealthCheck() if health is None else health, callback, inflation_state)
    run.record(0)
    M = problem.obs_data.shape[0]
    for k in range(1, M + 1):
        run.step(k)
    return run.rec.result(M, run.X, run.theta)
