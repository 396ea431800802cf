"""What the tissue filter needs: the grid, the absorption model, the laser, priors, noise."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

import fem

from ..checks import fraction
from ..problem import DEFAULT_METHOD
from .absorption import Absorption
from .parameters import (
    ESTIMATES,
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    default_bounds,
    default_prior,
    parameter_names,
    tracked_points,
)

__all__ = ["TissueFilterSetup"]


#: instants between two readings at which ``smoother_restarts = "laser_off"`` looks for
#: the end of a pulse (:meth:`TissueFilterSetup.restart_after`): pulses and pauses longer
#: than 1/64 of the readings' interval are seen
RESTART_PROBES = 64


@dataclass
class TissueFilterSetup:
    """Everything the filter's forward model and the filter need.

    Parameters
    ----------
    grid : fem.BoxGrid
        The filter's coarse voxel grid (also the emulator's grid).
    absorption : Absorption or callable
        An :class:`~enkf.tissue.absorption.Absorption` (the emulator
        :class:`~mcmatlab_py.emulator.AbsorptionEmulator` or its exact mode), or a plain
        ``absorption(mua (N,), mus (N,)) -> NA (N, nx, ny, nz)`` in W/cm^3/W.
    power : callable
        ``power(t) -> W``, the laser power at time ``t`` (s), e.g.
        :meth:`mcmatlab_py.heat.HeatSimulation.laser_power` (whose schedule then also
        gives each heat step its energy: :meth:`mean_power`).
    nominal : dict
        Nominal values of mua, mus (cm^-1), VHC (J cm^-3 K^-1), TC (W cm^-1 K^-1):
        VHC and TC are used as known values when not estimated, and the priors are
        ``prior_range`` times the nominal values (unless ``prior`` names the parameter).
    estimate : tuple of str
        ``("mua", "mus")`` or ``("mua", "mus", "VHC", "TC")``; with a second estimated
        medium (a :class:`~mcmatlab_py.emulator_media.TwoMediaEmulator` as absorption, e.g.
        epidermis and dermis) ``("mua", "mus", "mua2", "mus2")``, optionally followed by
        ``"VHC", "TC"``; ``nominal`` then also holds ``mua2`` and ``mus2``.
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
        measured on similar tissue). Only estimated parameters may be named (with
        ``parameter_model="coagulation"`` also ``mua_coag`` and ``mus_coag``).
    coagulation : enkf.tissue.coagulation.Coagulation, optional
        The Arrhenius law and nominal coagulated optics of
        ``parameter_model="coagulation"`` (default: ``Coagulation()``).
    """

    grid: fem.BoxGrid
    absorption: Absorption | Callable
    power: Callable[[float], float]
    nominal: dict
    estimate: tuple = ("mua", "mus")
    sensor_positions: np.ndarray = field(default_factory=lambda: np.zeros((1, 3)))
    sensor_noise_var: float | np.ndarray = 0.01
    image: object = None  #: enkf.image.ThermalImage or None
    localization_radius: float | None = None  #: cm, or None for no localization
    tracked_positions: np.ndarray = field(default_factory=tracked_points)
    T_initial: float = 0.0  #: deg C
    heat_boundary: fem.HeatBoundary = field(default_factory=fem.HeatBoundary)
    prior_range: tuple[float, float] = (0.5, 2.0)
    prior: dict = field(default_factory=dict)  #: {name: (lo, hi)} in physical units
    model_noise_std: float = 0.002  #: deg C per step, C = std^2 I (the white floor)
    #: "white" (default, the paper): the floor alone. "structured": the white floor plus a
    #: relative error of each step's tendency, correlated over depth and time
    #: (enkf.tissue.model_error.StructuredModelError, sized from the coarse model against
    #: independent models): honest bands for constant tissue on data from another model
    #: (validation/reports/model_error_coverage.md); not yet validated for drifting optics,
    #: where it slowed the parameters' drift in the first runs, so it is not the default
    model_error: str = "white"
    model_error_rel_std: float = 0.05  #: sd of the relative error of a step's tendency
    model_error_time_scale: float = 3.0  #: s, its correlation time
    model_error_length_xy: float = 0.1  #: cm, its correlation length across
    model_error_length_z: float = 0.05  #: cm, its correlation length down
    #: estimate a factor on the forecast's temperature covariance from the innovations
    #: (enkf.adaptive): the model error's size is then checked against the data. Off by
    #: default until validated for drifting optics (on in examples/own_data.toml)
    adaptive_inflation: bool = False
    adaptive_inflation_bounds: tuple[float, float] = (1.0, 25.0)  #: of the covariance factor
    adaptive_inflation_time_scale: float = 30.0  #: analysed steps averaged over
    random_walk_std: float | Sequence[float] = 0.002  #: log units per step, E = std^2 I
    #: factor on the random walk for steps with the laser off: 0 (default) holds the
    #: parameters still when nothing heats the tissue, which is what changes them (and, with
    #: the laser off, they no longer act on the forecast, so the data cannot hold a walk
    #: back: with the drifting walk [0.03, 0.10] and 1 here mus ended at 626 +- 771 cm^-1,
    #: issue #18); 1 walks always (the paper)
    random_walk_when_off: float = 0.0
    #: "random_walk" (the paper): log theta_(n+1) = log theta_n + xi. "trend": a local
    #: linear trend, log theta_(n+1) = log theta_n + v_n dt + xi, v_(n+1) = v_n + eta,
    #: with the rates v (1/s, in log units) filtered beside the parameters: a smooth
    #: drift (heating that changes the tissue steadily) is followed with a much smaller
    #: walk, so the data of many steps add up instead of being forgotten.
    #: "coagulation": each member's optics move from native (mua, mus) to coagulated
    #: (mua_coag, mus_coag) values with its own Arrhenius damage (enkf.tissue.coagulation);
    #: the four are estimated, with the random walk on top
    parameter_model: str = "random_walk"
    coagulation: object = None  #: enkf.tissue.coagulation.Coagulation (its defaults: None)
    trend_prior_std: float = 0.2  #: 1/s, prior spread of each rate v (mean 0)
    trend_noise_std: float | Sequence[float] = 0.02  #: 1/s per step, std of eta
    #: deg C: the prior sd of an unknown calibration offset of each point sensor, estimated
    #: with the parameters (one per sensor, N(0, sd^2) at the start, constant; added to the
    #: model's readings). 0 (default): the sensors are calibrated. A real sensor that reads
    #: 0.3 deg C high otherwise pulls the optics until the model fits the offset
    sensor_offset_std: float = 0.0
    n_members: int = 50
    method: str = DEFAULT_METHOD  #: "etkf" or "enkf" (see enkf.problem.FilterConfig)
    inflation: float = 1.0
    #: relaxation of the temperatures' analysis spread back towards the forecast's, alpha
    #: in [0, 1] (Whitaker & Hamill 2012; enkf.analysis.relax_to_prior_spread): 0 = none
    rtps: float = 0.0
    mda: int = 1  #: analysis iterations per step (see enkf.driver.FilterConfig.mda)
    seed: int = 0
    #: time scheme of the forecast's heat steps: 0.5 (default) Crank-Nicolson, 1 backward
    #: Euler. At the readings' 0.1 s, backward Euler lags the rise and the fall of the
    #: temperature by up to 0.6% of the peak (0.11 deg C at the paper's surface, 0.43 in its
    #: drifting case), an error the optics then take up: on data from independent model A
    #: the camera's mus came out 4.1% off with backward Euler, 1.5% with Crank-Nicolson
    #: (validation/reports/coarse_model_error.md, "The time scheme"; docs/enkf.md).
    #: Crank-Nicolson has the same cost per step
    theta: float = 0.5
    #: s, the longest heat step of the forecast (``[HS] dt`` in a config): an interval between
    #: readings longer than this is split into equal sub-steps. None: one step per interval
    max_dt: float | None = None
    #: "kronecker" (default): the tensor-product operator of :class:`fem.HeatStepper`, equal
    #: to P1 away from the box edges, with no per-member cost when VHC and TC are estimated;
    #: "p1": the exact P1 matrices (an edge correction per new pair of member scales)
    heat_operator: str = "kronecker"
    #: 1-D mass of the tensor-product operator: "averaged" (default) cancels the leading
    #: discretization error of the lumped mass; at the paper's true parameters the
    #: 20 x 20 x 10 surface temperature is then within 0.1% of the fine truth instead of
    #: 1.1% cold (validation/reports/coarse_model_error.md). "lumped" is the P1 lumped mass.
    heat_mass: str = "averaged"
    #: restarts of the filter from the smoother: after the first reading at or after each
    #: of these times (s), or at or after the end of each laser pulse (``"laser_off"``), the
    #: parameter ensemble is replaced by the ES-MDA smoother's over every reading so far
    #: (from the prior; enkf.tissue.identify.restart_ensemble) and the members' temperatures
    #: are re-run to that time with their new optics; then the filter goes on. The
    #: sequential updates lose information on a curved mua-mus ridge; the restart brings it
    #: back (docs/enkf.md, "Restarts"). Needs ``parameter_model = "random_walk"``, with
    #: ``random_walk_std = 0`` unless ``smoother_restart_knots >= 2``, and no sensor
    #: offsets. () (default): none
    smoother_restarts: tuple | str = ()
    smoother_restart_iterations: int = 8  #: ES-MDA updates of each restart
    #: s, with ``"laser_off"``: restart after the first reading at or after this long past
    #: the end of each pulse. Drifting optics (``smoother_restart_knots >= 2``) need some
    #: cooling readings to tell their final values (the end of a window is its least
    #: determined part): 2.5 s after a 5 s pulse in docs/enkf.md, "Restarts"
    smoother_restart_delay: float = 0.0
    #: 1 (default): constant optics (smooth_constant; needs random_walk_std = 0). 2 or more:
    #: optics drifting while heated, piecewise linear in heated time through that many
    #: values (smooth_drifting); the restart takes their value at its reading, and the
    #: filter's walk goes on from there. Several counts, e.g. (2, 3): the restarted
    #: ensemble is an equal mixture of the smoothers of those forms of the drift, each
    #: giving a block of members (the form is not known; docs/enkf.md, "Which form of the
    #: drift")
    smoother_restart_knots: int | tuple = 1
    #: the restarts' model discrepancy (relative sd of the rise; smooth_constant's
    #: ``discrepancy``) and its correlation time (s): 0 for identical twins
    smoother_restart_discrepancy: float = 0.0
    smoother_restart_discrepancy_time: float = 2.0
    #: True (default): the restarted members are a log-normal draw with the smoother's
    #: ensemble's log mean and covariance (enkf.tissue.identify.gaussian_ensemble): the
    #: ETKF's updates keep an ensemble's shape, and the smoother's skew made the quantile
    #: bands miss (75-80% on the layered twins, 90-95% with it). False: its members as they are
    smoother_restart_gaussian: bool = True
    #: whether the optics drift is told by the data: a :class:`~enkf.tissue.drift.DriftBank`
    #: runs this setup's filter (optics still) beside one whose optics drift while heated,
    #: and reports their mixture under the evidence (the command line's default). None
    #: (default here): this setup's filter alone
    drift: object = None

    def __post_init__(self):
        est = tuple(self.estimate)
        if est not in ESTIMATES:
            raise ValueError(f"estimate must be one of {ESTIMATES}, got {self.estimate!r}")
        self.estimate = est
        for name in dict.fromkeys(PARAMETER_NAMES + est):
            v = self.nominal.get(name)
            if v is None or not np.isfinite(v) or v <= 0:
                raise ValueError(f"nominal[{name!r}] must be > 0 ({PARAMETER_UNITS[name]}), "
                                 f"got {v!r}")
        lo, hi = self.prior_range
        if not 0 < lo < hi:
            raise ValueError(f"prior_range must be (lo, hi) with 0 < lo < hi, got "
                             f"{self.prior_range!r}")
        if self.parameter_model not in ("random_walk", "trend", "coagulation"):
            raise ValueError(f"parameter_model must be 'random_walk', 'trend' or 'coagulation', "
                             f"got {self.parameter_model!r}")
        for extra, what in (("mua2", "a second estimated medium (mua2, mus2)"),
                            ("beam_radius", "the beam's radius")):
            if extra in est and self.parameter_model != "random_walk":
                raise ValueError(f"parameter_model = {self.parameter_model!r} is not built for "
                                 f"{what}: use 'random_walk'")
        if self.parameter_model == "coagulation":
            from .coagulation import Coagulation

            if self.coagulation is None:
                self.coagulation = Coagulation()
            elif not isinstance(self.coagulation, Coagulation):
                raise ValueError(f"coagulation must be an enkf.tissue.coagulation.Coagulation, "
                                 f"got {type(self.coagulation).__name__}")
        names = self.parameter_names
        self.prior = dict(self.prior or {})
        for name, rng in self.prior.items():
            if name not in names:
                raise ValueError(f"prior[{name!r}]: {name} is not estimated (parameters = "
                                 f"{names})")
            try:
                p_lo, p_hi = (float(v) for v in rng)
            except (TypeError, ValueError):
                raise ValueError(f"prior[{name!r}] must be (lo, hi) in "
                                 f"{PARAMETER_UNITS[name]}, got {rng!r}") from None
            if not (np.isfinite(p_hi) and 0 < p_lo < p_hi):
                raise ValueError(f"prior[{name!r}] must be (lo, hi) with 0 < lo < hi "
                                 f"({PARAMETER_UNITS[name]}), got {rng!r}")
            self.prior[name] = (p_lo, p_hi)
        fraction(self.rtps, "rtps")
        self.sensor_positions = np.asarray(self.sensor_positions, float).reshape(-1, 3)
        if self.sensor_positions.shape[0] == 0 and self.image is None:
            raise ValueError("sensor_positions is empty and there is no image: nothing observed")
        if self.localization_radius is not None and not (
                np.isfinite(self.localization_radius) and self.localization_radius > 0):
            raise ValueError(f"localization_radius must be > 0 (cm) or None, got "
                             f"{self.localization_radius!r}")
        self.tracked_positions = np.atleast_2d(np.asarray(self.tracked_positions, float))
        if self.max_dt is not None and not (np.isfinite(self.max_dt) and self.max_dt > 0):
            raise ValueError(f"max_dt must be > 0 (s) or None, got {self.max_dt!r}")
        if self.sensor_offset_std and self.sensor_positions.shape[0] == 0:
            raise ValueError(f"sensor_offset_std = {self.sensor_offset_std!r} needs point sensors "
                             "(sensor_positions is empty)")
        if isinstance(self.theta, bool) or not (isinstance(self.theta, (int, float))
                                                 and 0.5 <= float(self.theta) <= 1.0):
            raise ValueError(f"theta must be in [0.5, 1] (0.5: Crank-Nicolson, 1: backward "
                             f"Euler), got {self.theta!r}")
        if self.model_error not in ("structured", "white"):
            raise ValueError(f"model_error must be 'structured' or 'white', got "
                             f"{self.model_error!r}")
        self._check_restarts()
        self._check_drift()
        for name in ("model_noise_std", "trend_prior_std", "model_error_rel_std", "sensor_offset_std",
                     "model_error_time_scale", "model_error_length_xy", "model_error_length_z"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")

    def _check_drift(self) -> None:
        if self.drift is None:
            return
        from .drift import DriftBank

        if not isinstance(self.drift, DriftBank):
            raise ValueError(f"drift must be an enkf.tissue.drift.DriftBank or None, got "
                             f"{type(self.drift).__name__}")
        if self.parameter_model != "random_walk":
            raise ValueError(f"drift (a bank of a still and a drifting filter) needs "
                             f"parameter_model = 'random_walk', got {self.parameter_model!r}: "
                             "set drift = None for the trend or coagulation model")


    def _check_restarts(self) -> None:
        r = self.smoother_restarts
        if isinstance(r, str):
            if r != "laser_off":
                raise ValueError(f"smoother_restarts must be times (s) or 'laser_off', got {r!r}")
        else:
            try:
                t = np.asarray(r, float).reshape(-1)
            except (TypeError, ValueError):
                raise ValueError(f"smoother_restarts must be times (s) or 'laser_off', got "
                                 f"{r!r}") from None
            if not (np.all(np.isfinite(t)) and np.all(t > 0) and np.all(np.diff(t) > 0)):
                raise ValueError(f"smoother_restarts must be increasing times > 0 (s), got {r!r}")
            self.smoother_restarts = tuple(float(v) for v in t)
            if not t.size:
                return
        n = self.smoother_restart_iterations
        if not (isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 1):
            raise ValueError(f"smoother_restart_iterations must be an integer >= 1, got {n!r}")
        forms = self.smoother_restart_knots
        forms = tuple(forms) if isinstance(forms, (list, tuple)) else (forms,)
        if not forms or not all(isinstance(k, (int, np.integer)) and not isinstance(k, bool)
                                and k >= 1 for k in forms):
            raise ValueError(f"smoother_restart_knots must be an integer >= 1 or a list of "
                             f"them, got {self.smoother_restart_knots!r}")
        if len(forms) > 1 and (min(forms) < 2 or len(set(forms)) < len(forms)):
            raise ValueError(f"smoother_restart_knots = {list(forms)}: a mixture of drift forms "
                             "needs different counts of knots, each >= 2")
        self.smoother_restart_knots = int(forms[0]) if len(forms) == 1 else tuple(
            int(k) for k in forms)
        if not isinstance(self.smoother_restart_gaussian, (bool, np.bool_)):
            raise ValueError(f"smoother_restart_gaussian must be True or False, got "
                             f"{self.smoother_restart_gaussian!r}")
        if self.smoother_restart_delay and not isinstance(r, str):
            raise ValueError(f"smoother_restart_delay = {self.smoother_restart_delay!r} is for "
                             "smoother_restarts = 'laser_off'")
        for name in ("smoother_restart_discrepancy", "smoother_restart_discrepancy_time",
                     "smoother_restart_delay"):
            v = getattr(self, name)
            if not (np.isfinite(v) and (v > 0 if name.endswith("time") else v >= 0)):
                raise ValueError(f"{name} must be {'> 0 (s)' if name.endswith('time') else '>= 0'}"
                                 f", got {v!r}")
        walk = np.asarray(self.random_walk_std, float)
        if self.parameter_model != "random_walk" or (
                not self.restart_drifts and np.any(walk != 0)):
            raise ValueError(f"smoother_restarts needs constant optics (parameter_model = "
                             f"'random_walk', random_walk_std = 0) or drifting ones "
                             f"(smoother_restart_knots >= 2), got parameter_model = "
                             f"{self.parameter_model!r}, random_walk_std = "
                             f"{self.random_walk_std!r}")
        if self.sensor_offset_std:
            raise ValueError("smoother_restarts does not estimate sensor offsets: set "
                             "sensor_offset_std = 0")
        drifting = self.restart_drifting
        if self.restart_drifts and not drifting:
            raise ValueError(f"smoother_restart_knots = {self.smoother_restart_knots} is for "
                             "drifting optics: no parameter walks (random_walk_std = "
                             f"{self.random_walk_std!r})")
        free = len(self.parameter_names) + (max(self.restart_knot_forms) - 1) * len(drifting)
        if self.smoother_restart_gaussian and self.n_members < 2 * len(self.restart_knot_forms):
            raise ValueError(f"a mixture of {len(self.restart_knot_forms)} drift forms needs "
                             f"at least 2 members per form, got n_members = {self.n_members}")
        if self.smoother_restart_gaussian and self.n_members <= free:
            raise ValueError(f"smoother_restart_gaussian needs more members than the restart's "
                             f"free values ({free}: the parameters, and every knot of the "
                             f"drifting ones), got n_members = {self.n_members}")

    @property
    def restart_knot_forms(self) -> tuple:
        """The restarts' counts of knots, one per form of the drift (:attr:`smoother_restart_knots`)."""
        k = self.smoother_restart_knots
        return tuple(k) if isinstance(k, tuple) else (int(k),)

    @property
    def restart_drifts(self) -> bool:
        """Whether the restarts let the optics drift (knots >= 2)."""
        return max(self.restart_knot_forms) > 1

    @property
    def restart_drifting(self) -> tuple:
        """The parameters a drifting restart (``smoother_restart_knots >= 2``) lets drift:
        those whose random walk is not 0."""
        walk = np.broadcast_to(np.asarray(self.random_walk_std, float),
                               (len(self.parameter_names),))
        return tuple(n for n, w in zip(self.parameter_names, walk, strict=True) if w > 0)

    def mean_power(self, t0: float, t1: float) -> float:
        """W over the heat step ``[t0, t1)`` (s): the schedule's average where ``power`` is a
        :meth:`~mcmatlab_py.heat.HeatSimulation.laser_power` (its ``mean_laser_power``: a
        pulse that starts or ends inside the step gives it the energy delivered), else
        ``power`` at the step's middle."""
        owner = getattr(self.power, "__self__", None)
        mean = getattr(owner, "mean_laser_power", None)
        if mean is not None and getattr(self.power, "__name__", "") == "laser_power":
            return float(mean(t0, t1))
        return self.power(0.5 * (t0 + t1))

    def restart_after(self, t_prev: float, t: float) -> bool:
        """Whether the filter restarts from the smoother after the reading at ``t`` (s), the
        reading before it at ``t_prev`` (:attr:`smoother_restarts`): ``t`` is the first
        reading at or after a restart time, or a pulse ended in ``(t_prev - d, t - d]``
        (the first reading at or after the end of a pulse plus ``d =
        smoother_restart_delay``). The laser is looked at just after both ends and at
        :data:`RESTART_PROBES` instants between them, so that a pulse that starts and ends
        between two readings, or a pause shorter than their interval, counts too."""
        r = self.smoother_restarts
        if isinstance(r, str):
            d = self.smoother_restart_delay
            x = np.linspace(t_prev - d, t - d, RESTART_PROBES + 2)
            on = [self.power(v + 1e-9 * max(1.0, abs(v))) > 0 for v in x]
            return any(a and not b for a, b in zip(on[:-1], on[1:], strict=True))
        return any(t_prev < tr <= t for tr in r)

    @property
    def n_sensor_offsets(self) -> int:
        """Offsets estimated beside the parameters: one per point sensor when
        ``sensor_offset_std > 0``, else 0."""
        return self.sensor_positions.shape[0] if self.sensor_offset_std > 0 else 0

    @property
    def parameter_names(self) -> tuple:
        """The filtered parameters in the state's order (:func:`parameter_names`):
        ``estimate``, with ``mua_coag``, ``mus_coag`` after the optics under coagulation."""
        return parameter_names(self.estimate, self.parameter_model)

    def nominal_values(self) -> np.ndarray:
        """Nominal value of each filtered parameter, in :attr:`parameter_names` order (the
        coagulated ones from :meth:`Coagulation.nominal`)."""
        nominal = dict(self.nominal)
        if self.parameter_model == "coagulation":
            nominal.update(self.coagulation.nominal(self.nominal))
        return np.array([nominal[n] for n in self.parameter_names], float)

    def prior_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the uniform prior of each filtered parameter (:attr:`parameter_names`)."""
        pairs = [self.prior.get(n, default_prior(n, v, self.prior_range))
                 for n, v in zip(self.parameter_names, self.nominal_values(), strict=True)]
        return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])

    def default_param_bounds(self) -> np.ndarray:
        """(n_par, 2) health-check range of each mean (:func:`default_bounds`)."""
        return default_bounds(self.nominal_values(), *self.prior_bounds())
