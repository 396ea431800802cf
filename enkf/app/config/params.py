"""The parameters of an identification config: their names, priors, bounds and the
damage-driven optics (``[filter.prior]``, ``[filter.bounds]``, ``[filter.coagulation]``).

They map onto :class:`~enkf.tissue.ParameterModel`.
"""

from __future__ import annotations

import numpy as np

from fem.checks import shorten
from mcmatlab_py.config import ConfigError, check_keys

from ...tissue.parameters import (
    BEAM_NAMES,
    COAGULATION_NAMES,
    ESTIMATES,
    PARAMETER_NAMES,
    PRIOR_FACTORS,
    SECOND_MEDIUM_NAMES,
    default_prior,
    parameter_names,
)
from .numbers import drift_form, num, pair

#: keys of [filter.coagulation] (enkf.tissue.coagulation.Coagulation)
COAGULATION_KEYS = {"E", "A", "nominal_factor", "weight_exponent", "mean_field_rel_std"}

__all__ = ["COAGULATION_KEYS", "DRIFT_KEYS", "bounds_settings", "coagulation_settings",
           "drift_settings", "filtered_names", "nominal_of", "prior_of", "prior_settings"]


#: every name [filter.prior] and [filter.bounds] may hold
_KNOWN = set(PARAMETER_NAMES) | set(COAGULATION_NAMES) | set(SECOND_MEDIUM_NAMES) | set(BEAM_NAMES)


def filtered_names(setup_kw: dict) -> tuple:
    """The filtered parameters of these settings (``estimate``, with the coagulated optics
    under ``parameter_model = "coagulation"``)."""
    return parameter_names(setup_kw.get("estimate", ESTIMATES[0]),
                           setup_kw.get("parameter_model", "random_walk"))


def _not_estimated(key: str, name: str, setup_kw: dict) -> ConfigError:
    why = (" (only with filter.parameter_model = \"coagulation\")" if name in COAGULATION_NAMES
           else f" (filter.estimate = {list(setup_kw.get('estimate', ESTIMATES[0]))})")
    return ConfigError(f"{key}.{name}: {name} is not estimated{why}")


def coagulation_settings(flt: dict, setup_kw: dict) -> None:
    """``[filter.coagulation]``: the Arrhenius law and nominal coagulated optics."""
    table = check_keys("filter.coagulation", flt.get("coagulation", {}), COAGULATION_KEYS)
    if setup_kw.get("parameter_model") != "coagulation":
        if table:
            raise ConfigError("[filter.coagulation] is given but filter.parameter_model is "
                              f"{setup_kw.get('parameter_model', 'random_walk')!r}: set "
                              "filter.parameter_model = \"coagulation\" or drop the table")
        return
    from ...tissue.coagulation import Coagulation

    kw = {k: num(f"filter.coagulation.{k}", table[k], positive=True)
          for k in ("E", "A", "weight_exponent") if k in table}
    if "mean_field_rel_std" in table:
        kw["mean_field_rel_std"] = num("filter.coagulation.mean_field_rel_std",
                                             table["mean_field_rel_std"], lo=0.0)
    if "nominal_factor" in table:
        f = table["nominal_factor"]
        if not (isinstance(f, list) and len(f) == 2):
            raise ConfigError(f"filter.coagulation.nominal_factor must be [mua, mus] (coagulated "
                              f"over native), got {shorten(repr(f))}")
        kw["nominal_factor"] = tuple(num(f"filter.coagulation.nominal_factor[{i}]", v,
                                          positive=True) for i, v in enumerate(f))
    setup_kw["coagulation"] = Coagulation(**kw)


def prior_settings(table, setup_kw: dict) -> dict:
    """``[filter.prior]``: a uniform prior [lo, hi] in physical units per parameter."""
    names = filtered_names(setup_kw)
    table = check_keys("filter.prior", table, _KNOWN)
    extra = sorted(set(table) - set(names))
    if extra:
        raise _not_estimated("filter.prior", extra[0], setup_kw)
    return {name: pair(f"filter.prior.{name}", table[name], positive=True) for name in table}


def prior_of(name: str, setup_kw: dict, medium, where: str = "G.media[0]"
             ) -> tuple[tuple[float, float], str]:
    """The prior range of ``name`` and where it comes from (for error messages);
    ``where``: the estimated medium's place in the config."""
    if name in setup_kw.get("prior", {}):
        return setup_kw["prior"][name], f"filter.prior.{name}"
    lo_f, hi_f = setup_kw.get("prior_range", (0.5, 2.0))
    v = nominal_of(name, setup_kw, medium)
    if name in SECOND_MEDIUM_NAMES:  # the second estimated medium's mua or mus
        return (lo_f * v, hi_f * v), f"filter.prior_range times {medium.where2}.{name[:3]}"
    if name in PRIOR_FACTORS:  # an input known to some percent (the beam's radius)
        return (default_prior(name, v, (lo_f, hi_f)),
                f"{list(PRIOR_FACTORS[name])} times MC.light_source.radius")
    if name in COAGULATION_NAMES:
        return (lo_f * v, hi_f * v), (f"filter.prior_range times filter.coagulation."
                                      f"nominal_factor times {where}.{name[:3]}")
    return (lo_f * v, hi_f * v), f"filter.prior_range times {where}.{name}"


def nominal_of(name: str, setup_kw: dict, medium) -> float:
    """The nominal value of ``name``: the medium's, or its coagulated multiple."""
    if name in COAGULATION_NAMES:
        native = {"mua": medium.mua, "mus": medium.mus}
        return setup_kw["coagulation"].nominal(native)[name]
    return getattr(medium, name)


def bounds_settings(table, setup_kw: dict, medium, where: str = "G.media[0]"
                    ) -> np.ndarray | None:
    """``[filter.bounds]``: the physical range of each estimated parameter's mean."""
    from ...tissue import default_bounds

    names = filtered_names(setup_kw)
    table = check_keys("filter.bounds", table, _KNOWN)
    if not table:
        return None
    extra = sorted(set(table) - set(names))
    if extra:
        raise _not_estimated("filter.bounds", extra[0], setup_kw)
    out = []
    for name in names:
        nominal = nominal_of(name, setup_kw, medium)
        (p_lo, p_hi), source = prior_of(name, setup_kw, medium, where)
        lo, hi = default_bounds([nominal], [p_lo], [p_hi])[0]
        if name in table:
            lo, hi = pair(f"filter.bounds.{name}", table[name], positive=True)
            if not (lo <= p_lo and p_hi <= hi):
                raise ConfigError(f"filter.bounds.{name} = {[lo, hi]} must contain the prior "
                                  f"[{p_lo:g}, {p_hi:g}] ({source})")
        out.append((lo, hi))
    return np.array(out)


#: keys of [filter.drift] (enkf.tissue.drift.DriftBank, and ``mode``)
DRIFT_KEYS = {"mode", "walk_std", "switch_prob", "prior_weight", "restart_weight",
              "restart_delay", "restart_knots", "restart_discrepancy", "rtps"}


def drift_settings(flt: dict, setup_kw: dict) -> None:
    """``[filter.drift]``: whether the data decide if the optics drift (``mode = "auto"``,
    the default: a :class:`~enkf.tissue.drift.DriftBank` of a still and a drifting filter)
    or the filter runs as configured (``"none"``). ``"auto"`` needs
    ``parameter_model = "random_walk"``; with the trend or coagulation model, left out, the
    mode is ``"none"``."""
    from ...tissue.drift import DriftBank

    table = check_keys("filter.drift", flt.get("drift", {}), DRIFT_KEYS)
    model = setup_kw.get("parameter_model", "random_walk")
    mode = table.get("mode", "auto" if model == "random_walk" else "none")
    if mode not in ("auto", "none"):
        raise ConfigError(f"filter.drift.mode must be \"auto\" or \"none\", got "
                          f"{shorten(repr(mode))}")
    if mode == "none":
        return
    if model != "random_walk":
        raise ConfigError(f"filter.drift.mode = \"auto\" needs filter.parameter_model = "
                          f"\"random_walk\", got {model!r}: set filter.drift.mode = \"none\"")
    kw = {}
    if "walk_std" in table:
        w = table["walk_std"]
        if not (isinstance(w, list) and len(w) == 2):
            raise ConfigError(f"filter.drift.walk_std must be [mua, mus] (log units per step), "
                              f"got {shorten(repr(w))}")
        kw["walk_std"] = tuple(num(f"filter.drift.walk_std[{i}]", v, positive=True, hi=10.0)
                               for i, v in enumerate(w))
    for k, lim in (("switch_prob", dict(lo=0, hi=0.5)), ("prior_weight", dict(positive=True, hi=1)),
                   ("restart_weight", dict(lo=0, hi=1)), ("restart_delay", dict(lo=0, hi=1e6)),
                   ("restart_discrepancy", dict(lo=0, hi=10.0)), ("rtps", dict(lo=0, hi=1))):
        if k in table:
            kw[k] = num(f"filter.drift.{k}", table[k], **lim)
    if "restart_knots" in table:
        k = table["restart_knots"]
        if not isinstance(k, list) or not k:
            raise ConfigError(f"filter.drift.restart_knots must be a list of forms (integers "
                              f">= 2, \"logistic\"), got {shorten(repr(k))}")
        kw["restart_knots"] = tuple(drift_form(f"filter.drift.restart_knots[{i}]", v)
                                    for i, v in enumerate(k))
    if "image" in setup_kw:  # a camera: the restarts' smoother takes no discrepancy (its
        # dense covariance over every pixel and reading would not fit), as smoother_* does
        if kw.get("restart_discrepancy", 0.0) > 0:
            raise ConfigError(f"filter.drift.restart_discrepancy = {kw['restart_discrepancy']:g} "
                              "is for point sensors: with [sensors.camera] its covariance over "
                              "every pixel and reading is too large; set it to 0")
        kw["restart_discrepancy"] = 0.0
    try:
        setup_kw["drift"] = DriftBank(**kw)
    except ValueError as err:
        raise ConfigError(str(err).replace("DriftBank.", "filter.drift.")) from None
