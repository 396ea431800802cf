"""The number checks of an identification config: each key's limit (:data:`LIMITS`) and
:func:`num`, :func:`pair`, :func:`points`, which raise a ConfigError naming the key."""

from __future__ import annotations

import numpy as np

from fem.checks import check_number, shorten
from mcmatlab_py.config import ConfigError

__all__ = ["LIMITS", "drift_form", "num", "pair", "points"]


#: upper limits of the config's numbers: far beyond any use, small enough that nothing
#: overflows (filter.model_noise_std = 1e300 gave a traceback): deg C^2, Hz, deg C, log
#: units, cm, counts, s
LIMITS = {"sensors.noise_var": 1e4, "sensors.camera.noise_var": 1e4,
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


def drift_form(name: str, value, lo: int = 2):
    """A form of the drift's path in the config: a count of knots (``lo`` to 50) or
    ``"logistic"`` (:mod:`enkf.tissue.paths`)."""
    if value == "logistic":
        return "logistic"
    if isinstance(value, str):
        raise ConfigError(f"{name} must be a count of knots or \"logistic\", got {value!r}")
    return int(num(name, value, integer=True, lo=lo, hi=50))


def num(key, v, *, positive=False, integer=False, lo=None, hi=None):
    """:func:`fem.checks.check_number` with the key's limit from :data:`LIMITS`."""
    if hi is None:
        hi = LIMITS.get(key.split("[")[0])
    if positive:
        lo = 0.0
    return check_number(key, v, integer=integer, lo=lo, hi=hi, lo_open=positive,
                        error=ConfigError)


def pair(key, v, positive=False):
    if not isinstance(v, list) or len(v) != 2:
        raise ConfigError(f"{key} must be [lo, hi], got {shorten(repr(v))}")
    lo, hi = (num(f"{key}[{i}]", x, positive=positive) for i, x in enumerate(v))
    if not lo < hi:
        raise ConfigError(f"{key} must have lo < hi, got {shorten(repr(v))}")
    return (lo, hi)


def points(key, v, G) -> np.ndarray:
    if not isinstance(v, list) or not all(isinstance(r, list) and len(r) == 3 for r in v):
        raise ConfigError(f"{key} must be a list of [x, y, z] points in cm, got {shorten(repr(v))}")
    pts = np.array([[num(f"{key}[{i}][{j}]", c) for j, c in enumerate(r)]
                    for i, r in enumerate(v)], dtype=float).reshape(-1, 3)
    tol = 1e-9
    for i, (x, y, z) in enumerate(pts):
        if not (abs(x) <= G.Lx / 2 + tol and abs(y) <= G.Ly / 2 + tol and -tol <= z <= G.Lz + tol):
            raise ConfigError(f"{key}[{i}] = {[float(x), float(y), float(z)]} cm is outside the tissue "
                              f"(x, y in [-{G.Lx / 2}, {G.Lx / 2}], z in [0, {G.Lz}])")
    return pts
