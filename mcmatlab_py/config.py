"""TOML configuration -> :class:`~mcmatlab_py.model.Model` (an edge module: imported only when used).

A config mirrors the Python API::

    [G]
    nx = 100            # voxels
    ny = 100
    nz = 50
    Lx = 0.5            # cm
    Ly = 0.5
    Lz = 0.25

    [[G.media]]         # index 0
    name = "standard tissue"
    mua = 1.0           # cm^-1
    mus = 100.0         # cm^-1
    g = 0.9
    n = 1.3
    VHC = 3.76          # J cm^-3 K^-1
    TC = 0.0037         # W cm^-1 K^-1

    [[G.regions]]       # optional boxes filled with another medium, applied in order
    medium = 1
    z_min = 0.1         # cm; x_min, x_max, y_min, y_max, z_min, z_max all optional

    [MC]
    n_photons_requested = 1_000_000
    seed = 1
    matched_interfaces = true
    boundary_type = 1

    [MC.light_source]
    source_type = "tophat"
    radius = 0.1        # cm

Every key is checked: an unknown key, a wrong type or a bad value raises
:class:`ConfigError` (a ``ValueError``) naming the key, the value and what is allowed.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np

from fem.checks import check_number, shorten, unknown_name_hint

from .geometry.media import Medium
from .model import Model

__all__ = ["MAX_CONFIG_BYTES", "ConfigError", "check_keys", "load_model", "model_from_config",
           "read_toml"]


class ConfigError(ValueError):
    """A configuration file that cannot be used; the message names the key and the value."""


_MEDIUM_KEYS = {"name", "mua", "mus", "g", "n", "VHC", "TC", "E", "A"}
_REGION_KEYS = {"medium", "x_min", "x_max", "y_min", "y_max", "z_min", "z_max"}
_G_KEYS = {"nx", "ny", "nz", "Lx", "Ly", "Lz", "media", "regions"}
_MC_KEYS = {
    "n_photons_requested", "simulation_time_requested", "seed", "matched_interfaces",
    "boundary_type", "n_outside", "russian_roulette", "weight_threshold", "roulette_chance",
    "n_threads", "batch_size", "light_source", "wavelength", "smoothing_length_scale",
    # the optional outputs (MCmatlab's light collector, far field, paths, NI maps, MCML's radial
    # tallies) and their tables
    "use_light_collector", "light_collector", "request_collected_photons", "far_field_res",
    "n_example_paths", "calc_normalized_irradiance", "n_radial_bins", "radial_bin_size",
    "n_angle_bins", "deposition_criteria", "calc_normalized_fluence_rate",
}
#: [MC.light_collector]: a lens (f finite) or a fiber (f = inf)
_COLLECTOR_KEYS = {"x", "y", "z", "theta", "phi", "f", "diam", "field_size", "NA", "res",
                   "t_start", "t_end", "n_time_bins"}
#: [MC.deposition_criteria]
_CRITERIA_KEYS = {f"{b}_{what}" for b in ("min", "max")
                  for what in ("scatterings", "refractions", "reflections",
                               "interface_transitions", "medium_idx_to_consider")}
_CRITERIA_KEYS |= {"only_collected", "evaluate_only_at_end_of_life"}
_SOURCE_KEYS = {"source_type", "radius", "x_focus", "y_focus", "z_focus"}
#: the tables of a config file: the model here, the rest for ``tissue-enkf identify``
TOP_LEVEL_KEYS = {"G", "MC", "HS", "sensors", "filter", "data", "run", "advice"}
_HS_KEYS = {
    "P", "duration_on", "duration_off", "n_pulses", "dt", "T_initial", "heat_boundary_type",
    "temp_sensor_positions", "heat_transfer_coefficient", "T_ambient", "theta",
    "mesh_divisions",
}


#: bytes: the largest config file read (the longest example is 8 kB; tomllib needs about ten
#: times a file's size in memory)
MAX_CONFIG_BYTES = 16 * 2**20


def read_toml(path: str | Path) -> dict:
    """Read a TOML file; a missing, unreadable or malformed file, one that is not a regular
    file (a pipe, a FIFO, a device) or one over :data:`MAX_CONFIG_BYTES` raises ConfigError."""
    from .files import read_regular

    path = Path(path)
    # not a pipe, FIFO or device (/dev/zero never ends), and no larger than a config can be
    data = read_regular(path, "config file", MAX_CONFIG_BYTES, error=ConfigError)
    try:
        return tomllib.loads(data.decode("utf-8-sig"))  # a byte-order mark is dropped
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise ConfigError(f"config file {str(path)!r} is not valid TOML: {err}") from None


def check_keys(section: str, table, allowed: set[str]) -> dict:
    """Check that ``table`` is a table whose keys are all in ``allowed``; a ConfigError
    names the first unknown key, the closest allowed one and the allowed keys."""
    if not isinstance(table, dict):
        raise ConfigError(f"[{section}] must be a table, got {shorten(repr(table))}")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise ConfigError(f"unknown key {section}.{shorten(unknown[0])}"
                          f"{unknown_name_hint(unknown[0], allowed)}")
    return table


def _number(key: str, value) -> float:
    return check_number(key, value, allow_inf=True, error=ConfigError)


def _region_map(regions: list) -> callable:
    boxes = []
    for i, region in enumerate(regions):
        key = f"G.regions[{i}]"
        check_keys(key, region, _REGION_KEYS)
        if "medium" not in region:
            raise ConfigError(f"{key}.medium is missing")
        medium = region["medium"]
        if isinstance(medium, bool) or not isinstance(medium, int):
            raise ConfigError(f"{key}.medium must be an integer index into G.media, got "
                              f"{shorten(repr(medium))}")
        bounds = {}
        for b in ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max"):
            v = _number(f"{key}.{b}", region[b]) if b in region else (
                -math.inf if b.endswith("min") else math.inf)
            bounds[b] = v
        boxes.append((medium, bounds))

    def geom_func(X, Y, Z):
        M = np.zeros(X.shape, dtype=int)
        for medium, b in boxes:
            inside = ((X >= b["x_min"]) & (X <= b["x_max"]) & (Y >= b["y_min"])
                      & (Y <= b["y_max"]) & (Z >= b["z_min"]) & (Z <= b["z_max"]))
            M[inside] = medium
        return M

    return geom_func


def _set(obj, section: str, table: dict, skip=()) -> None:
    for k, v in table.items():
        if k in skip:
            continue
        if isinstance(v, dict):
            raise ConfigError(f"{section}.{k} must be a value, got a table")
        if isinstance(getattr(obj, k), bool) and not isinstance(v, bool):
            # a switch (its default is one): "abc", nan or 2 would be taken by truthiness
            raise ConfigError(f"{section}.{k} must be true or false, got {shorten(repr(v))}")
        setattr(obj, k, v)


def _check_hs(table: dict) -> None:
    """Types of the [HS] keys that HeatSimulation.validate leaves to the config."""
    for k in ("T_ambient", "heat_transfer_coefficient"):
        if k in table:
            v = _number(f"HS.{k}", table[k])
            if not math.isfinite(v):
                raise ConfigError(f"HS.{k} must be finite, got {shorten(repr(table[k]))}")
    if "heat_transfer_coefficient" in table and table["heat_transfer_coefficient"] <= 0:
        raise ConfigError(f"HS.heat_transfer_coefficient must be > 0 (W cm^-2 K^-1), got "
                          f"{shorten(repr(table['heat_transfer_coefficient']))}")
    if "mesh_divisions" in table:
        md = table["mesh_divisions"]
        if not (isinstance(md, list) and len(md) == 3 and all(
                isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in md)):
            raise ConfigError(f"HS.mesh_divisions must be [nx, ny, nz], integers >= 1, got "
                              f"{shorten(repr(md))}")


def model_from_config(cfg: dict) -> Model:
    """Build a :class:`Model` from a parsed config; validates the model's G and MC parts."""
    # [sensors], [filter], [data] (identify) and [run] (Dask) are checked by enkf.config
    check_keys("config", cfg, TOP_LEVEL_KEYS)
    if "G" not in cfg:
        raise ConfigError("config has no [G] table (geometry)")
    G_cfg = check_keys("G", cfg["G"], _G_KEYS)
    model = Model()
    media_cfg = G_cfg.get("media")
    if not isinstance(media_cfg, list) or not media_cfg:
        raise ConfigError(f"G.media must be a non-empty array of tables, got {shorten(repr(media_cfg))}")
    media = []
    for i, m in enumerate(media_cfg):
        check_keys(f"G.media[{i}]", m, _MEDIUM_KEYS)
        missing = [k for k in ("mua", "mus") if k not in m]
        if missing:
            raise ConfigError(f"G.media[{i}].{missing[0]} is missing")
        if "name" in m and not isinstance(m["name"], str):
            raise ConfigError(f"G.media[{i}].name must be a string, got {shorten(repr(m['name']))}")
        for k, v in m.items():
            if k != "name":  # the type here, naming the key; the range in Medium
                _number(f"G.media[{i}].{k}", v)
        try:
            media.append(Medium(**{"name": f"medium {i}", **m}))
        except TypeError as err:
            raise ConfigError(f"G.media[{i}]: {err}") from None
        except ValueError as err:
            raise ConfigError(f"G.media[{i}]: {err}") from None
    model.G.media = media
    _set(model.G, "G", G_cfg, skip=("media", "regions"))
    if "regions" in G_cfg:
        if not isinstance(G_cfg["regions"], list):
            raise ConfigError(f"G.regions must be an array of tables, got {shorten(repr(G_cfg['regions']))}")
        model.G.geom_func = _region_map(G_cfg["regions"])
    MC_cfg = check_keys("MC", cfg.get("MC", {}), _MC_KEYS)
    tables = {"light_source": (_SOURCE_KEYS, model.MC.light_source),
              "light_collector": (_COLLECTOR_KEYS, model.MC.light_collector),
              "deposition_criteria": (_CRITERIA_KEYS, model.MC.deposition_criteria)}
    _set(model.MC, "MC", MC_cfg, skip=tuple(tables))
    if isinstance(MC_cfg.get("wavelength"), list):
        # the media of a config are constants: a broadband run would repeat one run
        raise ConfigError(f"MC.wavelength must be one number (nm) in a config file, got "
                          f"{shorten(repr(MC_cfg['wavelength']))}: broadband runs (an array of "
                          "wavelengths) are for the Python API, with media given as functions "
                          "of the wavelength")
    for name, (keys, obj) in tables.items():
        _set(obj, f"MC.{name}", check_keys(f"MC.{name}", MC_cfg.get(name, {}), keys))
    if "HS" in cfg:
        HS_cfg = check_keys("HS", cfg["HS"], _HS_KEYS)
        _check_hs(HS_cfg)
        _set(model.HS, "HS", HS_cfg)
        if "mesh_divisions" in HS_cfg:
            model.HS.mesh_divisions = tuple(HS_cfg["mesh_divisions"])
    try:
        model.G.medium_map()
        model.MC.validate(model.G)
    except ConfigError:
        raise
    except ValueError as err:
        raise ConfigError(str(err)) from None
    return model


def load_model(path: str | Path) -> Model:
    """Read a TOML config file and build its validated :class:`Model`."""
    return model_from_config(read_toml(path))
