"""The filter's pieces built from a setup (:func:`assemble`): the forward model, the
observation operator, the priors, the walks, localization, the camera's model error, the
health check; shared by :func:`~enkf.tissue.identify`, the online identifier, the
restarts and the smoother."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

import fem

from ..adaptive import AdaptiveInflation
from ..analysis import gaspari_cohn
from ..checks import rows_times
from ..discrepancy import discrepancy_posterior
from ..health import HealthCheck
from ..problem import FilterConfig, FilterProblem, uniform_prior
from ..random import standard_normal
from ..transforms import IdentityTransform, LogTransform, as_transforms
from .coagulation import CoagulationForwardModel
from .forward import TissueForwardModel, observation_operator
from .model_error import StructuredModelError
from .setup import TissueFilterSetup

__all__ = ["STATE_BOUNDS", "FilterPieces", "assemble", "tracked_statistics"]

#: deg C: the health check stops a run whose mean temperature anywhere leaves this range
#: (below absolute zero, or far above anything tissue reaches before it vaporises)
STATE_BOUNDS = (-273.15, 1.0e4)


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
    #: the sensors' estimated offsets in the readings (setup.sensors.offset_std > 0)
    observation_offset: Callable | None = None
    #: the image's model error in the readings' covariance (ThermalImage.error_covariance)
    obs_error: Callable | None = None
    #: ``tracked(rep) -> (mean, std)`` of the tracked points, with the camera's model
    #: error at those on the top face (:func:`tracked_statistics`; assemble sets it)
    tracked: Callable | None = None
    #: (n_par, 2) the health check's bounds in the filter's (log) units, where the
    #: parameters' random walk is reflected (filters restarted from the smoother only)
    walk_bounds: np.ndarray | None = None

    def model_noise(self):
        """The model error of a new run: a :class:`StructuredModelError` on the mesh nodes,
        or the white variance ``model_noise_std**2``."""
        s = self.model.setup
        if s.model_error.kind == "white":
            return s.model_error.noise_std ** 2
        p = self.model.mesh.p
        extra = None
        if isinstance(self.model, CoagulationForwardModel) and \
                self.model.coagulation.mean_field_rel_std > 0:
            extra = self.model.mean_field_rel_std
        return StructuredModelError(
            *(np.unique(p[i]) for i in range(3)), rel_std=s.model_error.rel_std,
            time_scale=s.model_error.time_scale, length_xy=s.model_error.length_xy,
            length_z=s.model_error.length_z, floor_std=s.model_error.noise_std,
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
            param_walk_bounds=self.walk_bounds, observation_offset=self.observation_offset,
            obs_error=self.obs_error)


def assemble(setup: TissueFilterSetup, param_bounds=None, warm_dt: float | None = None
              ) -> FilterPieces:
    model = TissueForwardModel(setup)
    names = setup.parameters.names
    if setup.parameters.kind == "coagulation":
        model = CoagulationForwardModel(model, setup.parameters.coagulation, names)
    npts = model.mesh.p.shape[1]
    if warm_dt is not None:
        model.warm_up(warm_dt)
        standard_normal(np.random.default_rng(0), (2, 2))  # the model noise's kernel too
    P_obs, noise_var, obs_xyz = observation_operator(setup, model.mesh)
    P_track = fem.probe_matrix(model.mesh, setup.sensors.tracked.T)
    nominal = setup.parameters.nominal_values()
    prior = uniform_prior(np.full(npts, float(setup.T_initial)), *setup.parameters.prior_bounds(),
                          sampling=setup.parameters.prior_sampling)
    n = len(names)
    rw = np.broadcast_to(np.asarray(setup.parameters.random_walk_std, float), (n,)) ** 2

    def walk_scale(t0, t1):
        return 1.0 if setup.power(0.5 * (t0 + t1)) > 0 else setup.parameters.random_walk_when_off

    transforms = LogTransform()
    dynamics = None
    bounds_extra = np.zeros((0, 2))
    if setup.parameters.kind == "trend":
        level_prior, sv = prior, float(setup.parameters.trend_prior_std)

        def prior(rng, N):  # noqa: F811 - the levels' prior plus zero-mean rates
            X0, th = level_prior(rng, N)
            return X0, np.hstack([th, sv * rng.standard_normal((N, n))])

        rw = np.concatenate([rw, np.broadcast_to(
            np.asarray(setup.parameters.trend_noise_std, float), (n,)) ** 2])
        transforms = [LogTransform()] * n + [IdentityTransform()] * n

        def dynamics(U, t0, t1):
            U = U.copy()
            # the rates (columns n to 2n); sensor offsets, if any, come after them
            U[:, :n] += U[:, n:2 * n] * ((t1 - t0) * walk_scale(t0, t1))
            return U

        bounds_extra = np.tile([-1e3, 1e3], (n, 1))  # rates: no physical bound
    observation_offset = None
    n_off = setup.sensors.n_offsets
    if n_off:
        # an unknown calibration offset of each point sensor (deg C), a parameter of the
        # members: N(0, sensor_offset_std^2) at the start, no walk, added to the readings
        inner_prior, so = prior, float(setup.sensors.offset_std)

        def prior(rng, N):  # noqa: F811 - the parameters' prior plus the offsets
            X0, th = inner_prior(rng, N)
            return X0, np.hstack([th, so * rng.standard_normal((N, n_off))])

        rw = np.concatenate([rw, np.zeros(n_off)])
        transforms = (transforms if isinstance(transforms, list) else [transforms] * n) \
            + [IdentityTransform()] * n_off
        bounds_extra = np.vstack([bounds_extra, np.tile([-1e3, 1e3], (n_off, 1))])
        p_img = 0 if setup.sensors.image is None else setup.sensors.image.n_pixels

        def observation_offset(theta):
            return np.hstack([theta[:, -n_off:], np.zeros((theta.shape[0], p_img))])
    localization = None
    if setup.localization_radius is not None:
        # Houtekamer & Mitchell (2001): taper the temperature-observation and the
        # observation-observation covariances; the parameters stay global (rows of ones)
        c = 0.5 * float(setup.localization_radius)  # the taper reaches zero at 2c
        d_xy = np.linalg.norm(model.mesh.p.T[:, None, :] - obs_xyz[None, :, :], axis=2)
        d_yy = np.linalg.norm(obs_xyz[:, None, :] - obs_xyz[None, :, :], axis=2)
        n_theta = len(names) * (2 if setup.parameters.kind == "trend" else 1) + n_off
        rho_xy = np.vstack([gaspari_cohn(d_xy / c), np.ones((n_theta, obs_xyz.shape[0]))])
        localization = (rho_xy, gaspari_cohn(d_yy / c))
    obs_error = None
    image = setup.sensors.image
    if image is not None and image.model_error_rel_std > 0:
        # the camera's model error, relative to each pixel's predicted rise: the pixels
        # follow the point sensors in the readings
        C_img, p_pts, p_all = image.error_correlation(), setup.sensors.positions.shape[0], \
            P_obs.shape[0]
        T_ref = float(setup.T_initial)

        def obs_error(y_mean):
            R = np.zeros((p_all, p_all))
            R[p_pts:, p_pts:] = image.error_covariance(y_mean[p_pts:], T_ref, C_img)
            return R
    adaptive = None
    if setup.model_error.adaptive_inflation:
        adaptive = AdaptiveInflation(bounds=setup.model_error.adaptive_inflation_bounds,
                                     time_scale=setup.model_error.adaptive_inflation_time_scale)
    config = FilterConfig(n_members=setup.n_members, method=setup.method,
                          inflation=setup.model_error.inflation, seed=setup.seed, mda=setup.mda,
                          adaptive_inflation=adaptive, rtps=setup.model_error.rtps)
    if param_bounds is None:
        param_bounds = setup.parameters.default_bounds()
    # stop on non-finite values, a parameter mean beyond the bounds, a collapsed spread
    # (below 1e-6 of the nominal value: the data can no longer move it), or a temperature
    # no tissue reaches (a runaway state: adaptive inflation compounding on the deep
    # temperatures with drifting optics reached 1e8 deg C)
    min_std = np.concatenate([1e-6 * nominal, np.zeros(len(bounds_extra))])
    all_bounds = np.vstack([param_bounds, bounds_extra])
    health = HealthCheck(param_bounds=all_bounds, min_param_std=min_std,
                         state_bounds=STATE_BOUNDS)
    # a filter restarted from the smoother (a drift bank's drifting filters) walks within
    # the health check's bounds, reflected there: a parameter the readings barely see (mus
    # with VHC and TC estimated too) waits inside them for the restart that resets it.
    # Without restarts nothing would reset it, and a walk that leaves them stops the run.
    walk_bounds = filter_space_bounds(transforms, all_bounds) if setup.restarts.times \
        else None
    return FilterPieces(model, P_obs, noise_var, P_track, prior, rw, transforms, dynamics,
                   localization, None if setup.parameters.random_walk_when_off == 1.0 else walk_scale,
                   config, health, n, observation_offset, obs_error,
                   tracked_statistics(setup, model.mesh, P_track), walk_bounds)


def filter_space_bounds(transforms, bounds: np.ndarray) -> np.ndarray:
    """(n_par, 2) ``bounds`` (physical units) in the filter's units; an end that the
    transform cannot map (0 under the log) is open (-inf or inf)."""
    trs = as_transforms(transforms, len(bounds))
    out = np.array([[-np.inf, np.inf]] * len(bounds))
    for i, tr in enumerate(trs):
        for j in range(2):
            try:
                v = float(tr.forward(np.array([bounds[i, j]]))[0])
            except ValueError:
                continue
            if np.isfinite(v):
                out[i, j] = v
    return out


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
    image = setup.sensors.image
    pos = setup.sensors.tracked
    top = np.flatnonzero(np.abs(pos[:, 2] - float(mesh.p[2].min())) <= 1e-9)
    if image is None or image.model_error_rel_std == 0 or not top.size:
        def stats(rep):
            Y = rows_times(P_track, rep.state_ensemble)
            return Y.mean(axis=0), Y.std(axis=0, ddof=1)
        return stats
    P_top, xy = P_track[top], pos[top, :2]
    C_top = image.point_correlation(xy)  # fixed: the points and the pixels do not move
    p_pts = setup.sensors.positions.shape[0]
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
