"""TOML -> identification run: the model, the sensors, the filter (an edge module).

One file describes everything ``tissue-enkf identify`` needs; the names follow the
Python API (``model.G``, ``model.MC``, ``model.HS`` as in MCmatlab, then
:class:`~enkf.tissue.TissueFilterSetup`)::

    [G] ... [[G.media]] ... [MC] ... [MC.light_source] ...   # as for `tissue-enkf mc`
    [HS]                      # laser and heat: P, duration_on, duration_off, n_pulses,
                              # T_initial, heat_boundary_type, ...
    [sensors]
    positions = [[0.0, 0.0, 0.0]]   # cm, one row per data column after `time`
    noise_var = 0.01                # deg C^2 (D)
    tracked = [[0, 0, 0], [0, 0, 0.1], [0, 0, 0.2]]   # reported temperatures
    [sensors.camera]                # optional: a thermal image (pixels after the sensors)
    x_range = [-0.2, 0.2]
    y_range = [-0.2, 0.2]
    shape = [16, 16]
    model_error_rel_std = 0.04      # the model's error per pixel, of the predicted rise,
    model_error_lengths = [0.02, 0.1]   # at each correlation length (cm; docs/beyond.md)
    [filter]
    n_members = 50
    method = "etkf"                 # or "enkf" (perturbed observations)
    estimate = ["mua", "mus"]       # or all four with "VHC", "TC"
    medium = "dermis"               # with several media: the one estimated (name or index),
                                    # or two: ["dermis", "epidermis"] estimates mua2, mus2 too
    grid = [20, 20, 10]             # the filter's coarse voxels
    prior_range = [0.5, 2.0]        # uniform prior, times the estimated medium's values
    ...
    [filter.coagulation]            # with parameter_model = "coagulation" (optics follow
    E = 422.5e3                     # each member's damage): Arrhenius E J/mol, A 1/s,
    A = 7.6e66                      # nominal coagulated (mua, mus) / native
    nominal_factor = [1.5, 3.0]
    weight_exponent = 2.0           # F weighs the nodes by (absorbed power)**this
    mean_field_rel_std = 0.25       # model error added per unit of F (structured only)
    [filter.emulator]
    method = "table"                # or "white" (one run per mus: docs/white_mc.md)
    n_photons = 250000
    n_mua = 12
    n_mus = 12

Every key is checked on load: an unknown key, a wrong type or a bad value raises
:class:`~mcmatlab_py.config.ConfigError` naming the key, the value and what is allowed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from fem.checks import check_number, shorten
from mcmatlab_py import NotBuiltError
from mcmatlab_py.budget import check_filter, check_steps
from mcmatlab_py.config import ConfigError, check_keys, model_from_config, read_toml

from ..problem import DEFAULT_METHOD
from ..tissue.parameters import (
    COAGULATION_NAMES,
    ESTIMATES,
    PARAMETER_NAMES,
    SECOND_MEDIUM_NAMES,
    TRACKED_DEPTHS,
    tracked_points,
)
from ..tissue.smooth import MODE_SEARCH
from .config_camera import CAMERA_KEYS, camera_settings
from .readers import apply_time_offset, load_frames, read_sensor_csv

__all__ = ["DataSpec", "IdentifyConfig", "check_identify_keys", "identify_config_from_dict",
           "load_identify"]


@dataclass
class DataSpec:
    """The ``[data]`` table: where the measurements are and how to read them."""

    file: Path | None = None  #: default data file (``--data`` wins), relative to the config
    columns: list | None = None  #: CSV header names, in the order of sensors.positions
    time_offset: float | None = None  #: s, the laser's start on the data's clock

_SENSOR_KEYS = {"positions", "noise_var", "tracked", "camera", "rate"}
_CAMERA_KEYS = CAMERA_KEYS
_FILTER_KEYS = {
    "n_members", "method", "estimate", "grid", "prior_range", "model_noise_std",
    "random_walk_std", "random_walk_when_off", "inflation", "rtps", "mda", "seed",
    "parameter_model",
    "localization_radius", "heat_mass", "transforms", "emulator", "bounds", "prior",
    "model_error", "adaptive_inflation", "coagulation", "medium", "sensor_offset_std",
    "smoother_iterations", "smoother_knots", "smoother_discrepancy",
    "smoother_discrepancy_time", "smoother_importance", "smoother_modes", "smoother_restarts",
    "smoother_restart_iterations", "smoother_restart_gaussian", "smoother_restart_knots",
    "smoother_restart_delay", "drift",
}
_MODEL_ERROR_KEYS = {"kind", "rel_std", "time_scale", "length_xy", "length_z"}
_ADAPTIVE_KEYS = {"enabled", "bounds", "time_scale"}
_LASER_KEYS = ("P", "duration_on", "T_initial")
_DATA_KEYS = {"file", "columns", "time_offset"}
_EMULATOR_KEYS = {"n_photons", "n_mua", "n_mus", "mua_range", "mus_range", "seed", "exact",
                  "method", "on_demand", "mua2_range", "mus2_range", "media_nodes",
                  "radius_range", "radius_nodes"}


@dataclass
class IdentifyConfig:
    """A parsed identification config: the model (G, MC, HS) and the filter's settings."""

    model: object
    setup_kw: dict  #: TissueFilterSetup arguments, without grid/absorption/power/nominal
    grid: tuple  #: the filter's coarse voxels
    emulator_kw: dict
    exact: bool
    raw: dict  #: the parsed TOML (for run.json)
    param_bounds: np.ndarray | None = None  #: (n_par, 2) health-check range, None: default
    data: DataSpec = None  #: the [data] table
    rate: float | None = None  #: Hz, the sensor's nominal rate (sensors.rate)
    medium: int = 0  #: index in G.media of the medium whose parameters are estimated
    #: how the emulator's table is built: "auto" (white where it applies, else table),
    #: "table" (direct Monte Carlo per point) or "white"
    emulator_method: str = "auto"
    #: build each table point the first time a member needs it (the same numbers; a cold
    #: start pays only for the part of the table the ensemble visits), else all at once
    emulator_on_demand: bool = True
    #: ES-MDA updates of the smoother over the whole window after the filter (0: none;
    #: enkf.tissue.smooth_constant or smooth_drifting), reported in summary.json
    smoother_iterations: int = 0
    #: the smoother's ``knots`` (1: constant optics, smooth_constant; >= 2: optics drifting
    #: while heated, smooth_drifting), ``discrepancy`` and ``discrepancy_time`` (s)
    smoother_options: dict = None
    #: index in G.media of a second estimated medium (``filter.medium = [first, second]``:
    #: its optics are the parameters mua2, mus2), None: one
    second_medium: int | None = None
    #: the node grid of the second medium's optics (``filter.emulator.mua2_range``,
    #: ``mus2_range``, ``media_nodes``): TwoMediaEmulator.build's arguments
    media_nodes: dict = None
    #: the node grid of the beam's radius when it is estimated (``filter.emulator.
    #: radius_range``, ``radius_nodes``): BeamRadiusEmulator.build's arguments
    beam_nodes: dict = None
    #: a camera whose spot's centre is estimated from its first frames
    #: (``sensors.camera.spot_center = "auto"``): :class:`~enkf.app.config_camera.
    #: CameraRegistration`, which :meth:`read_data` uses
    camera_registration: object = None
    camera_emissivity: float | None = None  #: replaces a FLIR file's emissivity
    #: the ``[advice]`` table (:class:`~enkf.app.config_advice.AdviceSpec`), None without one
    advice: object = None

    @property
    def n_obs(self) -> int:
        """Data columns after ``time``: the point sensors, then the camera's pixels."""
        kw = self.setup_kw
        return len(kw["sensor_positions"]) + (kw["image"].n_pixels if "image" in kw else 0)

    def read_data(self, path: str | Path) -> tuple[np.ndarray, np.ndarray]:
        """``(times (M,) s, data (M, n_obs) deg C)`` of a CSV, or of an NPZ image series.

        Raises ValueError naming the file and the problem (see :func:`read_sensor_csv`
        and :func:`enkf.app.readers.load_frames`).
        """
        from .frames import FRAME_SUFFIXES

        data = self.data or DataSpec()
        if Path(path).suffix.lower() in FRAME_SUFFIXES or Path(path).is_dir():
            times, values = self._camera_data(path, data)
        else:
            times, values, _ = read_sensor_csv(path, self.n_obs, columns=data.columns,
                                               time_offset=data.time_offset)
        max_dt = self.setup_kw.get("max_dt")
        if max_dt is not None and len(times):
            check_steps(float(times[-1]) / max_dt, f"{path}: the filter's heat steps over "
                        f"{float(times[-1]):g} s of data in steps of HS.dt = {max_dt:g} s", "HS.dt")
        if not np.isfinite(values).any():
            raise ValueError(f"{path}: no usable reading: all {values.size} values are NaN "
                             "(the filter would report its prior as the estimate)")
        return times, values

    def _camera_data(self, path, data: DataSpec) -> tuple[np.ndarray, np.ndarray]:
        """The frames of a camera file or folder (enkf.app.frames), (n, ny*nx) deg C; with
        ``spot_center = "auto"`` the camera is registered from them first."""
        from .frames import read_frames

        if "image" not in self.setup_kw or len(self.setup_kw["sensor_positions"]):
            raise ValueError(f"{path}: camera frames: the config needs [sensors.camera] and no "
                             "point sensors (sensors.positions = [])")
        image = self.setup_kw["image"]
        if Path(path).suffix.lower() == ".npz":
            times, frames = load_frames(path, image, flat=False)
            clock = False
        else:
            series = read_frames(path, rate=self.rate, emissivity=self.camera_emissivity)
            times, frames, clock = series.times, series.frames, series.clock
        if frames.shape[1:] != tuple(int(v) for v in image.shape):
            raise ValueError(f"{path}: frames are {frames.shape[1:]} pixels, the camera "
                             f"(sensors.camera.shape) {list(image.shape)}")
        if self.camera_registration is not None:
            self.setup_kw["image"] = self.camera_registration.estimate(frames, path)
        # times from a clock start at the first frame: the laser's start, unless
        # data.time_offset says otherwise
        offset = 0.0 if clock and data.time_offset is None else data.time_offset
        return apply_time_offset(path, times, frames.reshape(len(times), -1), offset)

    def camera_record(self) -> dict:
        """summary.json's ``camera``: where the spot's centre was found (or nothing)."""
        reg = self.camera_registration
        if reg is None or reg.spot_center is None:
            return {}
        return {"camera": {"spot_center_px": [round(v, 3) for v in reg.spot_center],
                           "estimated_from": "the first frames"}}

    def emulator(self, *, cache_dir=None, progress=True, client=None):
        """The absorption emulator of this model on the filter's mesh (cached)."""
        from mcmatlab_py.emulator import AbsorptionEmulator, DirectMonteCarloAbsorption, EmulatorSpec

        spec = EmulatorSpec.from_model(self.model, medium=self.medium,
                                       mesh_divisions=tuple(self.grid), **self.emulator_kw)
        if self.exact:
            return DirectMonteCarloAbsorption(spec, client=client)
        kw = dict(cache_dir=cache_dir, progress=progress, out_of_range="clamp", client=client,
                  method=self.emulator_method, on_demand=self.emulator_on_demand)
        if self.second_medium is not None:
            from mcmatlab_py.emulator.media import TwoMediaEmulator

            return TwoMediaEmulator.build(spec, self.second_medium, **self.media_nodes, **kw)
        if self.beam_nodes is not None:
            from mcmatlab_py.emulator.media import BeamRadiusEmulator

            return BeamRadiusEmulator.build(spec, **self.beam_nodes, **kw)
        return AbsorptionEmulator.build(spec, **kw)

    def setup(self, absorption, seed: int | None = None):
        """The :class:`~enkf.tissue.TissueFilterSetup` with ``absorption``."""
        import fem

        from ..tissue import TissueFilterSetup

        G, HS = self.model.G, self.model.HS
        m = G.media[self.medium]  # the others keep their values (in the emulator's spec)
        nominal = {"mua": m.mua, "mus": m.mus, "VHC": m.VHC, "TC": m.TC}
        if self.second_medium is not None:
            m2 = G.media[self.second_medium]
            nominal.update(mua2=m2.mua, mus2=m2.mus)
        if self.beam_nodes is not None:
            nominal["beam_radius"] = float(self.model.MC.light_source.radius)
        kw = dict(self.setup_kw)
        if seed is not None:
            kw["seed"] = seed
        boundary = fem.HeatBoundary.from_mcmatlab(
            HS.heat_boundary_type,
            temperature=None if HS.heat_boundary_type != 2 else HS.T_ambient,
            h=HS.heat_transfer_coefficient if HS.heat_boundary_type == 2 else 0.0)
        return TissueFilterSetup(
            grid=fem.BoxGrid(*self.grid, G.Lx, G.Ly, G.Lz), absorption=absorption,
            power=HS.laser_power, nominal=nominal, T_initial=float(HS.T_initial),
            heat_boundary=boundary, **kw)


#: upper limits of the config's numbers: far beyond any use, small enough that nothing
#: overflows (filter.model_noise_std = 1e300 gave a traceback): deg C^2, Hz, deg C, log
#: units, cm, counts, s
_LIMITS = {"sensors.noise_var": 1e4, "sensors.camera.noise_var": 1e4,
           "sensors.camera.model_error_rel_std": 1.0, "sensors.camera.model_error_lengths": 100.0,
           "sensors.rate": 1e6,
           "sensors.camera.shape": 4096, "sensors.camera.subsamples": 64,
           "filter.n_members": 100_000, "filter.grid": 1000, "filter.model_noise_std": 100.0,
           "filter.sensor_offset_std": 100.0,
           "filter.random_walk_std": 10.0, "filter.random_walk_when_off": 10.0,
           "filter.inflation": 100.0, "filter.rtps": 1.0, "filter.localization_radius": 1e3,
           "filter.mda": 100,
           "filter.smoother_iterations": 100, "filter.smoother_knots": 50,
           "filter.smoother_restart_iterations": 100, "filter.smoother_restart_knots": 50,
           "filter.smoother_restart_delay": 1e6,
           "filter.smoother_discrepancy": 10.0, "filter.smoother_discrepancy_time": 1e6,
           "filter.smoother_importance": 10**6, "filter.smoother_modes": 10**6,
           "filter.seed": 2**63 - 1, "filter.emulator.n_photons": 10**11,
           "filter.emulator.n_mua": 1000, "filter.emulator.n_mus": 1000,
           "filter.emulator.radius_nodes": 16, "filter.emulator.radius_range": 100.0,
           "filter.emulator.seed": 2**63 - 1, "data.time_offset": 1e9,
           "filter.coagulation.E": 1e7, "filter.coagulation.A": 1e300,
           "filter.coagulation.nominal_factor": 1e3, "filter.coagulation.weight_exponent": 10.0,
           "filter.coagulation.mean_field_rel_std": 10.0}


def _smoother_iterations(flt: dict, setup_kw: dict) -> int:
    """``[filter] smoother_iterations``: ES-MDA updates after the filter."""
    if "smoother_iterations" not in flt:
        for k in ("smoother_knots", "smoother_discrepancy", "smoother_discrepancy_time",
                  "smoother_importance", "smoother_modes"):
            if k in flt and not ("smoother_restarts" in flt and "discrepancy" in k):
                raise ConfigError(f"filter.{k} needs filter.smoother_iterations >= 1")
        return 0
    n = int(_num("filter.smoother_iterations", flt["smoother_iterations"], integer=True, lo=0))
    if n and setup_kw.get("parameter_model", "random_walk") != "random_walk":
        raise ConfigError("filter.smoother_iterations needs constant or drifting optics "
                          "(parameter_model = \"random_walk\"), got parameter_model = "
                          f"{setup_kw['parameter_model']!r}")
    if n and setup_kw.get("sensor_offset_std", 0):
        raise ConfigError("filter.smoother_iterations does not estimate sensor offsets: set "
                          "filter.sensor_offset_std = 0 or drop the smoother")
    return n


def _smoother_options(flt: dict, camera: bool = False) -> dict:
    """``[filter] smoother_knots``, ``smoother_discrepancy``, ``smoother_discrepancy_time``.
    With a camera the discrepancy is 0 (its dense covariance over every pixel and reading
    would not fit) and a value > 0 is refused."""
    out = dict(SMOOTHER_DEFAULTS)
    if camera:
        out["discrepancy"] = 0.0
    if "smoother_knots" in flt:
        out["knots"] = int(_num("filter.smoother_knots", flt["smoother_knots"], integer=True,
                                lo=1))
    if "smoother_discrepancy" in flt:
        out["discrepancy"] = float(_num("filter.smoother_discrepancy",
                                        flt["smoother_discrepancy"], lo=0))
        if camera and out["discrepancy"] > 0:
            raise ConfigError(f"filter.smoother_discrepancy = {out['discrepancy']:g} is for point "
                              "sensors: with [sensors.camera] its covariance over every pixel "
                              "and reading is too large; set it to 0")
    if "smoother_discrepancy_time" in flt:
        out["discrepancy_time"] = float(_num("filter.smoother_discrepancy_time",
                                             flt["smoother_discrepancy_time"], positive=True))
    if "smoother_importance" in flt:
        m = int(_num("filter.smoother_importance", flt["smoother_importance"], integer=True,
                     lo=0))
        if 0 < m < MIN_IMPORTANCE:
            raise ConfigError(f"filter.smoother_importance = {m}: use 0 (none) or at least "
                              f"{MIN_IMPORTANCE} samples")
        out["importance"] = m
        if m:
            out["mode_search"] = MODE_SEARCH
    if "smoother_modes" in flt:
        p = int(_num("filter.smoother_modes", flt["smoother_modes"], integer=True, lo=0))
        if p and not out.get("importance"):
            raise ConfigError(f"filter.smoother_modes = {p} needs filter.smoother_importance > 0 "
                              "(the modes seed the importance sampler)")
        if 0 < p < MIN_MODE_POINTS:
            raise ConfigError(f"filter.smoother_modes = {p}: use 0 (no mode search) or at "
                              f"least {MIN_MODE_POINTS} points")
        out["mode_search"] = p
    return out


def _restart_settings(flt: dict, setup_kw: dict, options: dict) -> None:
    """``[filter] smoother_restarts`` (times in s, or "laser_off"),
    ``smoother_restart_iterations``, ``smoother_restart_knots``, ``smoother_restart_delay``
    and ``smoother_restart_gaussian``; the restarts'
    discrepancy is the smoother's (``smoother_discrepancy``, ``smoother_discrepancy_time``
    and their defaults)."""
    if "smoother_restarts" not in flt:
        for k in ("smoother_restart_iterations", "smoother_restart_gaussian",
                  "smoother_restart_knots", "smoother_restart_delay"):
            if k in flt:
                raise ConfigError(f"filter.{k} needs filter.smoother_restarts")
        return
    r = flt["smoother_restarts"]
    if isinstance(r, str):  # TissueFilterSetup names the one allowed
        setup_kw["smoother_restarts"] = r
    elif isinstance(r, list):
        setup_kw["smoother_restarts"] = tuple(
            _num(f"filter.smoother_restarts[{i}]", v, positive=True) for i, v in enumerate(r))
    else:
        raise ConfigError(f"filter.smoother_restarts must be a list of times (s) or "
                          f"\"laser_off\", got {shorten(repr(r))}")
    if "smoother_restart_iterations" in flt:
        setup_kw["smoother_restart_iterations"] = int(_num(
            "filter.smoother_restart_iterations", flt["smoother_restart_iterations"],
            integer=True, lo=1))
    if "smoother_restart_knots" in flt:  # a count, or several: a mixture of drift forms
        k = flt["smoother_restart_knots"]
        setup_kw["smoother_restart_knots"] = (
            tuple(int(_num(f"filter.smoother_restart_knots[{i}]", v, integer=True, lo=2))
                  for i, v in enumerate(k)) if isinstance(k, list)
            else int(_num("filter.smoother_restart_knots", k, integer=True, lo=1)))
    if "smoother_restart_delay" in flt:
        setup_kw["smoother_restart_delay"] = float(_num("filter.smoother_restart_delay",
                                                        flt["smoother_restart_delay"], lo=0))
    if "smoother_restart_gaussian" in flt:
        if not isinstance(flt["smoother_restart_gaussian"], bool):
            raise ConfigError(f"filter.smoother_restart_gaussian must be true or false, got "
                              f"{shorten(repr(flt['smoother_restart_gaussian']))}")
        setup_kw["smoother_restart_gaussian"] = flt["smoother_restart_gaussian"]
    setup_kw["smoother_restart_discrepancy"] = options["discrepancy"]
    setup_kw["smoother_restart_discrepancy_time"] = options["discrepancy_time"]


#: the fewest importance samples a config may ask for (a few hundred per proposal)
MIN_IMPORTANCE = 600
#: the fewest prior points a mode search may screen (twice the searches it starts)
MIN_MODE_POINTS = 16


#: the smoother's defaults in a config: constant optics, a 1% model discrepancy over 2 s
SMOOTHER_DEFAULTS = {"knots": 1, "discrepancy": 0.01, "discrepancy_time": 2.0}


def _num(key, v, *, positive=False, integer=False, lo=None, hi=None):
    """:func:`fem.checks.check_number` with the key's limit from :data:`_LIMITS`."""
    if hi is None:
        hi = _LIMITS.get(key.split("[")[0])
    if positive:
        lo = 0.0
    return check_number(key, v, integer=integer, lo=lo, hi=hi, lo_open=positive,
                        error=ConfigError)


def _points(key, v, G) -> np.ndarray:
    if not isinstance(v, list) or not all(isinstance(r, list) and len(r) == 3 for r in v):
        raise ConfigError(f"{key} must be a list of [x, y, z] points in cm, got {shorten(repr(v))}")
    pts = np.array([[_num(f"{key}[{i}][{j}]", c) for j, c in enumerate(r)]
                    for i, r in enumerate(v)], dtype=float).reshape(-1, 3)
    tol = 1e-9
    for i, (x, y, z) in enumerate(pts):
        if not (abs(x) <= G.Lx / 2 + tol and abs(y) <= G.Ly / 2 + tol and -tol <= z <= G.Lz + tol):
            raise ConfigError(f"{key}[{i}] = {[float(x), float(y), float(z)]} cm is outside the tissue "
                              f"(x, y in [-{G.Lx / 2}, {G.Lx / 2}], z in [0, {G.Lz}])")
    return pts


def _camera_model_error(cam: dict) -> dict:
    """``ThermalImage`` keywords of the camera's model error (only those given)."""
    out = {}
    if "model_error_rel_std" in cam:
        out["model_error_rel_std"] = _num("sensors.camera.model_error_rel_std",
                                          cam["model_error_rel_std"], lo=0.0)
    if "model_error_lengths" in cam:
        v = cam["model_error_lengths"]
        if not (isinstance(v, list) and v):
            raise ConfigError(f"sensors.camera.model_error_lengths must be a list of lengths "
                              f"(cm), got {shorten(repr(v))}")
        out["model_error_lengths"] = tuple(_num(f"sensors.camera.model_error_lengths[{i}]", x,
                                                lo=0.0) for i, x in enumerate(v))
    return out


def _pair(key, v, positive=False):
    if not isinstance(v, list) or len(v) != 2:
        raise ConfigError(f"{key} must be [lo, hi], got {shorten(repr(v))}")
    lo, hi = (_num(f"{key}[{i}]", x, positive=positive) for i, x in enumerate(v))
    if not lo < hi:
        raise ConfigError(f"{key} must have lo < hi, got {shorten(repr(v))}")
    return (lo, hi)


def identify_config_from_dict(cfg: dict) -> IdentifyConfig:
    """Validate a parsed config for ``tissue-enkf identify``."""
    from mcmatlab_py.emulator import check_emulated

    from .config_params import (  # it uses this module's number checks: no import cycle
        bounds_settings,
        coagulation_settings,
        drift_settings,
        filtered_names,
        prior_of,
        prior_settings,
    )

    _require_laser(cfg)
    model = model_from_config(cfg)
    G = model.G
    try:
        model.HS.validate(G)
        check_emulated(model)  # the filter's forward model is an emulator of this source
    except (ValueError, NotBuiltError) as err:
        raise ConfigError(str(err)) from None
    flt = check_keys("filter", cfg.get("filter", {}), _FILTER_KEYS)
    medium, second = _estimated_media(flt.get("medium"), G)
    m = G.media[medium]
    where = f"G.media[{medium}]"
    if second is not None:  # the nominal values of both media's parameters, for the checks
        m2 = G.media[second]
        m = SimpleNamespace(mua=m.mua, mus=m.mus, VHC=m.VHC, TC=m.TC, mua2=m2.mua, mus2=m2.mus,
                            where2=f"G.media[{second}]")
    else:  # the beam's radius, for a config that carries it as an uncertain input
        m = SimpleNamespace(mua=m.mua, mus=m.mus, VHC=m.VHC, TC=m.TC,
                            beam_radius=float(model.MC.light_source.radius))
    sens = check_keys("sensors", cfg.get("sensors", {}), _SENSOR_KEYS)
    setup_kw: dict = {}
    positions = _points("sensors.positions", sens.get("positions", [[0.0, 0.0, 0.0]]), G)
    setup_kw["sensor_positions"] = positions
    setup_kw["sensor_noise_var"] = _num("sensors.noise_var", sens.get("noise_var", 0.01),
                                        positive=True)
    default_tracked = tracked_points(TRACKED_DEPTHS, Lz=G.Lz).tolist()
    setup_kw["tracked_positions"] = _points("sensors.tracked",
                                            sens.get("tracked", default_tracked), G)
    registration = emissivity = None
    if "camera" in sens:
        cam = check_keys("sensors.camera", sens["camera"], _CAMERA_KEYS)
        setup_kw["image"], registration, emissivity = camera_settings(
            cam, G, _num, _pair, _camera_model_error(cam))
    rate = None
    if "rate" in sens:
        rate = _num("sensors.rate", sens["rate"], positive=True)
    if "n_members" in flt:
        setup_kw["n_members"] = _num("filter.n_members", flt["n_members"], integer=True, lo=2)
    if "method" in flt:
        if flt["method"] not in ("enkf", "etkf"):
            raise ConfigError(f"filter.method must be 'enkf' or 'etkf', got {shorten(repr(flt['method']))}")
        setup_kw["method"] = flt["method"]
    else:
        setup_kw["method"] = DEFAULT_METHOD
    if "estimate" in flt:
        est = flt["estimate"]
        if not isinstance(est, list) or tuple(est) not in ESTIMATES:
            raise ConfigError(f"filter.estimate must be one of {[list(e) for e in ESTIMATES]}, "
                              f"got {shorten(repr(est))}")
        setup_kw["estimate"] = tuple(est)
    if second is not None:
        est = setup_kw.setdefault("estimate", ESTIMATES[2])
        if "mua2" not in est:
            raise ConfigError(f"filter.medium names two media: filter.estimate must hold mua2 and "
                              f"mus2 (the second medium's optics), e.g. {list(ESTIMATES[2])}, got "
                              f"{list(est)}")
    elif "mua2" in setup_kw.get("estimate", ()):
        raise ConfigError(f"filter.estimate = {list(setup_kw['estimate'])} holds mua2, mus2: "
                          "name the second medium in filter.medium = [first, second]")
    if "transforms" in flt and flt["transforms"] != "log":
        raise ConfigError(f"filter.transforms must be \"log\" (positive parameters), got "
                          f"{shorten(repr(flt['transforms']))}")
    grid = flt.get("grid", [20, 20, 10])
    if not (isinstance(grid, list) and len(grid) == 3):
        raise ConfigError(f"filter.grid must be [nx, ny, nz], got {shorten(repr(grid))}")
    grid = tuple(_num(f"filter.grid[{i}]", v, integer=True, lo=1) for i, v in enumerate(grid))
    if "prior_range" in flt:
        setup_kw["prior_range"] = _pair("filter.prior_range", flt["prior_range"], positive=True)
    if "parameter_model" in flt:  # before the priors: "coagulation" adds parameters
        allowed = ("random_walk", "trend", "coagulation")
        if flt["parameter_model"] not in allowed:
            raise ConfigError(f"filter.parameter_model must be one of {allowed}, got "
                              f"{shorten(repr(flt['parameter_model']))}")
        setup_kw["parameter_model"] = flt["parameter_model"]
        if second is not None and flt["parameter_model"] != "random_walk":
            raise ConfigError(f"filter.parameter_model = {flt['parameter_model']!r} is not built "
                              "for a second estimated medium (filter.medium = [first, second]): "
                              "use \"random_walk\"")
    coagulation_settings(flt, setup_kw)
    prior = prior_settings(flt.get("prior", {}), setup_kw)
    if prior:
        setup_kw["prior"] = prior
    for k, kw in (("model_noise_std", dict(lo=0)), ("random_walk_when_off", dict(lo=0)),
                  ("sensor_offset_std", dict(lo=0)), ("rtps", dict(lo=0)),
                  ("inflation", dict(positive=True)), ("localization_radius", dict(positive=True))):
        if k in flt:
            setup_kw[k] = _num(f"filter.{k}", flt[k], **kw)
    if "mda" in flt:
        setup_kw["mda"] = _num("filter.mda", flt["mda"], integer=True, lo=1)
    if "seed" in flt:
        setup_kw["seed"] = _num("filter.seed", flt["seed"], integer=True, lo=0)
    if "random_walk_std" in flt:
        rw = flt["random_walk_std"]
        n = len(filtered_names(setup_kw))
        if isinstance(rw, list):
            if len(rw) != n:
                raise ConfigError(f"filter.random_walk_std must be a number or {n} numbers "
                                  f"(one per estimated parameter), got {shorten(repr(rw))}")
            setup_kw["random_walk_std"] = [_num(f"filter.random_walk_std[{i}]", v, lo=0)
                                           for i, v in enumerate(rw)]
        else:
            setup_kw["random_walk_std"] = _num("filter.random_walk_std", rw, lo=0)
    _model_error(flt, setup_kw)
    drift_settings(flt, setup_kw)
    for k, allowed in (("heat_mass", ("averaged", "lumped")),):
        if k in flt:
            if flt[k] not in allowed:
                raise ConfigError(f"filter.{k} must be one of {allowed}, got {shorten(repr(flt[k]))}")
            setup_kw[k] = flt[k]
    emu = check_keys("filter.emulator", flt.get("emulator", {}), _EMULATOR_KEYS)
    emulator_kw = {}
    for k in ("n_photons", "n_mua", "n_mus", "seed"):
        if k in emu:
            emulator_kw[k] = _num(f"filter.emulator.{k}", emu[k], integer=True,
                                  lo=4 if k in ("n_mua", "n_mus") else (0 if k == "seed" else 1))
    for k in ("mua_range", "mus_range"):
        if k in emu:
            emulator_kw[k] = _pair(f"filter.emulator.{k}", emu[k], positive=True)
    for name, default in (("mua", (0.1, 20.0)), ("mus", (10.0, 2000.0))):  # EmulatorSpec's
        t_lo, t_hi = emulator_kw.get(f"{name}_range", default)
        # with damage-driven optics the effective values lie between native and coagulated
        for par in [p for p in (name, f"{name}_coag") if p in filtered_names(setup_kw)]:
            (p_lo, p_hi), source = prior_of(par, setup_kw, m, where)
            if not (t_lo <= p_lo and p_hi <= t_hi):
                raise ConfigError(
                    f"filter.emulator.{name}_range = {[t_lo, t_hi]} must cover the prior of "
                    f"{par}, [{p_lo:g}, {p_hi:g}] cm^-1 ({source})")
    media_nodes = None if second is None else _media_nodes(emu, setup_kw, m)
    for k in ("mua2_range", "mus2_range", "media_nodes"):
        if k in emu and second is None:
            raise ConfigError(f"filter.emulator.{k} is for a second estimated medium "
                              "(filter.medium = [first, second])")
    beam = "beam_radius" in setup_kw.get("estimate", ())
    beam_nodes = _beam_nodes(emu, setup_kw, m, model) if beam else None
    for k in ("radius_range", "radius_nodes"):
        if k in emu and not beam:
            raise ConfigError(f"filter.emulator.{k} is for an estimated beam radius "
                              "(filter.estimate = [\"mua\", \"mus\", \"beam_radius\"])")
    method = emu.get("method", "auto")
    if method not in ("table", "white", "auto"):
        raise ConfigError(f"filter.emulator.method must be \"auto\", \"table\" or \"white\", "
                          f"got {shorten(repr(method))}")
    exact = emu.get("exact", False)
    on_demand = emu.get("on_demand", True)
    for k, v in (("exact", exact), ("on_demand", on_demand)):
        if not isinstance(v, bool):
            raise ConfigError(f"filter.emulator.{k} must be true or false, got {shorten(repr(v))}")
    if exact and second is not None:
        raise ConfigError("filter.emulator.exact = true is not built for two estimated media "
                          "(filter.medium = [first, second]): use the emulator")
    if exact and beam:
        raise ConfigError("filter.emulator.exact = true is not built for an estimated beam "
                          "radius: use the emulator")
    if "theta" in cfg.get("HS", {}):
        setup_kw["theta"] = float(model.HS.theta)  # the filter's time scheme (checked by HS)
    if "dt" in cfg.get("HS", {}) and model.HS.dt is not None:
        setup_kw["max_dt"] = float(model.HS.dt)  # the filter's longest heat step
        try:
            check_steps(model.HS.total_duration / model.HS.dt, "the filter's heat steps (HS.dt = "
                        f"{model.HS.dt:g} s over {model.HS.total_duration:g} s of laser pulses)",
                        "HS.dt")
        except ValueError as err:  # a ConfigError, as every other bad key
            raise ConfigError(str(err)) from None
    run_table(cfg)
    bounds = bounds_settings(flt.get("bounds", {}), setup_kw, m, where)
    data = _data_spec(cfg.get("data", {}), len(positions) + (
        setup_kw["image"].n_pixels if "image" in setup_kw else 0))
    smoother_options = _smoother_options(flt, camera="image" in setup_kw)
    _restart_settings(flt, setup_kw, smoother_options)
    try:
        out = IdentifyConfig(model, setup_kw, grid, emulator_kw, exact, cfg, bounds, data, rate,
                             medium, method, on_demand, _smoother_iterations(flt, setup_kw),
                             smoother_options, second, media_nodes, beam_nodes,
                             registration, emissivity)
        out.setup(absorption=lambda mua, mus: None)  # validates the filter settings
        from .config_advice import advice_settings

        out.advice = advice_settings(cfg.get("advice"), model, medium, grid, setup_kw)
        n_nodes = int(np.prod([n + 1 for n in grid]))
        table = 0 if exact else emulator_kw.get("n_mua", 12) * emulator_kw.get("n_mus", 12)
        table *= 1 if media_nodes is None else media_nodes["n_nodes"] ** 2
        table *= 1 if beam_nodes is None else beam_nodes["n_nodes"]
        check_filter(setup_kw.get("n_members", 50), n_nodes, table)
    except ConfigError:
        raise
    except ValueError as err:
        raise ConfigError(str(err)) from None
    return out


def _estimated_media(value, G) -> tuple[int, int | None]:
    """``filter.medium``: one medium (name or index), or a list of two whose optics are
    both estimated (the second's as mua2, mus2): ``(first, second or None)``."""
    if not isinstance(value, list):
        return _estimated_medium(value, G), None
    if len(value) == 1:
        return _estimated_medium(value[0], G), None
    if len(value) != 2:
        raise ConfigError(f"filter.medium must be one medium or a list of two (whose optics are "
                          f"estimated), got {shorten(repr(value))}")
    first, second = (_estimated_medium(v, G) for v in value)
    if first == second:
        raise ConfigError(f"filter.medium = {shorten(repr(value))} names one medium twice")
    return first, second


#: the default node range of a second medium's optics: its prior, widened by this factor
#: each way (members that an analysis moves beyond the prior would be clamped to the edge
#: and stop responding to the data: with the nodes on the prior's edges a camera's bands
#: missed truths near those edges)
MEDIA_NODES_ROOM = 1.5


def _media_nodes(emu: dict, setup_kw: dict, m) -> dict:
    """``filter.emulator.mua2_range``, ``mus2_range`` (default: the second medium's prior
    widened by :data:`MEDIA_NODES_ROOM` each way) and ``media_nodes`` (per axis, default
    4: over that range 3 nodes added 0.5-1% to the loads' error, 4 nothing measurable,
    ``validation/layered_both.py --emulator``): the node grid of its optics."""
    from .config_params import prior_of

    out = {"n_nodes": 4}
    if "media_nodes" in emu:
        out["n_nodes"] = _num("filter.emulator.media_nodes", emu["media_nodes"], integer=True,
                              lo=2)
    for name in ("mua2", "mus2"):
        prior, source = prior_of(name, setup_kw, m, m.where2)
        rng = (prior[0] / MEDIA_NODES_ROOM, prior[1] * MEDIA_NODES_ROOM)
        if f"{name}_range" in emu:
            rng = _pair(f"filter.emulator.{name}_range", emu[f"{name}_range"], positive=True)
            if not (rng[0] <= prior[0] and prior[1] <= rng[1]):
                raise ConfigError(f"filter.emulator.{name}_range = {list(rng)} must cover the "
                                  f"prior of {name}, [{prior[0]:g}, {prior[1]:g}] cm^-1 ({source})")
        out[f"{name}_range"] = tuple(rng)
    return out


#: the default node range of an estimated beam radius: its prior widened by this factor each
#: way (as :data:`MEDIA_NODES_ROOM`, so that members an analysis moves past the prior still
#: respond to the data)
BEAM_NODES_ROOM = 1.1


def _beam_nodes(emu: dict, setup_kw: dict, m, model) -> dict:
    """``filter.emulator.radius_range`` (default: the radius's prior widened by
    :data:`BEAM_NODES_ROOM` each way) and ``radius_nodes`` (default 4: against tables built
    directly at radii between the nodes the filter's loads were 0.93% off at worst, 2.6%
    with 3 nodes, 0.66% with 5, with a table's own Monte Carlo noise 0.53%;
    ``validation/reports/beam_radius.md``): the node grid of the beam's radius."""
    from .config_params import prior_of

    src = model.MC.light_source
    if src.source_type not in ("tophat", "gaussian"):
        raise ConfigError(f"filter.estimate holds beam_radius, but MC.light_source.source_type "
                          f"= {src.source_type!r} has no radius: use \"tophat\" or \"gaussian\"")
    out = {"n_nodes": 4}
    if "radius_nodes" in emu:
        out["n_nodes"] = _num("filter.emulator.radius_nodes", emu["radius_nodes"], integer=True,
                              lo=2)
    prior, source = prior_of("beam_radius", setup_kw, m)
    rng = (prior[0] / BEAM_NODES_ROOM, prior[1] * BEAM_NODES_ROOM)
    if "radius_range" in emu:
        rng = _pair("filter.emulator.radius_range", emu["radius_range"], positive=True)
        if not (rng[0] <= prior[0] and prior[1] <= rng[1]):
            raise ConfigError(f"filter.emulator.radius_range = {list(rng)} must cover the prior "
                              f"of beam_radius, [{prior[0]:g}, {prior[1]:g}] cm ({source})")
    out["radius_range"] = tuple(rng)
    return out


def _estimated_medium(value, G) -> int:
    """``filter.medium``: the index in ``G.media`` of the medium whose parameters are
    estimated (a name or an index; default the only medium). The heat model has one VHC
    and TC for the whole block, so every medium must have the same."""
    names = [m.name for m in G.media]
    if value is None:
        if len(names) > 1:
            raise ConfigError(f"G.media holds {len(names)} media {names}: set filter.medium to "
                              "the name (or index) of the one whose parameters are estimated")
        i = 0
    elif isinstance(value, str):
        if names.count(value) != 1:
            why = "is repeated in" if value in names else "is not a medium of"
            raise ConfigError(f"filter.medium = {shorten(repr(value))} {why} G.media {names}")
        i = names.index(value)
    elif isinstance(value, int) and not isinstance(value, bool):
        if not 0 <= value < len(names):
            raise ConfigError(f"filter.medium = {value} is not an index of G.media "
                              f"(0..{len(names) - 1}: {names})")
        i = value
    else:
        raise ConfigError(f"filter.medium must be a medium's name or index, got "
                          f"{shorten(repr(value))}")
    for k in ("VHC", "TC"):
        if getattr(G.media[i], k) is None:
            raise ConfigError(f"G.media[{i}].{k} is missing (needed by the heat model)")
    if len(names) > 1:
        try:
            M = G.medium_map()
        except ValueError as err:
            raise ConfigError(str(err)) from None
        if not (M == i).any():
            raise ConfigError(f"filter.medium = {names[i]!r} (G.media[{i}]) fills no voxel of "
                              "the geometry (G.geom_func): nothing to estimate")
        ref = G.media[i]
        for j, other in enumerate(G.media):
            for k in ("VHC", "TC"):
                a, b = getattr(other, k), getattr(ref, k)
                if callable(a) or callable(b) or a != b:
                    raise ConfigError(
                        f"G.media[{j}].{k} = {shorten(repr(a))} differs from the estimated "
                        f"medium's {shorten(repr(b))}: the filter's heat model has one {k} for "
                        "the whole block (give every medium the same VHC and TC)")
    return i


def _require_laser(cfg: dict) -> None:
    """identify needs the laser: no silent defaults for what heats the tissue."""
    hs = cfg.get("HS")
    if not isinstance(hs, dict):
        raise ConfigError("[HS] is missing: identify needs the laser and the start temperature "
                          "(HS.P in W, HS.duration_on in s, HS.T_initial in deg C)")
    missing = [k for k in _LASER_KEYS if k not in hs]
    if missing:
        raise ConfigError(f"HS.{missing[0]} is missing: identify needs the laser and the start "
                          f"temperature ({', '.join('HS.' + k for k in _LASER_KEYS)})")


def _data_spec(table, n_obs: int) -> DataSpec:
    table = check_keys("data", table, _DATA_KEYS)
    spec = DataSpec()
    if "file" in table:
        if not isinstance(table["file"], str) or not table["file"]:
            raise ConfigError(f"data.file must be a path (a string), got {shorten(repr(table['file']))}")
        spec.file = Path(table["file"])
    if "columns" in table:
        cols = table["columns"]
        if not (isinstance(cols, list) and all(isinstance(c, str) and c for c in cols)):
            raise ConfigError(f"data.columns must be a list of column names, got {shorten(repr(cols))}")
        if len(cols) != n_obs:
            raise ConfigError(f"data.columns names {len(cols)} columns, the config observes "
                              f"{n_obs} (sensors.positions, then camera pixels)")
        if len(set(cols)) != len(cols):
            raise ConfigError(f"data.columns repeats a name: {shorten(repr(cols))}")
        spec.columns = list(cols)
    if "time_offset" in table:
        spec.time_offset = _num("data.time_offset", table["time_offset"])
    return spec


def _model_error(flt: dict, setup_kw: dict) -> None:
    """[filter.model_error] and [filter.adaptive_inflation] into TissueFilterSetup arguments."""
    me = check_keys("filter.model_error", flt.get("model_error", {}), _MODEL_ERROR_KEYS)
    # structured unless the config says otherwise: measured data never come from the
    # filter's own model (docs/enkf.md, validation/reports/model_error_coverage.md)
    kind = me.get("kind", "structured")
    if kind not in ("structured", "white"):
        raise ConfigError(f"filter.model_error.kind must be \"structured\" or \"white\", got "
                          f"{shorten(repr(kind))}")
    setup_kw["model_error"] = kind
    for k, hi in (("rel_std", 10.0), ("time_scale", 1e6), ("length_xy", 1e3), ("length_z", 1e3)):
        if k in me:
            setup_kw[f"model_error_{k}"] = _num(f"filter.model_error.{k}", me[k], lo=0, hi=hi)
    ai = check_keys("filter.adaptive_inflation", flt.get("adaptive_inflation", {}),
                    _ADAPTIVE_KEYS)
    if "enabled" in ai:
        if not isinstance(ai["enabled"], bool):
            raise ConfigError(f"filter.adaptive_inflation.enabled must be true or false, got "
                              f"{shorten(repr(ai['enabled']))}")
        setup_kw["adaptive_inflation"] = ai["enabled"]
    if "bounds" in ai:
        lo, hi = _pair("filter.adaptive_inflation.bounds", ai["bounds"], positive=True)
        if not (lo <= hi <= 1e4):
            raise ConfigError(f"filter.adaptive_inflation.bounds must be [lo, hi] with "
                              f"0 < lo <= hi <= 1e4, got {[lo, hi]}")
        setup_kw["adaptive_inflation_bounds"] = (lo, hi)
    if "time_scale" in ai:
        setup_kw["adaptive_inflation_time_scale"] = _num(
            "filter.adaptive_inflation.time_scale", ai["time_scale"], lo=1, hi=1e9)


def check_identify_keys(cfg: dict) -> None:
    """Check the key names of [sensors], [filter], [data] and [run] (for ``mc``, ``heat``).

    Those commands do not use the tables, but a typo in them is still an error.
    """
    sens = check_keys("sensors", cfg.get("sensors", {}), _SENSOR_KEYS)
    if "camera" in sens:
        check_keys("sensors.camera", sens["camera"], _CAMERA_KEYS)
    flt = check_keys("filter", cfg.get("filter", {}), _FILTER_KEYS)
    check_keys("filter.emulator", flt.get("emulator", {}), _EMULATOR_KEYS)
    names = set(PARAMETER_NAMES) | set(COAGULATION_NAMES) | set(SECOND_MEDIUM_NAMES)
    check_keys("filter.bounds", flt.get("bounds", {}), names)
    check_keys("filter.prior", flt.get("prior", {}), names)
    check_keys("filter.coagulation", flt.get("coagulation", {}),
               {"E", "A", "nominal_factor", "weight_exponent"})
    check_keys("filter.model_error", flt.get("model_error", {}), _MODEL_ERROR_KEYS)
    check_keys("filter.adaptive_inflation", flt.get("adaptive_inflation", {}), _ADAPTIVE_KEYS)
    from .config_params import DRIFT_KEYS

    check_keys("filter.drift", flt.get("drift", {}), DRIFT_KEYS)
    check_keys("data", cfg.get("data", {}), _DATA_KEYS)
    from .config_advice import ADVICE_KEYS

    check_keys("advice", cfg.get("advice", {}), ADVICE_KEYS)
    run_table(cfg)


def run_table(cfg: dict) -> tuple[str | None, int | None]:
    """``(scheduler, workers)`` of the ``[run]`` table (Dask; None when not given)."""
    run = check_keys("run", cfg.get("run", {}), {"scheduler", "workers"})
    scheduler, workers = run.get("scheduler"), run.get("workers")
    if scheduler is not None and not isinstance(scheduler, str):
        raise ConfigError(f"run.scheduler must be an address string, got {shorten(repr(scheduler))}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise ConfigError(f"run.workers must be an integer >= 1, got {shorten(repr(workers))}")
    return scheduler, workers


def load_identify(path: str | Path) -> IdentifyConfig:
    """Read and validate an identification config file.

    A relative ``data.file`` is taken relative to the config file's folder.
    """
    cfg = identify_config_from_dict(read_toml(path))
    if cfg.data.file is not None and not cfg.data.file.is_absolute():
        cfg.data.file = Path(path).parent / cfg.data.file
    return cfg
