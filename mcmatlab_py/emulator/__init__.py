"""The filter's forward model of the absorption: NA(mua, mus) from a table of Monte Carlo
runs (:mod:`~mcmatlab_py.emulator.absorption`), built point by point
(:mod:`~mcmatlab_py.emulator.table`) or one white Monte Carlo run per column
(:mod:`~mcmatlab_py.emulator.white`), cached (:mod:`~mcmatlab_py.emulator.cache`), over more
inputs (:mod:`~mcmatlab_py.emulator.media`), and its exact mode
(:mod:`~mcmatlab_py.emulator.exact`). It uses the Monte Carlo; nothing of MCmatlab's
classes imports it."""

from ._interp import interpolate_log_na
from .absorption import AbsorptionEmulator, check_range
from .cache import (
    METHODS,
    WHITE_VERSION,
    cache_key,
    default_cache_dir,
    entry_problem,
    load_cached,
    resolve_method,
    store_atomically,
    usable_cache_dir,
)
from .exact import DirectMonteCarloAbsorption, direct_member
from .media import BeamRadiusEmulator, NodeGridEmulator, TwoMediaEmulator, lagrange_weights
from .spec import CACHE_VERSION, EMULATED_SOURCES, NA_OFFSET, EmulatorSpec, check_emulated
from .table import symmetrize, table_point, table_row, table_rows
from .white import white_absorbed, white_column, white_obstacle, white_supported

__all__ = [
    "CACHE_VERSION", "EMULATED_SOURCES", "METHODS", "NA_OFFSET", "WHITE_VERSION",
    "AbsorptionEmulator", "BeamRadiusEmulator", "DirectMonteCarloAbsorption", "EmulatorSpec",
    "NodeGridEmulator", "TwoMediaEmulator", "cache_key", "check_emulated", "check_range",
    "default_cache_dir", "direct_member", "entry_problem", "interpolate_log_na",
    "lagrange_weights", "load_cached", "resolve_method", "store_atomically", "symmetrize",
    "table_point", "table_row", "table_rows", "usable_cache_dir", "white_absorbed",
    "white_column", "white_obstacle", "white_supported",
]
