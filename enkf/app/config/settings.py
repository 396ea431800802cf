"""``[filter]``'s smoother, restarts and model error: the keys that map onto
:class:`~enkf.tissue.SmootherRestarts` and :class:`~enkf.tissue.ModelError` (and the
smoother run after the filter)."""

from __future__ import annotations

from fem.checks import shorten
from mcmatlab_py.config import ConfigError, check_keys

from ...tissue.smooth import MODE_SEARCH
from .numbers import drift_form, num, pair

__all__ = ["ADAPTIVE_KEYS", "MIN_IMPORTANCE", "MIN_MODE_POINTS", "MODEL_ERROR_KEYS",
           "SMOOTHER_DEFAULTS", "model_error_settings", "restart_settings",
           "smoother_iterations", "smoother_options"]

#: keys of [filter.model_error] (:class:`~enkf.tissue.ModelError`'s structured error)
MODEL_ERROR_KEYS = {"kind", "rel_std", "time_scale", "length_xy", "length_z"}
#: keys of [filter.adaptive_inflation]
ADAPTIVE_KEYS = {"enabled", "bounds", "time_scale"}


#: the fewest importance samples a config may ask for (a few hundred per proposal)
MIN_IMPORTANCE = 600


#: the fewest prior points a mode search may screen (twice the searches it starts)
MIN_MODE_POINTS = 16


#: the smoother's defaults in a config: constant optics, a 1% model discrepancy over 2 s
SMOOTHER_DEFAULTS = {"knots": 1, "discrepancy": 0.01, "discrepancy_time": 2.0}


def smoother_iterations(flt: dict, setup_kw: dict) -> int:
    """``[filter] smoother_iterations``: ES-MDA updates after the filter."""
    if "smoother_iterations" not in flt:
        for k in ("smoother_knots", "smoother_discrepancy", "smoother_discrepancy_time",
                  "smoother_importance", "smoother_modes"):
            if k in flt and not ("smoother_restarts" in flt and "discrepancy" in k):
                raise ConfigError(f"filter.{k} needs filter.smoother_iterations >= 1")
        return 0
    n = int(num("filter.smoother_iterations", flt["smoother_iterations"], integer=True, lo=0))
    if n and setup_kw.get("parameter_model", "random_walk") != "random_walk":
        raise ConfigError("filter.smoother_iterations needs constant or drifting optics "
                          "(parameter_model = \"random_walk\"), got parameter_model = "
                          f"{setup_kw['parameter_model']!r}")
    if n and setup_kw.get("sensor_offset_std", 0):
        raise ConfigError("filter.smoother_iterations does not estimate sensor offsets: set "
                          "filter.sensor_offset_std = 0 or drop the smoother")
    return n


def smoother_options(flt: dict, camera: bool = False) -> dict:
    """``[filter] smoother_knots``, ``smoother_discrepancy``, ``smoother_discrepancy_time``.
    With a camera the discrepancy is 0 (its dense covariance over every pixel and reading
    would not fit) and a value > 0 is refused."""
    out = dict(SMOOTHER_DEFAULTS)
    if camera:
        out["discrepancy"] = 0.0
    if "smoother_knots" in flt:
        out["knots"] = int(num("filter.smoother_knots", flt["smoother_knots"], integer=True,
                                lo=1))
    if "smoother_discrepancy" in flt:
        out["discrepancy"] = float(num("filter.smoother_discrepancy",
                                        flt["smoother_discrepancy"], lo=0))
        if camera and out["discrepancy"] > 0:
            raise ConfigError(f"filter.smoother_discrepancy = {out['discrepancy']:g} is for point "
                              "sensors: with [sensors.camera] its covariance over every pixel "
                              "and reading is too large; set it to 0")
    if "smoother_discrepancy_time" in flt:
        out["discrepancy_time"] = float(num("filter.smoother_discrepancy_time",
                                             flt["smoother_discrepancy_time"], positive=True))
    if "smoother_importance" in flt:
        m = int(num("filter.smoother_importance", flt["smoother_importance"], integer=True,
                     lo=0))
        if 0 < m < MIN_IMPORTANCE:
            raise ConfigError(f"filter.smoother_importance = {m}: use 0 (none) or at least "
                              f"{MIN_IMPORTANCE} samples")
        out["importance"] = m
        if m:
            out["mode_search"] = MODE_SEARCH
    if "smoother_modes" in flt:
        p = int(num("filter.smoother_modes", flt["smoother_modes"], integer=True, lo=0))
        if p and not out.get("importance"):
            raise ConfigError(f"filter.smoother_modes = {p} needs filter.smoother_importance > 0 "
                              "(the modes seed the importance sampler)")
        if 0 < p < MIN_MODE_POINTS:
            raise ConfigError(f"filter.smoother_modes = {p}: use 0 (no mode search) or at "
                              f"least {MIN_MODE_POINTS} points")
        out["mode_search"] = p
    return out


def restart_settings(flt: dict, setup_kw: dict, options: dict) -> None:
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
            num(f"filter.smoother_restarts[{i}]", v, positive=True) for i, v in enumerate(r))
    else:
        raise ConfigError(f"filter.smoother_restarts must be a list of times (s) or "
                          f"\"laser_off\", got {shorten(repr(r))}")
    if "smoother_restart_iterations" in flt:
        setup_kw["smoother_restart_iterations"] = int(num(
            "filter.smoother_restart_iterations", flt["smoother_restart_iterations"],
            integer=True, lo=1))
    if "smoother_restart_knots" in flt:  # a count, or several: a mixture of drift forms
        k = flt["smoother_restart_knots"]
        setup_kw["smoother_restart_knots"] = (
            tuple(drift_form(f"filter.smoother_restart_knots[{i}]", v) for i, v in enumerate(k))
            if isinstance(k, list) else drift_form("filter.smoother_restart_knots", k, lo=1))
    if "smoother_restart_delay" in flt:
        setup_kw["smoother_restart_delay"] = float(num("filter.smoother_restart_delay",
                                                        flt["smoother_restart_delay"], lo=0))
    if "smoother_restart_gaussian" in flt:
        if not isinstance(flt["smoother_restart_gaussian"], bool):
            raise ConfigError(f"filter.smoother_restart_gaussian must be true or false, got "
                              f"{shorten(repr(flt['smoother_restart_gaussian']))}")
        setup_kw["smoother_restart_gaussian"] = flt["smoother_restart_gaussian"]
    setup_kw["smoother_restart_discrepancy"] = options["discrepancy"]
    setup_kw["smoother_restart_discrepancy_time"] = options["discrepancy_time"]


def model_error_settings(flt: dict, setup_kw: dict) -> None:
    """[filter.model_error] and [filter.adaptive_inflation] into TissueFilterSetup arguments."""
    me = check_keys("filter.model_error", flt.get("model_error", {}), MODEL_ERROR_KEYS)
    # structured unless the config says otherwise: measured data never come from the
    # filter's own model (docs/enkf.md, validation/reports/model_error_coverage.md)
    kind = me.get("kind", "structured")
    if kind not in ("structured", "white"):
        raise ConfigError(f"filter.model_error.kind must be \"structured\" or \"white\", got "
                          f"{shorten(repr(kind))}")
    setup_kw["model_error"] = kind
    for k, hi in (("rel_std", 10.0), ("time_scale", 1e6), ("length_xy", 1e3), ("length_z", 1e3)):
        if k in me:
            setup_kw[f"model_error_{k}"] = num(f"filter.model_error.{k}", me[k], lo=0, hi=hi)
    ai = check_keys("filter.adaptive_inflation", flt.get("adaptive_inflation", {}),
                    ADAPTIVE_KEYS)
    if "enabled" in ai:
        if not isinstance(ai["enabled"], bool):
            raise ConfigError(f"filter.adaptive_inflation.enabled must be true or false, got "
                              f"{shorten(repr(ai['enabled']))}")
        setup_kw["adaptive_inflation"] = ai["enabled"]
    if "bounds" in ai:
        lo, hi = pair("filter.adaptive_inflation.bounds", ai["bounds"], positive=True)
        if not (lo <= hi <= 1e4):
            raise ConfigError(f"filter.adaptive_inflation.bounds must be [lo, hi] with "
                              f"0 < lo <= hi <= 1e4, got {[lo, hi]}")
        setup_kw["adaptive_inflation_bounds"] = (lo, hi)
    if "time_scale" in ai:
        setup_kw["adaptive_inflation_time_scale"] = num(
            "filter.adaptive_inflation.time_scale", ai["time_scale"], lo=1, hi=1e9)
