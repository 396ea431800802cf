r"""Tissue identification: the augmented EnKF of Arnold & Fichera driven by the laser-tissue model.

State of member :math:`n`: the temperature at every node of the filter's coarse
mesh (by default 20 x 20 x 10 voxels, 4,851 nodes) and
:math:`\theta = (\mu_a, \mu_s)` or :math:`(\mu_a, \mu_s, c_v, k)`, held as
logarithms so they stay positive. The forecast of one sensor interval is one
implicit heat step (:class:`fem.HeatStepper`) with the member's own absorbed
power map ``P(t) * NA(mua_n, mus_n)`` (from the absorption emulator, or direct
Monte Carlo in exact mode) and its own heat capacity and conductivity (per-member
scales, no refactorization). The observation is the temperature at the sensor
point(s), interpolated with the P1 basis.

Defaults and their reasons (see also docs/enkf.md):

* ``N = 50``; priors uniform between 0.5 and 2 times the nominal values; initial
  temperature known; ``D`` the sensor noise variance: as the paper.
* ``model_noise_std = 0.002`` deg C per step (``C = 0.002^2 I``): the coarse model
  is close to the truth, and a larger white nodal noise only makes the members
  rough and lets them disagree with data through noise rather than physics.
* random walk on log parameters (``E``), per 0.1 s step: ``0.002`` when the
  parameters are believed constant; when they may drift, ``0.03`` for log mua and
  ``0.06`` for log mus (the paper's ramps are 0.028 and 0.032 per step in log
  units; mus, weakly identified, needs the wider walk to be followed at all).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

import fem
from fem._threads import blas_threads

from .driver import (
    FilterConfig,
    FilterDivergence,
    FilterProblem,
    FilterResult,
    HealthCheck,
    StepReport,
    run_filter,
    uniform_prior,
)
from .transforms import IdentityTransform, LogTransform

PARAMETER_NAMES = ("mua", "mus", "VHC", "TC")
PARAMETER_UNITS = {"mua": "cm^-1", "mus": "cm^-1", "VHC": "J cm^-3 K^-1", "TC": "W cm^-1 K^-1"}


def default_bounds(nominal, prior_lo, prior_hi) -> np.ndarray:
    """(n_par, 2) default health-check range of each parameter's mean: 1/20 to 20 times
    the nominal value, widened to a tenth of the prior's low end and ten times its high end."""
    nominal, prior_lo, prior_hi = (np.asarray(a, float) for a in (nominal, prior_lo, prior_hi))
    return np.column_stack([np.minimum(nominal / 20, prior_lo / 10),
                            np.maximum(nominal * 20, prior_hi * 10)])


@dataclass
class TissueFilterSetup:
    """Everything the filter's forward model and the filter need.

    Parameters
    ----------
    grid : fem.BoxGrid
        The filter's coarse voxel grid (also the emulator's grid).
    absorption : callable
        ``absorption(mua (N,), mus (N,)) -> NA (N, nx, ny, nz)`` in W/cm^3/W (an
        :class:`~mcmatlab_py.emulator.AbsorptionEmulator` or its exact mode).
    power : callable
        ``power(t) -> W``, the laser power at time ``t`` (s), e.g.
        :meth:`mcmatlab_py.heat.HeatSimulation.laser_power`.
    nominal : dict
        Nominal values of mua, mus (cm^-1), VHC (J cm^-3 K^-1), TC (W cm^-1 K^-1):
        VHC and TC are used as known values when not estimated, and the priors are
        ``prior_range`` times the nominal values (unless ``prior`` names the parameter).
    estimate : tuple of str
        ``("mua", "mus")`` or ``("mua", "mus", "VHC", "TC")``.
    sensor_positions : (p, 3) cm, point sensors (may be empty, shape (0, 3), with an image)
    sensor_noise_var : float or (p,), deg C^2 (the paper: 0.01)
    image : enkf.image.ThermalImage, optional
        A camera's pixels over the top face, observed after the point sensors: the data
        then have ``p + image.n_pixels`` columns (pixels in C order of the frame).
    localization_radius : float, optional
        cm: covariance localization (Gaspari-Cohn taper, zero beyond this distance)
        between temperatures and observations; the parameters stay global. Needs
        ``method="enkf"``.
    tracked_positions : (n_tracked, 3) cm, points whose temperature is reported
    prior : dict, optional
        ``{name: (lo, hi)}`` in the parameter's own units: the uniform prior of that
        parameter, in place of ``prior_range`` times its nominal value (e.g. a range
        measured on similar tissue). Only estimated parameters may be named.
    """

    grid: fem.BoxGrid
    absorption: Callable
    power: Callable[[float], float]
    nominal: dict
    estimate: tuple = ("mua", "mus")
    sensor_positions: np.ndarray = field(default_factory=lambda: np.zeros((1, 3)))
    sensor_noise_var: float | np.ndarray = 0.01
    image: object = None  #: enkf.image.ThermalImage or None
    localization_radius: float | None = None  #: cm, or None for no localization
    tracked_positions: np.ndarray = field(
        default_factory=lambda: np.array([[0, 0, 0], [0, 0, 0.1], [0, 0, 0.2]], float))
    T_initial: float = 0.0  #: deg C
    heat_boundary: fem.HeatBoundary = field(default_factory=fem.HeatBoundary)
    prior_range: tuple[float, float] = (0.5, 2.0)
    prior: dict = field(default_factory=dict)  #: {name: (lo, hi)} in physical units
    model_noise_std: float = 0.002  #: deg C per step, C = std^2 I
    random_walk_std: float | Sequence[float] = 0.002  #: log units per step, E = std^2 I
    #: factor on the random walk for steps with the laser off: 1 walks always (the paper);
    #: 0 holds the parameters still when nothing heats the tissue, which is what changes
    #: them (and, with the laser off, they no longer act on the forecast at all)
    random_walk_when_off: float = 1.0
    #: "random_walk" (the paper): log theta_(n+1) = log theta_n + xi. "trend": a local
    #: linear trend, log theta_(n+1) = log theta_n + v_n dt + xi, v_(n+1) = v_n + eta,
    #: with the rates v (1/s, in log units) filtered beside the parameters: a smooth
    #: drift (heating that changes the tissue steadily) is followed with a much smaller
    #: walk, so the data of many steps add up instead of being forgotten.
    parameter_model: str = "random_walk"
    trend_prior_std: float = 0.2  #: 1/s, prior spread of each rate v (mean 0)
    trend_noise_std: float | Sequence[float] = 0.02  #: 1/s per step, std of eta
    n_members: int = 50
    method: str = "enkf"
    inflation: float = 1.0
    mda: int = 1  #: analysis iterations per step (see enkf.driver.FilterConfig.mda)
    seed: int = 0
    theta: float = 1.0  #: time scheme of the heat steps (1: backward Euler)
    #: "kronecker" (default): the tensor-product operator of :class:`fem.HeatStepper`, equal
    #: to P1 away from the box edges, with no per-member cost when VHC and TC are estimated;
    #: "p1": the exact P1 matrices (an edge correction per new pair of member scales)
    heat_operator: str = "kronecker"
    #: 1-D mass of the tensor-product operator: "averaged" (default) cancels the leading
    #: discretization error of the lumped mass; at the paper's true parameters the
    #: 20 x 20 x 10 surface temperature is then within 0.1% of the fine truth instead of
    #: 1.1% cold (validation/reports/coarse_model_error.md). "lumped" is the P1 lumped mass.
    heat_mass: str = "averaged"

    def __post_init__(self):
        est = tuple(self.estimate)
        if est not in (("mua", "mus"), ("mua", "mus", "VHC", "TC")):
            raise ValueError(f"estimate must be ('mua', 'mus') or ('mua', 'mus', 'VHC', 'TC'), "
                             f"got {self.estimate!r}")
        self.estimate = est
        for name in PARAMETER_NAMES:
            v = self.nominal.get(name)
            if v is None or not np.isfinite(v) or v <= 0:
                raise ValueError(f"nominal[{name!r}] must be > 0 ({PARAMETER_UNITS[name]}), "
                                 f"got {v!r}")
        lo, hi = self.prior_range
        if not 0 < lo < hi:
            raise ValueError(f"prior_range must be (lo, hi) with 0 < lo < hi, got "
                             f"{self.prior_range!r}")
        self.prior = dict(self.prior or {})
        for name, rng in self.prior.items():
            if name not in est:
                raise ValueError(f"prior[{name!r}]: {name} is not estimated (estimate = {est})")
            try:
                p_lo, p_hi = (float(v) for v in rng)
            except (TypeError, ValueError):
                raise ValueError(f"prior[{name!r}] must be (lo, hi) in "
                                 f"{PARAMETER_UNITS[name]}, got {rng!r}") from None
            if not (np.isfinite(p_hi) and 0 < p_lo < p_hi):
                raise ValueError(f"prior[{name!r}] must be (lo, hi) with 0 < lo < hi "
                                 f"({PARAMETER_UNITS[name]}), got {rng!r}")
            self.prior[name] = (p_lo, p_hi)
        self.sensor_positions = np.asarray(self.sensor_positions, float).reshape(-1, 3)
        if self.sensor_positions.shape[0] == 0 and self.image is None:
            raise ValueError("sensor_positions is empty and there is no image: nothing observed")
        if self.localization_radius is not None and not (
                np.isfinite(self.localization_radius) and self.localization_radius > 0):
            raise ValueError(f"localization_radius must be > 0 (cm) or None, got "
                             f"{self.localization_radius!r}")
        self.tracked_positions = np.atleast_2d(np.asarray(self.tracked_positions, float))
        if self.parameter_model not in ("random_walk", "trend"):
            raise ValueError(f"parameter_model must be 'random_walk' or 'trend', got "
                             f"{self.parameter_model!r}")
        for name in ("model_noise_std", "trend_prior_std"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")

    def prior_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the uniform prior of each estimated parameter, in ``estimate`` order."""
        lo_f, hi_f = self.prior_range
        pairs = [self.prior.get(n, (lo_f * self.nominal[n], hi_f * self.nominal[n]))
                 for n in self.estimate]
        return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])

    def default_param_bounds(self) -> np.ndarray:
        """(n_par, 2) health-check range of each mean (:func:`default_bounds`)."""
        return default_bounds(np.array([self.nominal[n] for n in self.estimate]),
                              *self.prior_bounds())


@dataclass
class TissueEstimates:
    """Filter output in physical units (step 0 is the prior).

    ``param_mean``/``param_std``: (M+1, n_par) in the order of ``names``;
    ``tracked_mean``/``tracked_std``: (M+1, n_tracked) deg C at ``tracked_positions``.
    ``step_latency_s``: (M,) wall time of each filter step.
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


class TissueForwardModel:
    """The forecast ``F(T, theta)`` of the filter: one implicit heat step per interval."""

    def __init__(self, setup: TissueFilterSetup):
        self.setup = setup
        g = setup.grid
        self.mesh = g.mesh()
        self.L = fem.voxel_load_matrix(self.mesh, g).tocsr()  # (npoints, nvox)
        # an emulator of nodal loads on this mesh: gather, no operator at all
        self._nodal = getattr(setup.absorption, "kind", "NA") == "load"
        if self._nodal:
            shape = setup.absorption.shape
            if shape != tuple(n + 1 for n in g.shape):
                raise ValueError(f"the load emulator's mesh has {shape} nodes, the filter's "
                                 f"grid {tuple(n + 1 for n in g.shape)}")
        # an emulator that stores symmetry orbits: fold the expansion into the operator
        self._unique = hasattr(setup.absorption, "unique") and not self._nodal
        if self._unique:
            inv = setup.absorption.inverse
            expand = sp.csr_matrix((np.ones(inv.size), (np.arange(inv.size), inv)))
            self.L = (self.L @ expand).tocsr()  # (npoints, n_unique)
        self.steppers: dict[float, fem.HeatStepper] = {}
        self.n_par = len(setup.estimate)
        self._warned = False

    def stepper(self, dt: float) -> fem.HeatStepper:
        key = round(dt, 9)
        if key not in self.steppers:
            s = self.setup
            self.steppers[key] = fem.HeatStepper(self.mesh, s.nominal["VHC"], s.nominal["TC"], dt,
                                                 theta=s.theta, boundary=s.heat_boundary,
                                                 operator=s.heat_operator,
                                                 mass=s.heat_mass if s.heat_operator == "kronecker"
                                                 else "lumped")
        return self.steppers[key]

    def warm_up(self, dt: float) -> None:
        """Build the solver and load the JIT code before the online loop (not timed there)."""
        s = self.setup
        N = s.n_members
        theta = np.tile([s.nominal[n] for n in s.estimate], (N, 1))
        npts = self.mesh.p.shape[1]
        power = s.power
        try:
            s.power = lambda t: 1.0
            if hasattr(s.absorption, "unique") and getattr(s.absorption, "log_na", None) is None:
                s.power = lambda t: 0.0  # exact mode: no Monte Carlo for a warm-up
            self(np.zeros((N, npts)), theta, 0.0, dt)
        finally:
            s.power = power

    def __call__(self, E_state: np.ndarray, theta: np.ndarray, t0: float, t1: float):
        s = self.setup
        N = E_state.shape[0]
        power = s.power(0.5 * (t0 + t1))
        if power != 0.0:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                if self._nodal:
                    vals = s.absorption.unique(theta[:, 0], theta[:, 1])
                    NA = None
                elif self._unique:
                    NA = s.absorption.unique(theta[:, 0], theta[:, 1])
                else:
                    NA = s.absorption(theta[:, 0], theta[:, 1])
            if caught and not self._warned:
                warnings.warn(str(caught[0].message), RuntimeWarning, stacklevel=2)
                self._warned = True
            if self._nodal:
                load = power * vals[:, s.absorption.inverse]
            else:
                load = (self.L @ (power * NA.reshape(N, -1)).T).T
        else:
            load = None
        kw = {}
        if self.n_par == 4:
            kw = dict(vhc_scale=theta[:, 2] / s.nominal["VHC"],
                      tc_scale=theta[:, 3] / s.nominal["TC"])
        return self.stepper(t1 - t0).step(E_state, load, **kw)


def observation_operator(setup: TissueFilterSetup, mesh):
    """``(P (p, n_nodes) csr, noise variances (p,), positions (p, 3) cm)`` of the point
    sensors followed by the image's pixels (pixel centres on z = 0)."""
    blocks, var, xyz = [], [], []
    n_pts = setup.sensor_positions.shape[0]
    if n_pts:
        blocks.append(fem.probe_matrix(mesh, setup.sensor_positions.T))  # points are (3, n)
        var.append(np.broadcast_to(np.asarray(setup.sensor_noise_var, float), (n_pts,)))
        xyz.append(setup.sensor_positions)
    if setup.image is not None:
        blocks.append(setup.image.matrix(mesh))
        var.append(np.full(setup.image.n_pixels, float(setup.image.noise_var)))
        xyz.append(setup.image.pixel_centers())
    return (sp.vstack(blocks).tocsr(), np.concatenate(var), np.vstack(xyz))


@dataclass
class _Pieces:
    """What identify and OnlineIdentifier build from a setup (internal)."""

    model: TissueForwardModel
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

    def problem(self, times, data, prior=None, t0: float = 0.0) -> FilterProblem:
        s = self.model.setup
        return FilterProblem(
            forecast=self.model, observation=self.P_obs, obs_times=times, obs_data=data,
            obs_cov=self.noise_var, prior=prior or self.prior,
            model_noise=s.model_noise_std ** 2, param_noise=self.rw,
            transforms=self.transforms, t0=t0, param_dynamics=self.dynamics,
            localization=self.localization, param_noise_scale=self.walk_scale)


def _assemble(setup: TissueFilterSetup, param_bounds=None, warm_dt: float | None = None
              ) -> _Pieces:
    model = TissueForwardModel(setup)
    npts = model.mesh.p.shape[1]
    if warm_dt is not None:
        model.warm_up(warm_dt)
    P_obs, noise_var, obs_xyz = observation_operator(setup, model.mesh)
    P_track = fem.probe_matrix(model.mesh, setup.tracked_positions.T)
    names = setup.estimate
    nominal = np.array([setup.nominal[n] for n in names])
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
            U[:, :n] += U[:, n:] * ((t1 - t0) * walk_scale(t0, t1))
            return U

        bounds_extra = np.tile([-1e3, 1e3], (n, 1))  # rates: no physical bound
    localization = None
    if setup.localization_radius is not None:
        from .analysis import gaspari_cohn

        # Houtekamer & Mitchell (2001): taper the temperature-observation and the
        # observation-observation covariances; the parameters stay global (rows of ones)
        c = 0.5 * float(setup.localization_radius)  # the taper reaches zero at 2c
        d_xy = np.linalg.norm(model.mesh.p.T[:, None, :] - obs_xyz[None, :, :], axis=2)
        d_yy = np.linalg.norm(obs_xyz[:, None, :] - obs_xyz[None, :, :], axis=2)
        n_theta = len(names) * (2 if setup.parameter_model == "trend" else 1)
        rho_xy = np.vstack([gaspari_cohn(d_xy / c), np.ones((n_theta, obs_xyz.shape[0]))])
        localization = (rho_xy, gaspari_cohn(d_yy / c))
    config = FilterConfig(n_members=setup.n_members, method=setup.method,
                          inflation=setup.inflation, seed=setup.seed, mda=setup.mda)
    if param_bounds is None:
        param_bounds = setup.default_param_bounds()
    # stop on non-finite values, a parameter mean beyond the bounds, or a collapsed
    # spread (below 1e-6 of the nominal value: the data can no longer move it)
    min_std = np.concatenate([1e-6 * nominal, np.zeros(len(bounds_extra))])
    health = HealthCheck(param_bounds=np.vstack([param_bounds, bounds_extra]),
                         min_param_std=min_std)
    return _Pieces(model, P_obs, noise_var, P_track, prior, rw, transforms, dynamics,
                   localization, None if setup.random_walk_when_off == 1.0 else walk_scale,
                   config, health, n)


def identify(setup: TissueFilterSetup, times: np.ndarray, data: np.ndarray, *,
             callback: Callable[[StepReport], None] | None = None,
             param_bounds: np.ndarray | None = None) -> TissueEstimates:
    """Run the filter on sensor data.

    Parameters
    ----------
    times : (M,) s, strictly increasing, after 0 (the prior is at t = 0)
    data : (M, p) deg C at ``setup.sensor_positions`` (then the image's pixels);
        NaN = missing (no analysis)
    param_bounds : (n_par, 2), physical range of each parameter's ensemble mean;
        leaving it stops the run (default: :meth:`TissueFilterSetup.default_param_bounds`)

    Returns
    -------
    TissueEstimates; if the filter diverges, the estimates up to that point with
    ``diverged`` set to the message.
    """
    pieces = _assemble(setup, param_bounds, float(times[0]) if len(times) else None)
    problem = pieces.problem(times, data)
    P_track, n = pieces.P_track, pieces.n
    M = len(times)
    tr_mean = np.full((M + 1, P_track.shape[0]), np.nan)
    tr_std = np.full_like(tr_mean, np.nan)

    def record(rep: StepReport):
        Y = (P_track @ rep.state_ensemble.T).T
        tr_mean[rep.step] = Y.mean(axis=0)
        tr_std[rep.step] = Y.std(axis=0, ddof=1)
        if callback is not None:
            callback(rep)

    t0 = time.perf_counter()
    diverged = None
    try:
        # the filter's dense products are small (50 x 5000): threaded BLAS only spins, and
        # on a busy machine it is 20-30 times slower (measured); numba kernels keep the cores
        with blas_threads(1):
            res = run_filter(problem, pieces.config, health=pieces.health, callback=record)
    except FilterDivergence as err:
        res = err.result
        diverged = str(err)
    wall = time.perf_counter() - t0
    k = len(res.times)
    return TissueEstimates(
        times=res.times, names=setup.estimate, param_mean=res.param_mean[:, :n],
        param_std=res.param_std[:, :n],
        tracked_positions=setup.tracked_positions, tracked_mean=tr_mean[:k],
        tracked_std=tr_std[:k], analysed=res.analysed, step_latency_s=res.step_latency_s,
        filter_wall_s=wall, result=res, diverged=diverged)


@dataclass
class OnlineEstimate:
    """The filter's state after one reading (physical units; see TissueEstimates)."""

    time: float
    param_mean: np.ndarray  #: (n_par,)
    param_std: np.ndarray  #: (n_par,)
    tracked_mean: np.ndarray  #: (n_tracked,) deg C
    tracked_std: np.ndarray  #: (n_tracked,) deg C
    analysed: bool
    latency_s: float  #: wall time of this update


class OnlineIdentifier:
    """The filter one reading at a time, for a live sensor (``identify --follow``).

    Each :meth:`update` forecasts the ensemble from the previous reading's time to the
    new one and assimilates the new reading (NaN entries are skipped), so the estimate
    is ready before the next frame arrives. The random numbers of reading ``k`` come
    from ``(setup.seed, k)``: a replay of the same readings gives the same estimates
    (they differ from :func:`identify`'s, which draws from one stream).

    Raises :class:`~enkf.driver.FilterDivergence` when the health check stops the
    filter (the estimates so far stay in :attr:`history`).
    """

    def __init__(self, setup: TissueFilterSetup, *, param_bounds=None, dt_hint: float = 0.1):
        self.setup = setup
        self._pieces = _assemble(setup, param_bounds, dt_hint)
        rng = np.random.default_rng([setup.seed, 0])
        self._X, self._theta = self._pieces.prior(rng, setup.n_members)
        self.time = 0.0
        self.history: list[OnlineEstimate] = []
        self.names = setup.estimate
        self.n_obs = self._pieces.P_obs.shape[0]

    def update(self, t: float, y) -> OnlineEstimate:
        """Assimilate the reading ``y`` ((p,) deg C, NaN = missing) taken at ``t`` (s)."""
        t = float(t)
        if not np.isfinite(t) or t <= self.time:
            raise ValueError(f"reading time must be finite and after {self.time} s, got {t!r}")
        y = np.asarray(y, float).reshape(-1)
        if y.shape != (self.n_obs,):
            raise ValueError(f"a reading must hold {self.n_obs} values (sensors then pixels), "
                             f"got {y.size}")
        X, theta = self._X, self._theta
        problem = self._pieces.problem(np.array([t]), y[None, :],
                                       prior=lambda rng, N: (X, theta), t0=self.time)
        seed = int(np.random.SeedSequence([self.setup.seed, len(self.history) + 1])
                   .generate_state(1)[0])
        config = replace(self._pieces.config, seed=seed)
        tic = time.perf_counter()
        with blas_threads(1):
            res = run_filter(problem, config, health=self._pieces.health)
        self._X, self._theta = res.state_ensemble, res.param_ensemble
        Y = (self._pieces.P_track @ self._X.T).T
        n = self._pieces.n
        est = OnlineEstimate(t, res.param_mean[-1, :n], res.param_std[-1, :n], Y.mean(axis=0),
                             Y.std(axis=0, ddof=1), bool(res.analysed[-1]),
                             time.perf_counter() - tic)
        self.time = t
        self.history.append(est)
        return est
