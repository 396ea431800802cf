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
    prior_sampling = "random"       # or "stratified" (a Latin hypercube): the members' draws
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

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from fem.checks import shorten
from mcmatlab_py import NotBuiltError
from mcmatlab_py.budget import check_filter, check_steps
from mcmatlab_py.config import ConfigError, check_keys, model_from_config, read_toml

from ...problem import DEFAULT_METHOD, PRIOR_SAMPLINGS
from ...tissue.parameters import (
    COAGULATION_NAMES,
    ESTIMATES,
    PARAMETER_NAMES,
    SECOND_MEDIUM_NAMES,
    TRACKED_DEPTHS,
    tracked_points,
)
from .advice import ADVICE_KEYS, advice_settings
from .camera import CAMERA_KEYS, camera_settings
from .media import beam_nodes, estimated_media, media_nodes
from .numbers import num, pair, points
from .params import (
    DRIFT_KEYS,
    bounds_settings,
    coagulation_settings,
    drift_settings,
    filtered_names,
    prior_of,
    prior_settings,
)
from .settings import (
    ADAPTIVE_KEYS,
    MODEL_ERROR_KEYS,
    model_error_settings,
    restart_settings,
    smoother_iterations,
    smoother_options,
)
from .spec import DataSpec, IdentifyConfig

__all__ = ["FILTER_KEYS", "check_identify_keys", "identify_config_from_dict", "load_identify",
           "run_table"]

#: keys of [sensors] (:class:`~enkf.tissue.Sensors`; ``rate`` is the reader's)
_SENSOR_KEYS = {"positions", "noise_var", "tracked", "camera", "rate"}
_CAMERA_KEYS = CAMERA_KEYS
#: keys of [filter]: each goes to its part of the setup by its flat name
#: (:data:`enkf.tissue.setup.FLAT_NAMES`), the emulator's and the smoother's to theirs
FILTER_KEYS = {
    "n_members", "method", "estimate", "grid", "prior_range", "prior_sampling", "model_noise_std",
    "random_walk_std", "random_walk_when_off", "inflation", "rtps", "mda", "seed",
    "parameter_model",
    "localization_radius", "heat_mass", "transforms", "emulator", "bounds", "prior",
    "model_error", "adaptive_inflation", "coagulation", "medium", "sensor_offset_std",
    "smoother_iterations", "smoother_knots", "smoother_discrepancy",
    "smoother_discrepancy_time", "smoother_importance", "smoother_modes", "smoother_restarts",
    "smoother_restart_iterations", "smoother_restart_gaussian", "smoother_restart_knots",
    "smoother_restart_delay", "drift",
}


_LASER_KEYS = ("P", "duration_on", "T_initial")


_DATA_KEYS = {"file", "columns", "time_offset"}


_EMULATOR_KEYS = {"n_photons", "n_mua", "n_mus", "mua_range", "mus_range", "seed", "exact",
                  "method", "on_demand", "mua2_range", "mus2_range", "media_nodes",
                  "radius_range", "radius_nodes"}


def _camera_model_error(cam: dict) -> dict:
    """``ThermalImage`` keywords of the camera's model error (only those given)."""
    out = {}
    if "model_error_rel_std" in cam:
        out["model_error_rel_std"] = num("sensors.camera.model_error_rel_std",
                                          cam["model_error_rel_std"], lo=0.0)
    if "model_error_lengths" in cam:
        v = cam["model_error_lengths"]
        if not (isinstance(v, list) and v):
            raise ConfigError(f"sensors.camera.model_error_lengths must be a list of lengths "
                              f"(cm), got {shorten(repr(v))}")
        out["model_error_lengths"] = tuple(num(f"sensors.camera.model_error_lengths[{i}]", x,
                                                lo=0.0) for i, x in enumerate(v))
    return out


def identify_config_from_dict(cfg: dict) -> IdentifyConfig:
    """Validate a parsed config for ``tissue-enkf identify``."""
    from mcmatlab_py.emulator import check_emulated

    _require_laser(cfg)
    model = model_from_config(cfg)
    G = model.G
    try:
        model.HS.validate(G)
        check_emulated(model)  # the filter's forward model is an emulator of this source
    except (ValueError, NotBuiltError) as err:
        raise ConfigError(str(err)) from None
    flt = check_keys("filter", cfg.get("filter", {}), FILTER_KEYS)
    medium, second = estimated_media(flt.get("medium"), G)
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
    positions = points("sensors.positions", sens.get("positions", [[0.0, 0.0, 0.0]]), G)
    setup_kw["sensor_positions"] = positions
    setup_kw["sensor_noise_var"] = num("sensors.noise_var", sens.get("noise_var", 0.01),
                                        positive=True)
    default_tracked = tracked_points(TRACKED_DEPTHS, Lz=G.Lz).tolist()
    setup_kw["tracked_positions"] = points("sensors.tracked",
                                            sens.get("tracked", default_tracked), G)
    registration = emissivity = None
    if "camera" in sens:
        cam = check_keys("sensors.camera", sens["camera"], _CAMERA_KEYS)
        setup_kw["image"], registration, emissivity = camera_settings(
            cam, G, num, pair, _camera_model_error(cam))
    rate = None
    if "rate" in sens:
        rate = num("sensors.rate", sens["rate"], positive=True)
    if "n_members" in flt:
        setup_kw["n_members"] = num("filter.n_members", flt["n_members"], integer=True, lo=2)
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
    grid = tuple(num(f"filter.grid[{i}]", v, integer=True, lo=1) for i, v in enumerate(grid))
    if "prior_range" in flt:
        setup_kw["prior_range"] = pair("filter.prior_range", flt["prior_range"], positive=True)
    if "prior_sampling" in flt:
        if flt["prior_sampling"] not in PRIOR_SAMPLINGS:
            raise ConfigError(f"filter.prior_sampling must be one of {list(PRIOR_SAMPLINGS)}, "
                              f"got {shorten(repr(flt['prior_sampling']))}")
        setup_kw["prior_sampling"] = flt["prior_sampling"]
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
            setup_kw[k] = num(f"filter.{k}", flt[k], **kw)
    if "mda" in flt:
        setup_kw["mda"] = num("filter.mda", flt["mda"], integer=True, lo=1)
    if "seed" in flt:
        setup_kw["seed"] = num("filter.seed", flt["seed"], integer=True, lo=0)
    if "random_walk_std" in flt:
        rw = flt["random_walk_std"]
        n = len(filtered_names(setup_kw))
        if isinstance(rw, list):
            if len(rw) != n:
                raise ConfigError(f"filter.random_walk_std must be a number or {n} numbers "
                                  f"(one per estimated parameter), got {shorten(repr(rw))}")
            setup_kw["random_walk_std"] = [num(f"filter.random_walk_std[{i}]", v, lo=0)
                                           for i, v in enumerate(rw)]
        else:
            setup_kw["random_walk_std"] = num("filter.random_walk_std", rw, lo=0)
    model_error_settings(flt, setup_kw)
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
            emulator_kw[k] = num(f"filter.emulator.{k}", emu[k], integer=True,
                                  lo=4 if k in ("n_mua", "n_mus") else (0 if k == "seed" else 1))
    for k in ("mua_range", "mus_range"):
        if k in emu:
            emulator_kw[k] = pair(f"filter.emulator.{k}", emu[k], positive=True)
    for name, default in (("mua", (0.1, 20.0)), ("mus", (10.0, 2000.0))):  # EmulatorSpec's
        t_lo, t_hi = emulator_kw.get(f"{name}_range", default)
        # with damage-driven optics the effective values lie between native and coagulated
        for par in [p for p in (name, f"{name}_coag") if p in filtered_names(setup_kw)]:
            (p_lo, p_hi), source = prior_of(par, setup_kw, m, where)
            if not (t_lo <= p_lo and p_hi <= t_hi):
                raise ConfigError(
                    f"filter.emulator.{name}_range = {[t_lo, t_hi]} must cover the prior of "
                    f"{par}, [{p_lo:g}, {p_hi:g}] cm^-1 ({source})")
    media = None if second is None else media_nodes(emu, setup_kw, m)
    for k in ("mua2_range", "mus2_range", "media_nodes"):
        if k in emu and second is None:
            raise ConfigError(f"filter.emulator.{k} is for a second estimated medium "
                              "(filter.medium = [first, second])")
    beam = "beam_radius" in setup_kw.get("estimate", ())
    beam_grid = beam_nodes(emu, setup_kw, m, model) if beam else None
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
    smoothing = smoother_options(flt, camera="image" in setup_kw)
    restart_settings(flt, setup_kw, smoothing)
    try:
        out = IdentifyConfig(model, setup_kw, grid, emulator_kw, exact, cfg, bounds, data, rate,
                             medium, method, on_demand, smoother_iterations(flt, setup_kw),
                             smoothing, second, media, beam_grid,
                             registration, emissivity)
        out.setup(absorption=lambda mua, mus: None)  # validates the filter settings
        out.advice = advice_settings(cfg.get("advice"), model, medium, grid, setup_kw)
        n_nodes = int(np.prod([n + 1 for n in grid]))
        table = 0 if exact else emulator_kw.get("n_mua", 12) * emulator_kw.get("n_mus", 12)
        table *= 1 if media is None else media["n_nodes"] ** 2
        table *= 1 if beam_grid is None else beam_grid["n_nodes"]
        check_filter(setup_kw.get("n_members", 50), n_nodes, table)
    except ConfigError:
        raise
    except ValueError as err:
        raise ConfigError(str(err)) from None
    return out


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
        spec.time_offset = num("data.time_offset", table["time_offset"])
    return spec


def check_identify_keys(cfg: dict) -> None:
    """Check the key names of [sensors], [filter], [data] and [run] (for ``mc``, ``heat``).

    Those commands do not use the tables, but a typo in them is still an error.
    """
    sens = check_keys("sensors", cfg.get("sensors", {}), _SENSOR_KEYS)
    if "camera" in sens:
        check_keys("sensors.camera", sens["camera"], _CAMERA_KEYS)
    flt = check_keys("filter", cfg.get("filter", {}), FILTER_KEYS)
    check_keys("filter.emulator", flt.get("emulator", {}), _EMULATOR_KEYS)
    names = set(PARAMETER_NAMES) | set(COAGULATION_NAMES) | set(SECOND_MEDIUM_NAMES)
    check_keys("filter.bounds", flt.get("bounds", {}), names)
    check_keys("filter.prior", flt.get("prior", {}), names)
    check_keys("filter.coagulation", flt.get("coagulation", {}),
               {"E", "A", "nominal_factor", "weight_exponent"})
    check_keys("filter.model_error", flt.get("model_error", {}), MODEL_ERROR_KEYS)
    check_keys("filter.adaptive_inflation", flt.get("adaptive_inflation", {}), ADAPTIVE_KEYS)
    check_keys("filter.drift", flt.get("drift", {}), DRIFT_KEYS)
    check_keys("data", cfg.get("data", {}), _DATA_KEYS)
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
