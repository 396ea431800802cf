"""What the tissue filter needs: the problem (grid, absorption, laser, start) and its parts."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

import fem

from ...problem import DEFAULT_METHOD
from ..absorption import Absorption
from ..paths import free_values
from .parameter_model import ParameterModel
from .parts import HeatModel, ModelError, Sensors, SmootherRestarts

__all__ = ["FLAT_NAMES", "RESTART_PROBES", "TissueFilterSetup"]


#: instants between two readings at which restarts at ``"laser_off"`` look for the end of
#: a pulse (:meth:`TissueFilterSetup.restart_after`): pulses and pauses longer than 1/64
#: of the readings' interval are seen
RESTART_PROBES = 64

#: the flat names of :meth:`TissueFilterSetup.build` and :meth:`~TissueFilterSetup.with_`
#: (and of a config's ``[filter]`` and ``[sensors]`` keys): ``name: (part, field)``
FLAT_NAMES = {
    **{k: ("parameters", k) for k in (
        "nominal", "estimate", "prior_range", "prior", "prior_sampling", "random_walk_std",
        "random_walk_when_off", "trend_prior_std", "trend_noise_std", "coagulation", "drift")},
    "parameter_model": ("parameters", "kind"),
    "sensor_positions": ("sensors", "positions"),
    "sensor_noise_var": ("sensors", "noise_var"),
    "image": ("sensors", "image"),
    "sensor_offset_std": ("sensors", "offset_std"),
    "tracked_positions": ("sensors", "tracked"),
    "model_noise_std": ("model_error", "noise_std"),
    "model_error": ("model_error", "kind"),
    **{f"model_error_{k}": ("model_error", k) for k in (
        "rel_std", "time_scale", "length_xy", "length_z")},
    **{k: ("model_error", k) for k in (
        "adaptive_inflation", "adaptive_inflation_bounds", "adaptive_inflation_time_scale",
        "inflation", "rtps")},
    "theta": ("heat", "theta"),
    "max_dt": ("heat", "max_dt"),
    "heat_operator": ("heat", "operator"),
    "heat_mass": ("heat", "mass"),
    "heat_boundary": ("heat", "boundary"),
    "smoother_restarts": ("restarts", "times"),
    **{f"smoother_restart_{k}": ("restarts", k) for k in (
        "iterations", "delay", "knots", "discrepancy", "discrepancy_time", "gaussian")},
}

#: each part's class, by its field in :class:`TissueFilterSetup`
_PARTS = {"parameters": ParameterModel, "sensors": Sensors, "model_error": ModelError,
          "heat": HeatModel, "restarts": SmootherRestarts}


@dataclass
class TissueFilterSetup:
    """Everything the filter's forward model and the filter need: the problem itself and
    its parts.

    Build it from its parts, or from flat names with :meth:`build` (``build(grid=...,
    random_walk_std=0.03, sensor_offset_std=0.5, ...)``, the names of :data:`FLAT_NAMES`);
    :meth:`with_` changes a few settings by those names.

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
    parameters : ParameterModel
        Which parameters are estimated, their priors and walks.
    sensors : Sensors
        What is observed, and the points whose temperature is reported.
    model_error : ModelError
        The forecast's error, inflation and relaxation to prior spread.
    heat : HeatModel
        The forecast's time scheme, heat operator and boundaries.
    restarts : SmootherRestarts
        Restarts of the filter from the smoother (default: none).
    T_initial : float
        deg C, the known initial temperature.
    n_members : int
        Ensemble size N (the paper: 50).
    method : str
        ``"etkf"`` or ``"enkf"`` (:class:`enkf.problem.FilterConfig`).
    mda : int
        Analysis iterations per step (:attr:`enkf.problem.FilterConfig.mda`).
    seed : int
        The run's seed: the same seed gives the same numbers.
    localization_radius : float, optional
        cm: covariance localization (Gaspari-Cohn taper, zero beyond this distance)
        between temperatures and observations; the parameters stay global. Needs
        ``method="enkf"``. None: no localization.
    """

    # the ensemble's settings (n_members ... localization_radius) stay here rather than in
    # a part of their own: they are few, read everywhere, and FilterConfig's own names
    grid: fem.BoxGrid
    absorption: Absorption | Callable
    power: Callable[[float], float]
    parameters: ParameterModel
    sensors: Sensors = field(default_factory=Sensors)
    model_error: ModelError = field(default_factory=ModelError)
    heat: HeatModel = field(default_factory=HeatModel)
    restarts: SmootherRestarts = field(default_factory=SmootherRestarts)
    T_initial: float = 0.0
    n_members: int = 50
    method: str = DEFAULT_METHOD
    mda: int = 1
    seed: int = 0
    localization_radius: float | None = None

    def __post_init__(self):
        for name, cls in _PARTS.items():
            if not isinstance(getattr(self, name), cls):
                raise ValueError(f"{name} must be a {cls.__name__}, got "
                                 f"{type(getattr(self, name)).__name__}")
        if self.localization_radius is not None and not (
                np.isfinite(self.localization_radius) and self.localization_radius > 0):
            raise ValueError(f"localization_radius must be > 0 (cm) or None, got "
                             f"{self.localization_radius!r}")
        self._check_restarts()

    @classmethod
    def build(cls, **kw) -> TissueFilterSetup:
        """A setup from flat names: this class's own fields, and each part's by its name in
        :data:`FLAT_NAMES` (e.g. ``random_walk_std``, ``sensor_positions``,
        ``smoother_restart_knots``), as a config's ``[filter]`` and ``[sensors]`` keys."""
        own, parts = _route(kw)
        for name, part_kw in parts.items():
            if name in own:
                raise ValueError(f"{name} is given both as a part and by its fields "
                                 f"{sorted(part_kw)}")
            own[name] = _PARTS[name](**part_kw)
        return cls(**own)

    def with_(self, **changes) -> TissueFilterSetup:
        """A copy with ``changes`` by flat names (:meth:`build`'s), each part checked again:
        ``setup.with_(random_walk_std=0.03, smoother_restarts="laser_off")``."""
        own, parts = _route(changes)
        for name, part_kw in parts.items():
            own[name] = dataclasses.replace(own.get(name, getattr(self, name)), **part_kw)
        return dataclasses.replace(self, **own)

    def _check_restarts(self) -> None:
        """What ties the restarts to the other parts: the parameter model, the sensors'
        offsets and the ensemble's size."""
        rs, par = self.restarts, self.parameters
        if not rs.times:
            return
        if par.kind != "random_walk" or (not rs.drifts and np.any(par.walk_std() != 0)):
            raise ValueError(f"smoother_restarts needs constant optics (parameter_model = "
                             f"'random_walk', random_walk_std = 0) or drifting ones "
                             f"(smoother_restart_knots >= 2), got parameter_model = "
                             f"{par.kind!r}, random_walk_std = {par.random_walk_std!r}")
        if self.sensors.offset_std:
            raise ValueError("smoother_restarts does not estimate sensor offsets: set "
                             "sensor_offset_std = 0")
        drifting = par.walking
        if rs.drifts and not drifting:
            raise ValueError(f"smoother_restart_knots = {rs.knots} is for drifting optics: no "
                             f"parameter walks (random_walk_std = {par.random_walk_std!r})")
        forms = rs.knot_forms
        free = max(free_values(k, len(par.names), len(drifting)) for k in forms)
        if rs.gaussian and self.n_members < 2 * len(forms):
            raise ValueError(f"a mixture of {len(forms)} drift forms needs at least 2 members "
                             f"per form, got n_members = {self.n_members}")
        if rs.gaussian and self.n_members <= free:
            raise ValueError(f"smoother_restart_gaussian needs more members than the restart's "
                             f"free values ({free}: the parameters, and every knot of the "
                             f"drifting ones), got n_members = {self.n_members}")

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
        reading before it at ``t_prev`` (:attr:`SmootherRestarts.times`): ``t`` is the first
        reading at or after a restart time, or a pulse ended in ``(t_prev - d, t - d]``
        (the first reading at or after the end of a pulse plus ``d =
        restarts.delay``). The laser is looked at just after both ends and at
        :data:`RESTART_PROBES` instants between them, so that a pulse that starts and ends
        between two readings, or a pause shorter than their interval, counts too."""
        r = self.restarts.times
        if isinstance(r, str):
            d = self.restarts.delay
            x = np.linspace(t_prev - d, t - d, RESTART_PROBES + 2)
            on = [self.power(v + 1e-9 * max(1.0, abs(v))) > 0 for v in x]
            return any(a and not b for a, b in zip(on[:-1], on[1:], strict=True))
        return any(t_prev < tr <= t for tr in r)


def _route(kw: dict) -> tuple[dict, dict]:
    """``kw`` by flat names -> (this class's own fields, ``{part: {field: value}}``);
    ``model_error`` is the part when given one, else its ``kind`` (a config's name)."""
    own_names = {f.name for f in dataclasses.fields(TissueFilterSetup)}
    own, parts = {}, {}
    for k, v in kw.items():
        if k in own_names and not (k in FLAT_NAMES and not isinstance(v, _PARTS[k])):
            own[k] = v
        elif k in FLAT_NAMES:
            part, name = FLAT_NAMES[k]
            parts.setdefault(part, {})[name] = v
        else:
            raise TypeError(f"TissueFilterSetup has no setting {k!r} (its fields, or the "
                            f"flat names of FLAT_NAMES)")
    return own, parts
