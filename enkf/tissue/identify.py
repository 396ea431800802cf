"""identify: run the tissue filter on a series of sensor readings (see :mod:`enkf.tissue`)."""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

import fem
from fem.threads import blas_threads, keep_freed_memory

from ..adaptive import (
    PERSISTENCE_THRESHOLD,
    AdaptiveInflation,
    InflationEstimator,
    innovation_persistence,
    persistence_flagged,
)
from ..analysis import gaspari_cohn
from ..checks import rows_times
from ..discrepancy import discrepancy_posterior
from ..health import HealthCheck
from ..loop import run_filter
from ..problem import FilterConfig, FilterDivergence, FilterProblem, FilterResult, StepReport, uniform_prior
from ..random import standard_normal
from ..transforms import IdentityTransform, LogTransform
from .coagulation import CoagulationForwardModel
from .forward import TissueForwardModel, observation_operator
from .model_error import StructuredModelError
from .setup import TissueFilterSetup

__all__ = ["STATE_BOUNDS", "FilterPieces", "TissueEstimates", "assemble",
           "identify", "laser_persistence", "persistence_summary"]

#: deg C: the health check stops a run whose mean temperature anywhere leaves this range
#: (below absolute zero, or far above anything tissue reaches before it vaporises)
STATE_BOUNDS = (-273.15, 1.0e4)

@dataclass
class TissueEstimates:
    """Filter output in physical units (step 0 is the prior).

    ``param_mean``/``param_std``: (M+1, n_par) in the order of ``names``;
    ``tracked_mean``/``tracked_std``: (M+1, n_tracked) deg C at ``tracked_positions``.
    ``step_latency_s``: (M,) wall time of each filter step.
    ``param_q_low``/``param_q_high``: (M+1, n_par) the 2.3 % and 97.7 % quantiles of the
    ensemble (the +-2 sd points of a normal), positive like the members; None when not
    recorded (then :meth:`param_band` takes them from a log-normal of the same moments).
    ``clamped``: how often the absorption model clamped a member's optics to its table
    (:meth:`TissueForwardModel.clamp_report`), None when never.
    ``effective_mean``/``effective_std``: (M+1, 2) the ensemble's effective (mua, mus)
    cm^-1 and ``coagulated_fraction`` (M+1,) its mean ``F``, with
    ``parameter_model="coagulation"`` (:mod:`enkf.tissue.coagulation`); else None.
    ``innovation_loglik``: (M,) log-density of each reading under the forecast (NaN where
    none was analysed; :func:`enkf.adaptive.innovation_loglik`): the sums of two models on
    the same data compare them.
    ``innovation_normalized``: (M, p) each reading's innovation over its forecast sd
    (:func:`enkf.adaptive.normalized_innovation`, NaN where none was analysed), and
    ``laser_on``: (M,) whether the laser delivered energy during each step;
    :meth:`innovation_persistence` tells from them whether the model misses something.
    ``sensor_offset_mean``/``sensor_offset_std``: (M+1, n_sensors) deg C, the point
    sensors' estimated offsets with ``sensor_offset_std > 0``; else None.
    With restarts (``setup.smoother_restarts``) the row of a restart's reading holds the
    restarted ensemble; ``step_latency_s`` does not count the restarts (``restarts``).
    """

    times: np.ndarray
    names: tuple
    param_mean: np.ndarray
    param_std: np.ndarray
    tracked_positions: np.ndarray
    tracked_mean: np.ndarray
    tracked_std: np.ndarray
    analysed: np.ndarray
    step_latency_s: np.ndarray
    filter_wall_s: float
    result: FilterResult | None = None
    diverged: str | None = None  #: message when the filter stopped early
    param_q_low: np.ndarray | None = None
    param_q_high: np.ndarray | None = None
    method: str | None = None  #: "etkf" or "enkf"
    clamped: dict | None = None
    effective_mean: np.ndarray | None = None
    effective_std: np.ndarray | None = None
    coagulated_fraction: np.ndarray | None = None
    innovation_loglik: np.ndarray | None = None
    innovation_normalized: np.ndarray | None = None
    laser_on: np.ndarray | None = None
    #: (M+1, n_sensors) deg C: mean and sd of the point sensors' estimated offsets
    #: (``setup.sensor_offset_std > 0``), else None
    sensor_offset_mean: np.ndarray | None = None
    sensor_offset_std: np.ndarray | None = None
    #: the restarts from the smoother (``setup.smoother_restarts``), one dict each:
    #: ``time_s`` (the reading after which), ``readings`` (how many it read), ``wall_s``
    restarts: tuple = ()
    #: (M+1, N, n_par) the members' parameters at each step (the weighted bands of a
    #: :class:`~enkf.tissue.drift.DriftBank` pool them)
    param_members: np.ndarray | None = None
    #: (M+1,) with ``setup.drift`` (:class:`~enkf.tissue.drift.DriftBank`): the
    #: probability, after each reading, that the optics drift while heated; else None
    drift_weight: np.ndarray | None = None
    #: with ``setup.drift``: ``{"still": TissueEstimates, "drifting-2": ..., ...}``, the
    #: bank's filters (these estimates are their mixture); else None
    components: dict | None = None
    #: with ``setup.drift``: ``{name: (M+1,)}``, each filter's probability after each
    #: reading (their sum is 1); else None
    component_weights: dict | None = None

    @property
    def leading_component(self) -> str | None:
        """With ``setup.drift``: the bank's filter of the largest final weight (its risk
        maps are the run's); None without a bank."""
        if not self.component_weights:
            return None
        return max(self.component_weights, key=lambda n: self.component_weights[n][-1])

    @property
    def drift_behaviour(self) -> str | None:
        """What the data support at the end, with ``setup.drift``: ``"drifting"`` or
        ``"still"`` (the more probable), None without a bank."""
        if self.drift_weight is None or not len(self.drift_weight):
            return None
        return "drifting" if self.drift_weight[-1] >= 0.5 else "still"

    def log_evidence(self) -> float:
        """Sum of :attr:`innovation_loglik` over the analysed readings (NaN if not recorded)."""
        if self.innovation_loglik is None:
            return float("nan")
        return float(np.nansum(self.innovation_loglik))

    def innovation_persistence(self, laser: str = "off") -> tuple[float, int]:
        """Lag-1 correlation of the normalized innovations from reading to reading, and the
        number of pairs it sums, over the steps where the laser is ``"off"`` (default),
        ``"on"``, or over ``"all"``: :func:`laser_persistence`."""
        return laser_persistence(self.innovation_normalized, self.laser_on, laser)

    def param_band(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of parameter ``i`` over time: the ensemble's 2.3 % and 97.7 %
        quantiles, or those of a log-normal with the recorded mean and std (the filter
        works on log parameters, so the band stays positive; mean +- 2 sd does not)."""
        if self.param_q_low is not None:
            return self.param_q_low[:, i], self.param_q_high[:, i]
        m, s = self.param_mean[:, i], self.param_std[:, i]
        with np.errstate(invalid="ignore", divide="ignore"):
            s2 = np.log1p((s / m) ** 2)
            mu = np.log(m) - 0.5 * s2
            return np.exp(mu - 2 * np.sqrt(s2)), np.exp(mu + 2 * np.sqrt(s2))


@dataclass
class FilterPieces:
    """What :func:`identify` and the online identifier build from a setup."""

    model: TissueForwardModel | CoagulationForwardModel
    P_obs: sp.csr_matrix
    noise_var: np.ndarray
    P_track: sp.csr_matrix
    prior: Callable
    rw: np.ndarray
    transforms: object
    dynamics: Callable | None
    localization: tuple | None
    walk_scale: Callable | None
    config: FilterConfig
    health: HealthCheck
    n: int
    #: the sensors' estimated offsets in the readings (setup.sensor_offset_std > 0)
    observation_offset: Callable | None = None
    #: the image's model error in the readings' covariance (ThermalImage.error_covariance)
    obs_error: Callable | None = None
    #: ``tracked(rep) -> (mean, std)`` of the tracked points, with the camera's model
    #: error at those on the top face (:func:`tracked_statistics`; assemble sets it)
    tracked: Callable | None = None

    def model_noise(self):
        """The model error of a new run: a :class:`StructuredModelError` on the mesh nodes,
        or the white variance ``model_noise_std**2``."""
        s = self.model.setup
        if s.model_error == "white":
            return s.model_noise_std ** 2
        p = self.model.mesh.p
        extra = None
        if isinstance(self.model, CoagulationForwardModel) and \
                self.model.coagulation.mean_field_rel_std > 0:
            extra = self.model.mean_field_rel_std
        return StructuredModelError(
            *(np.unique(p[i]) for i in range(3)), rel_std=s.model_error_rel_std,
            time_scale=s.model_error_time_scale, length_xy=s.model_error_length_xy,
            length_z=s.model_error_length_z, floor_std=s.model_noise_std,
            extra_rel_std=extra)

    def problem(self, times, data, prior=None, t0: float = 0.0, model_noise=None
                ) -> FilterProblem:
        return FilterProblem(
            forecast=self.model, observation=self.P_obs, obs_times=times, obs_data=data,
            obs_cov=self.noise_var, prior=prior or self.prior,
            model_noise=self.model_noise() if model_noise is None else model_noise,
            param_noise=self.rw,
            transforms=self.transforms, t0=t0, param_dynamics=self.dynamics,
            localization=self.localization, param_noise_scale=self.walk_scale,
            observation_offset=self.observation_offset, obs_error=self.obs_error)


def assemble(setup: TissueFilterSetup, param_bounds=None, warm_dt: float | None = None
              ) -> FilterPieces:
    model = TissueForwardModel(setup)
    names = setup.parameter_names
    if setup.parameter_model == "coagulation":
        model = CoagulationForwardModel(model, setup.coagulation, names)
    npts = model.mesh.p.shape[1]
    if warm_dt is not None:
        model.warm_up(warm_dt)
        standard_normal(np.random.default_rng(0), (2, 2))  # the model noise's kernel too
    P_obs, noise_var, obs_xyz = observation_operator(setup, model.mesh)
    P_track = fem.probe_matrix(model.mesh, setup.tracked_positions.T)
    nominal = setup.nominal_values()
    prior = uniform_prior(np.full(npts, float(setup.T_initial)), *setup.prior_bounds())
    n = len(names)
    rw = np.broadcast_to(np.asarray(setup.random_walk_std, float), (n,)) ** 2

    def walk_scale(t0, t1):
        return 1.0 if setup.power(0.5 * (t0 + t1)) > 0 else setup.random_walk_when_off

    transforms = LogTransform()
    dynamics = None
    bounds_extra = np.zeros((0, 2))
    if setup.parameter_model == "trend":
        level_prior, sv = prior, float(setup.trend_prior_std)

        def prior(rng, N):  # noqa: F811 - the levels' prior plus zero-mean rates
            X0, th = level_prior(rng, N)
            return X0, np.hstack([th, sv * rng.standard_normal((N, n))])

        rw = np.concatenate([rw, np.broadcast_to(
            np.asarray(setup.trend_noise_std, float), (n,)) ** 2])
        transforms = [LogTransform()] * n + [IdentityTransform()] * n

        def dynamics(U, t0, t1):
            U = U.copy()
            # the rates (columns n to 2n); sensor offsets, if any, come after them
            U[:, :n] += U[:, n:2 * n] * ((t1 - t0) * walk_scale(t0, t1))
            return U

        bounds_extra = np.tile([-1e3, 1e3], (n, 1))  # rates: no physical bound
    observation_offset = None
    n_off = setup.n_sensor_offsets
    if n_off:
        # an unknown calibration offset of each point sensor (deg C), a parameter of the
        # members: N(0, sensor_offset_std^2) at the start, no walk, added to the readings
        inner_prior, so = prior, float(setup.sensor_offset_std)

        def prior(rng, N):  # noqa: F811 - the parameters' prior plus the offsets
            X0, th = inner_prior(rng, N)
            return X0, np.hstack([th, so * rng.standard_normal((N, n_off))])

        rw = np.concatenate([rw, np.zeros(n_off)])
        transforms = (transforms if isinstance(transforms, list) else [transforms] * n) \
            + [IdentityTransform()] * n_off
        bounds_extra = np.vstack([bounds_extra, np.tile([-1e3, 1e3], (n_off, 1))])
        p_img = 0 if setup.image is None else setup.image.n_pixels

        def observation_offset(theta):
            return np.hstack([theta[:, -n_off:], np.zeros((theta.shape[0], p_img))])
    localization = None
    if setup.localization_radius is not None:
        # Houtekamer & Mitchell (2001): taper the temperature-observation and the
        # observation-observation covariances; the parameters stay global (rows of ones)
        c = 0.5 * float(setup.localization_radius)  # the taper reaches zero at 2c
        d_xy = np.linalg.norm(model.mesh.p.T[:, None, :] - obs_xyz[None, :, :], axis=2)
        d_yy = np.linalg.norm(obs_xyz[:, None, :] - obs_xyz[None, :, :], axis=2)
        n_theta = len(names) * (2 if setup.parameter_model == "trend" else 1) + n_off
        rho_xy = np.vstack([gaspari_cohn(d_xy / c), np.ones((n_theta, obs_xyz.shape[0]))])
        localization = (rho_xy, gaspari_cohn(d_yy / c))
    obs_error = None
    image = setup.image
    if image is not None and image.model_error_rel_std > 0:
        # the camera's model error, relative to each pixel's predicted rise: the pixels
        # follow the point sensors in the readings
        C_img, p_pts, p_all = image.error_correlation(), setup.sensor_positions.shape[0], \
            P_obs.shape[0]
        T_ref = float(setup.T_initial)

        def obs_error(y_mean):
            R = np.zeros((p_all, p_all))
            R[p_pts:, p_pts:] = image.error_covariance(y_mean[p_pts:], T_ref, C_img)
            return R
    adaptive = None
    if setup.adaptive_inflation:
        adaptive = AdaptiveInflation(bounds=setup.adaptive_inflation_bounds,
                                     time_scale=setup.adaptive_inflation_time_scale)
    config = FilterConfig(n_members=setup.n_members, method=setup.method,
                          inflation=setup.inflation, seed=setup.seed, mda=setup.mda,
                          adaptive_inflation=adaptive, rtps=setup.rtps)
    if param_bounds is None:
        param_bounds = setup.default_param_bounds()
    # stop on non-finite values, a parameter mean beyond the bounds, a collapsed spread
    # (below 1e-6 of the nominal value: the data can no longer move it), or a temperature
    # no tissue reaches (a runaway state: adaptive inflation compounding on the deep
    # temperatures with drifting optics reached 1e8 deg C)
    min_std = np.concatenate([1e-6 * nominal, np.zeros(len(bounds_extra))])
    health = HealthCheck(param_bounds=np.vstack([param_bounds, bounds_extra]),
                         min_param_std=min_std, state_bounds=STATE_BOUNDS)
    return FilterPieces(model, P_obs, noise_var, P_track, prior, rw, transforms, dynamics,
                   localization, None if setup.random_walk_when_off == 1.0 else walk_scale,
                   config, health, n, observation_offset, obs_error,
                   tracked_statistics(setup, model.mesh, P_track))


def tracked_statistics(setup: TissueFilterSetup, mesh, P_track) -> Callable:
    """``stats(rep: StepReport) -> (mean, std)`` (n_tracked,) deg C: the tracked points'
    temperatures in the ensemble, and, with a camera whose model error is on
    (``image.model_error_rel_std > 0``), that error at the tracked points on the top face.

    The camera's model error says the model's surface is a few percent of the rise wrong
    between the pixels too; the ensemble does not carry it (it lives in the readings'
    covariance), so a point on the surface is reported with its share
    (:meth:`ThermalImage.point_error`, :func:`enkf.discrepancy.discrepancy_posterior`):
    after an analysis, the error's estimate from the frame's innovations and what of its
    variance the frame leaves; without one, its whole variance. Points below the surface
    keep the ensemble's statistics (the camera's error says nothing there).
    """
    image = setup.image
    pos = setup.tracked_positions
    top = np.flatnonzero(np.abs(pos[:, 2] - float(mesh.p[2].min())) <= 1e-9)
    if image is None or image.model_error_rel_std == 0 or not top.size:
        def stats(rep):
            Y = rows_times(P_track, rep.state_ensemble)
            return Y.mean(axis=0), Y.std(axis=0, ddof=1)
        return stats
    P_top, xy = P_track[top], pos[top, :2]
    C_top = image.point_correlation(xy)  # fixed: the points and the pixels do not move
    p_pts = setup.sensor_positions.shape[0]
    T_ref = float(setup.T_initial)

    def stats(rep):
        Y = rows_times(P_track, rep.state_ensemble)
        mean, var = Y.mean(axis=0), Y.var(axis=0, ddof=1)
        if rep.forecast is None:  # no frame: the error's prior variance
            k_zz = image.point_error(xy, mean[top] - T_ref, np.full(image.n_pixels, T_ref),
                                     T_ref, C_top)[1]
            var[top] += k_zz
        else:
            X_f, Y_f, y, R = rep.forecast
            G_f = rows_times(P_top, X_f)
            k_pix, k_zz = image.point_error(xy, G_f.mean(axis=0) - T_ref,
                                            Y_f[:, p_pts:].mean(axis=0), T_ref, C_top)
            k_zy = np.zeros((top.size, Y_f.shape[1]))
            k_zy[:, p_pts:] = k_pix
            shift, extra = discrepancy_posterior(G_f, Y_f, y, R, k_zy, k_zz)
            mean[top] += shift
            var[top] += extra
        return mean, np.sqrt(np.maximum(var, 0.0))
    return stats


def restart_points(setup: TissueFilterSetup, times, data=None) -> list[int]:
    """The reading counts ``k`` (1..M) after which the filter restarts from the smoother
    (:attr:`TissueFilterSetup.smoother_restarts`, :meth:`~TissueFilterSetup.restart_after`);
    with ``data`` (M, p), not before the first finite reading (the smoother needs one),
    and for drifting optics not before the laser has heated."""
    if not setup.smoother_restarts:
        return []
    from .smooth import heated_time

    t = np.asarray(times, float)
    finite = np.ones(t.size, bool) if data is None else \
        np.isfinite(np.asarray(data, float)).reshape(t.size, -1).any(axis=1)
    seen = np.cumsum(finite) > 0  # a finite reading at or before reading k
    if setup.restart_drifts:  # drifting: and a heated step (the knots' clock)
        seen &= heated_time(setup.power, np.r_[0.0, t])[1:] > 0
    return [k + 1 for k in range(t.size) if seen[k]
            and setup.restart_after(float(t[k - 1]) if k else 0.0, float(t[k]))]


def restart_ensemble(setup: TissueFilterSetup, pieces: FilterPieces, times, data,
                     on_step: Callable | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """The ensemble a restart gives after the readings ``data`` at ``times`` (all of them
    so far): the parameters of the ES-MDA smoother over them
    (:func:`enkf.tissue.smooth.smooth_constant`, or with ``smoother_restart_knots >= 2``
    :func:`~enkf.tissue.smooth.smooth_drifting`'s at the last reading; with several counts
    of knots, an equal mixture of those smoothers, a block of members from each;
    ``setup.smoother_restart_iterations`` updates from the prior; with
    ``setup.smoother_restart_gaussian`` a log-normal ensemble of their moments,
    :func:`gaussian_ensemble`) and each member's temperatures re-run from ``T_initial``
    with its own optics (drifting: along its own path through its knots).

    The re-run carries the filter's model error (:meth:`FilterPieces.model_noise`: a
    draw of the structured error, or the white floor), so that the restarted members
    hold the spread of the temperatures that the filter's forecasts would have: without
    it, against data from another model their bands beneath the surface were too narrow.
    (Keeping instead each filter member's residual, its temperatures less a run of its
    own parameters, carried the analyses' compensation of the old parameters' errors:
    the twins' estimates went to 2-3 times the bound.)

    ``on_step(k, t, X, theta)``, if given, sees the re-run: step 0 at the start, then
    each step ``k`` at ``times[k - 1]`` with the members' optics of that step.

    Returns ``(X (N, n_nodes) deg C, theta (N, n_par), wall_s)``."""
    from .smooth import heated_time, smooth_constant, smooth_drifting

    tic = time.perf_counter()
    kw = dict(n_iter=setup.smoother_restart_iterations,
              discrepancy=setup.smoother_restart_discrepancy,
              discrepancy_time=setup.smoother_restart_discrepancy_time)
    edges = np.r_[0.0, np.asarray(times, float)]
    rng = np.random.default_rng([setup.seed, len(times), 7])
    if setup.restart_drifts:  # drifting: each member's path, then its end
        parts = [smooth_drifting(setup, times, data, knots=k, drifting=setup.restart_drifting,
                                 **kw) for k in setup.restart_knot_forms]
    else:
        parts = [smooth_constant(setup, times, data, **kw)]
    if setup.smoother_restart_gaussian:
        parts = [_redrawn(sm, rng) for sm in parts]
    heated = heated_time(setup.power, edges)
    mid = 0.5 * (heated[:-1] + heated[1:])
    # each step's optics, (M, N, n_par); several forms of the drift: a block of members each
    blocks = np.array_split(np.arange(parts[0].theta.shape[0]), len(parts))
    path = np.concatenate([sm.at(mid)[:, b] for sm, b in zip(parts, blocks, strict=True)],
                          axis=1)
    theta = np.ascontiguousarray(np.concatenate(
        [sm.theta[b] for sm, b in zip(parts, blocks, strict=True)]))
    noise = pieces.model_noise()
    X = np.full((theta.shape[0], pieces.model.mesh.p.shape[1]), float(setup.T_initial))
    if on_step is not None:
        on_step(0, float(edges[0]), X, np.ascontiguousarray(path[0]))
    for k in range(edges.size - 1):
        th = np.ascontiguousarray(path[k])
        X1 = pieces.model(X, th, float(edges[k]), float(edges[k + 1]))
        if callable(noise):
            X1 = X1 + noise(rng, X, X1, th, float(edges[k]), float(edges[k + 1]))
        elif noise > 0:
            X1 = X1 + np.sqrt(noise) * standard_normal(rng, X1.shape)
        X = X1
        if on_step is not None:
            on_step(k + 1, float(edges[k + 1]), X, th)
    return X, theta, time.perf_counter() - tic


def _redrawn(sm, rng: np.random.Generator):
    """The smoother's estimates ``sm`` with its members replaced by a log-normal draw of
    their moments (:func:`gaussian_ensemble`): of ``theta``, or with knots of their free
    values (every knot of a drifting parameter, the first of a constant one), ``theta``
    then their last knot."""
    if sm.knots is None:
        return replace(sm, theta=gaussian_ensemble(sm.theta, rng))
    V = sm.knots.copy()  # (N, K, n_par)
    drift = np.any(V != V[:, :1], axis=(0, 1))
    cols = [(k, i) for i in range(V.shape[2]) for k in (range(V.shape[1]) if drift[i] else (0,))]
    W = gaussian_ensemble(np.stack([V[:, k, i] for k, i in cols], axis=1), rng)
    for j, (k, i) in enumerate(cols):
        if drift[i]:
            V[:, k, i] = W[:, j]
        else:  # one value over every knot
            V[:, :, i] = W[:, j, None]
    return replace(sm, theta=np.ascontiguousarray(V[:, -1]), knots=V)


def gaussian_ensemble(theta: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, n) positive members whose logs have exactly the mean and covariance of
    ``log theta``'s and are otherwise a normal draw: the members' skew and outliers, which
    the deterministic (ETKF) updates carry on unchanged, are dropped."""
    U = np.log(theta)
    N, d = U.shape
    if N <= d:
        raise ValueError(f"gaussian_ensemble needs more members than parameters, got {N} "
                         f"members for {d}")
    Z = rng.standard_normal((N, d))
    Z -= Z.mean(axis=0)
    Z = Z @ np.linalg.inv(np.linalg.cholesky(np.cov(Z.T).reshape(d, d))).T  # cov exactly I
    L = np.linalg.cholesky(np.cov(U.T).reshape(d, d))
    return np.exp(U.mean(axis=0) + Z @ L.T)


def _restarted(last: FilterResult, X: np.ndarray, theta: np.ndarray) -> FilterResult:
    """A one-row result at ``last``'s final time holding the restarted ensemble."""
    nt = last.tracked_mean.shape[1]
    empty = np.zeros(0)
    return FilterResult(last.times[-1:].copy(), theta.mean(axis=0)[None],
                        theta.std(axis=0, ddof=1)[None], np.full((1, nt), np.nan),
                        np.full((1, nt), np.nan), np.zeros(0, bool), empty, empty, X, theta,
                        empty, empty, _no_rows(last.innovation_normalized))


def laser_persistence(z: np.ndarray | None, laser_on: np.ndarray | None,
                      laser: str = "off") -> tuple[float, int]:
    """:func:`enkf.adaptive.innovation_persistence` of the normalized innovations ``z``
    (M, p) over the steps where the laser is ``"off"`` (``laser_on`` (M,) False), ``"on"``,
    or over ``"all"``; ``(nan, 0)`` when ``z`` was not recorded or no pair is left.

    With the laser off the forecast is heat conduction alone and the optics no longer take
    up what the model gets wrong, so a heat model that misses the tissue's physics (its
    shape, boundaries, conduction) leaves innovations that persist from frame to frame.
    """
    if laser not in ("off", "on", "all"):
        raise ValueError(f"laser must be 'off', 'on' or 'all', got {laser!r}")
    if z is None or len(z) == 0:
        return float("nan"), 0
    z = np.asarray(z, float)
    if laser == "all":
        return innovation_persistence(z)
    if laser_on is None:
        return float("nan"), 0
    return innovation_persistence(z, np.asarray(laser_on, bool)[: z.shape[0]] == (laser == "on"))


def persistence_summary(est) -> dict:
    """summary.json's ``innovation_persistence``: the lag-1 correlation of the normalized
    innovations while the laser is off and over all readings, whether it is flagged
    (:func:`enkf.adaptive.persistence_flagged`) and what that means (``advice``, also
    the warning's text), of ``est`` (a :class:`~enkf.tissue.TissueEstimates` or an
    :class:`~enkf.tissue.OnlineIdentifier`); ``likely_cause`` names what the evidence
    points at (:func:`enkf.tissue.diagnose.likely_cause`: drifting optics, a sensor
    offset, the model's physics), and ``advice`` what to do about it (None when nothing
    is to be done: no misfit, or a drift the drift bank has taken up)."""
    from .diagnose import drift_weight_of, likely_cause

    r_off, n_off = est.innovation_persistence("off")
    r_on, n_on = est.innovation_persistence("on")
    r_all, n_all = est.innovation_persistence("all")
    flagged = persistence_flagged(r_off, n_off)
    cause, advice = likely_cause(est, r_off, n_off, r_on, n_on)
    if cause == "drifting optics" and not flagged and drift_weight_of(est) is not None:
        advice = None  # a drift bank has taken the drift up: nothing to do

    def num(r):
        return round(float(r), 4) if np.isfinite(r) else None

    return {"laser_off": num(r_off), "laser_off_pairs": n_off,
            "laser_on": num(r_on), "laser_on_pairs": n_on,
            "all": num(r_all), "all_pairs": n_all,
            "threshold": PERSISTENCE_THRESHOLD, "flagged": flagged or advice is not None,
            "likely_cause": cause, "advice": advice}


def _no_rows(a: np.ndarray | None) -> np.ndarray | None:
    """``a``'s shape with no rows (a restart's row adds no step)."""
    return None if a is None else np.zeros((0, *a.shape[1:]))


def _join(parts: list[FilterResult]) -> FilterResult:
    """One result from the segments of a run with restarts: each segment's first row (the
    restarted ensemble) replaces the last row of the one before."""
    if len(parts) == 1:
        return parts[0]
    rows = ("times", "param_mean", "param_std", "tracked_mean", "tracked_std")
    steps = ("analysed", "step_latency_s", "analysis_latency_s", "inflation",
             "innovation_loglik", "innovation_normalized")
    out = {k: np.concatenate([getattr(r, k)[:-1] for r in parts[:-1]]
                             + [getattr(parts[-1], k)]) for k in rows}
    out.update({k: np.concatenate([getattr(r, k) for r in parts]) for k in steps})
    return FilterResult(**out, state_ensemble=parts[-1].state_ensemble,
                        param_ensemble=parts[-1].param_ensemble)


def identify(setup: TissueFilterSetup, times: np.ndarray, data: np.ndarray, *,
             callback: Callable[[StepReport], None] | None = None,
             param_bounds: np.ndarray | None = None) -> TissueEstimates:
    """Run the filter on sensor data.

    With ``setup.drift`` (a :class:`~enkf.tissue.drift.DriftBank`) a still and a drifting
    filter run on the readings and the estimates are their mixture under the evidence
    (:func:`enkf.tissue.drift.identify_bank`; ``drift_weight`` says, per reading, how
    probable the drift is).

    With ``setup.smoother_restarts`` the filter restarts from the smoother after the
    readings :func:`restart_points` names (:func:`restart_ensemble`; ``docs/enkf.md``,
    "Restarts"). After each restart the callback sees the restarted members' re-run again
    from step 0 (``StepReport.replayed``), then the filter's steps go on: a
    :class:`~enkf.tissue.risk.RiskTracker` (step 0 starts it afresh) so integrates each
    member's damage along its own history.

    Parameters
    ----------
    times : (M,) s, strictly increasing, after 0 (the prior is at t = 0)
    data : (M, p) deg C at ``setup.sensor_positions`` (then the image's pixels);
        NaN = missing (no analysis)
    callback : called with a :class:`~enkf.problem.StepReport` after each step (the prior
        is step 0)
    param_bounds : (n_par, 2), physical range of each parameter's ensemble mean;
        leaving it stops the run (default: :meth:`TissueFilterSetup.default_param_bounds`)

    Returns
    -------
    TissueEstimates; if the filter diverges, the estimates up to that point with
    ``diverged`` set to the message.
    """
    if setup.drift is not None:
        from .drift import identify_bank

        return identify_bank(setup, times, data, callback=callback, param_bounds=param_bounds)
    return _identify_single(setup, times, data, callback=callback, param_bounds=param_bounds)


def _identify_single(setup: TissueFilterSetup, times: np.ndarray, data: np.ndarray, *,
                     callback: Callable[[StepReport], None] | None = None,
                     param_bounds: np.ndarray | None = None,
                     restart_gate: Callable[[int, np.ndarray], bool] | None = None
                     ) -> TissueEstimates:
    """:func:`identify` with one filter. ``restart_gate(a, loglik)``, if given, is asked
    before each restart (after reading ``a``, with the filter's log-densities of readings
    1..a): False skips that restart, and the filter goes on with its members."""
    pieces = assemble(setup, param_bounds, float(times[0]) if len(times) else None)
    P_track, n = pieces.P_track, pieces.n
    n_off = setup.n_sensor_offsets
    M = len(times)
    tr_mean = np.full((M + 1, P_track.shape[0]), np.nan)
    tr_std = np.full_like(tr_mean, np.nan)
    q_lo = np.full((M + 1, n), np.nan)
    q_hi = np.full_like(q_lo, np.nan)
    members = np.full((M + 1, setup.n_members, n), np.nan)
    coag = isinstance(pieces.model, CoagulationForwardModel)
    eff_mean = np.full((M + 1, 2), np.nan) if coag else None
    eff_std = np.full((M + 1, 2), np.nan) if coag else None
    frac = np.full(M + 1, np.nan) if coag else None

    def record(rep: StepReport, outside: bool = True):
        tr_mean[rep.step], tr_std[rep.step] = pieces.tracked(rep)
        members[rep.step] = rep.param_ensemble[:, :n]
        with np.errstate(invalid="ignore"):
            q_lo[rep.step], q_hi[rep.step] = np.quantile(
                rep.param_ensemble[:, :n], [0.02275, 0.97725], axis=0)
        if coag:  # the optics the members had at this time: their damage, their values
            F, eff = pieces.model.effective(rep.param_ensemble[:, :n], rep.time)
            eff_mean[rep.step], eff_std[rep.step] = eff.mean(axis=0), eff.std(axis=0, ddof=1)
            frac[rep.step] = F.mean()
        if callback is not None and outside:
            callback(rep)

    def replay(k, t, X, th):  # a restart's re-run, for the callback (StepReport.replayed)
        rep = StepReport(k, t, False, 0.0, th.mean(axis=0), th.std(axis=0, ddof=1),
                         np.zeros(0), np.zeros(0), X, th, replayed=True)
        callback(rep)

    on_step = None if callback is None else replay
    t0 = time.perf_counter()
    diverged = None
    # the restarts from the smoother (setup.smoother_restarts) cut the readings into
    # segments: the filter runs each from the ensemble the one before left (the first from
    # the prior), replaced after a segment's last reading by the smoother's
    cuts = restart_points(setup, times, data)
    edges = [0, *[c for c in cuts if c < M], M]
    parts, restarts = [], []
    # the inflation estimate runs across the restarts, as in OnlineIdentifier; the
    # model error's time-correlated field starts afresh with each segment's new members
    ai = pieces.config.adaptive_inflation
    inflation = InflationEstimator(ai) if ai is not None else None
    # the filter's dense products are small (50 x 5000): threaded BLAS only spins, and
    # on a busy machine it is 20-30 times slower (measured); numba kernels keep the cores
    keep_freed_memory()  # ensemble-sized temporaries: reuse, not fresh page faults
    for j, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        if not j:
            problem = pieces.problem(times[:b], data[:b])
        elif restart_gate is not None and not restart_gate(a, np.concatenate(
                [p.innovation_loglik for p in parts])):
            # no restart here: the filter goes on with its members
            last = parts[-1]
            problem = pieces.problem(times[a:b], data[a:b], t0=float(times[a - 1]),
                                     prior=lambda rng, N, X=last.state_ensemble,
                                     th=last.param_ensemble: (X.copy(), th.copy()))
        else:
            X, theta, w = restart_ensemble(setup, pieces, times[:a], data[:a], on_step)
            restarts.append({"time_s": float(times[a - 1]), "readings": a, "wall_s": w})
            problem = pieces.problem(times[a:b], data[a:b], t0=float(times[a - 1]),
                                     prior=lambda rng, N, X=X, th=theta: (X.copy(), th.copy()))
        config = pieces.config if not j else replace(
            pieces.config, seed=int(np.random.SeedSequence([setup.seed, j]).generate_state(1)[0]))

        def seg_record(rep, a=a):  # this segment's steps in the run's numbering; the
            # restarted ensemble (its step 0) replaces the last step's, unseen outside
            record(replace(rep, step=rep.step + a), outside=rep.step > 0 or a == 0)

        try:
            with blas_threads(1):
                res = run_filter(problem, config, health=pieces.health, callback=seg_record,
                                 inflation_state=inflation)
        except FilterDivergence as err:
            parts.append(err.result)
            if j and err.step == 0:  # the restarted ensemble failed: its row is all its own
                r = err.result
                record(StepReport(a, float(times[a - 1]), False, 0.0, r.param_mean[0],
                                  r.param_std[0], r.tracked_mean[0], r.tracked_std[0],
                                  r.state_ensemble, r.param_ensemble), outside=False)
            # a later segment counts its steps from its restart
            diverged = str(err) + (f" (steps counted from the restart after the reading at "
                                   f"{times[a - 1]:g} s, reading {a})" if j else "")
            break
        parts.append(res)
    if diverged is None and M in cuts and (restart_gate is None or restart_gate(
            M, np.concatenate([p.innovation_loglik for p in parts]))):
        # a restart after the last reading: the final ensemble
        X, theta, w = restart_ensemble(setup, pieces, times, data, on_step)
        restarts.append({"time_s": float(times[-1]), "readings": M, "wall_s": w})
        parts.append(_restarted(parts[-1], X, theta))
        r = parts[-1]
        record(StepReport(M, float(times[-1]), False, 0.0, r.param_mean[0], r.param_std[0],
                          r.tracked_mean[0], r.tracked_std[0], X, theta), outside=False)
    res = _join(parts)
    wall = time.perf_counter() - t0
    clamped = pieces.model.clamp_report()
    if clamped:
        warnings.warn(f"the absorption emulator clamped members' optics to its table on "
                      f"{clamped['member_steps']} member-steps over {clamped['forecast_steps']} "
                      f"forecast steps: {clamped['advice']}", RuntimeWarning, stacklevel=2)
    k = len(res.times)
    est = TissueEstimates(
        times=res.times, names=setup.parameter_names, param_mean=res.param_mean[:, :n],
        param_std=res.param_std[:, :n],
        tracked_positions=setup.tracked_positions, tracked_mean=tr_mean[:k],
        tracked_std=tr_std[:k], analysed=res.analysed, step_latency_s=res.step_latency_s,
        filter_wall_s=wall, result=res, diverged=diverged, param_q_low=q_lo[:k],
        param_q_high=q_hi[:k], method=setup.method, clamped=clamped,
        effective_mean=None if eff_mean is None else eff_mean[:k],
        effective_std=None if eff_std is None else eff_std[:k],
        coagulated_fraction=None if frac is None else frac[:k],
        innovation_loglik=res.innovation_loglik,
        innovation_normalized=res.innovation_normalized,
        laser_on=np.array([setup.mean_power(float(a), float(b)) > 0
                           for a, b in zip(res.times[:-1], res.times[1:], strict=True)]),
        sensor_offset_mean=res.param_mean[:, -n_off:] if n_off else None,
        sensor_offset_std=res.param_std[:, -n_off:] if n_off else None,
        restarts=tuple(restarts), param_members=members[:k])
    persistence = persistence_summary(est)
    if persistence["flagged"]:
        warnings.warn(persistence["advice"], RuntimeWarning, stacklevel=2)
    return est
