"""MCmatlab's property names to this port's, read from the classes themselves.

A name is looked up on the class it belongs to (``model.MC.lightSource`` is a
:class:`~mcmatlab_py.LightSource`): its own fields and properties, compared without
case or underscores (``nPhotonsRequested`` is ``n_photons_requested``, ``XDistr`` is
``x_distr``, ``GPUdevice`` is ``gpu_device``), then the class's ``_renamed`` table
(``LS``, ``FPID``, ``fieldSize``). The names that need more than a rename are in
:data:`SPECIAL`; names of features this port does not have raise :class:`Unconvertible`
with the reason the class itself gives.
"""

from __future__ import annotations

import re

from ..fluorescence import FluorescenceMonteCarloSimulation
from ..geometry.cuboid import Geometry
from ..geometry.media import Medium
from ..heat.simulation import HeatSimulation
from ..light.collector import DepositionCriteria, LightCollector
from ..light.source import IntensityDistribution, LightSource
from ..monte_carlo.simulation import MonteCarloSimulation

__all__ = ["MEDIUM_FIELDS", "SPECIAL", "Unconvertible", "child_class", "python_name", "root_class"]


class Unconvertible(Exception):
    """A construct the converter cannot translate; the message says why (and what to do)."""


#: model.X -> class
_ROOT = {"G": Geometry, "MC": MonteCarloSimulation, "FMC": FluorescenceMonteCarloSimulation,
         "HS": HeatSimulation}
#: (class, our field) -> class of that field
_CHILD = {
    (MonteCarloSimulation, "light_source"): LightSource,
    (MonteCarloSimulation, "light_collector"): LightCollector,
    (MonteCarloSimulation, "deposition_criteria"): DepositionCriteria,
    (LightSource, "focal_plane_intensity_distribution"): IntensityDistribution,
    (LightSource, "angular_intensity_distribution"): IntensityDistribution,
}
for (_cls, _name), _child in list(_CHILD.items()):
    if _cls is MonteCarloSimulation:
        _CHILD[(FluorescenceMonteCarloSimulation, _name)] = _child

#: (owner label, MCmatlab name) -> what the translator does with it (see translate.py)
SPECIAL = {
    ("G", "mediaPropertiesFunc"): "media_func",
    ("G", "mediaPropParams"): "media_params",
    ("G", "silentMode"): "silent",
    ("G", "M_raw"): "m_raw",
    ("MC", "silentMode"): "silent",
    ("FMC", "silentMode"): "silent",
    ("HS", "silentMode"): "silent",
    ("MC", "useAllCPUs"): "all_cpus",
    ("FMC", "useAllCPUs"): "all_cpus",
    ("HS", "useAllCPUs"): "all_cpus",
    ("MC", "matchedInterfaces"): "matched",
    ("FMC", "matchedInterfaces"): "matched",
    ("HS", "T"): "hs_T",
    ("HS", "Tinitial"): "hs_T",  # MCmatlab 3's start temperature (MCmatlab 4: HS.T)
    ("HS", "Omega"): "hs_Omega",
    ("MC", "P"): "mc_P",
    ("MC", "FRinitial"): "FR",
    ("FMC", "FRinitial"): "FR",
    ("MC.deposition_criteria", "minMediumIdxToConsider"): "medium_index",
    ("MC.deposition_criteria", "maxMediumIdxToConsider"): "medium_index",
}

#: MCmatlab's mediumProperties fields -> Medium's keyword arguments
MEDIUM_FIELDS = {"name": "name", "mua": "mua", "mus": "mus", "g": "g", "n": "n", "VHC": "VHC",
                 "TC": "TC", "E": "E", "A": "A", "nBins": "n_bins", "QY": "QY", "ES": "ES",
                 "customPhaseFunc": "custom_phase_func"}
#: optical properties take (wavelength, FR, T, FD); thermal ones (T, FD)
OPTICAL_ARGS = ("wavelength", "FR", "T", "FD")
THERMAL_ARGS = ("T", "FD")


def _squash(name: str) -> str:
    return name.replace("_", "").lower()


def _identifier(text: str) -> bool:
    return re.fullmatch(r"[A-Za-z_]\w*", text) is not None


def root_class(name: str):
    """The class of ``model.<name>`` (``G``, ``MC``, ``FMC``, ``HS``)."""
    if name not in _ROOT:
        raise Unconvertible(f"model.{name} is not a part of a MCmatlab model (G, MC, FMC, HS)")
    return _ROOT[name]


def child_class(cls, field: str):
    """The class of the object in ``cls``'s ``field``, or None for a plain value."""
    return _CHILD.get((cls, field))


def label(cls) -> str:
    return getattr(cls, "_owner_label", cls.__name__)


def python_name(cls, name: str) -> str:
    """Our name of MCmatlab's property ``name`` of ``cls``; :class:`Unconvertible` if none."""
    known = cls._known_attributes()
    if name in known:
        return name
    by_squash = {_squash(k): k for k in known}
    if _squash(name) in by_squash:
        return by_squash[_squash(name)]
    renamed = cls._renamed.get(name)
    if renamed is not None and _identifier(renamed) and renamed in known:
        return renamed
    err = cls._unknown(name)
    raise Unconvertible(str(err))


def medium_field(name: str) -> str:
    if name in MEDIUM_FIELDS:
        return MEDIUM_FIELDS[name]
    raise Unconvertible(str(Medium._unknown(name)))
