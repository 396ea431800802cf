"""What converted scripts call at run time: :func:`quick`, a small model for tests.

``quick(model)`` does nothing unless the environment variable ``MCMATLAB_PY_QUICK`` is set
(to anything but ``0`` or the empty string). Then every later setting of the model is made
small as it is set: ``G.nx``, ``ny``, ``nz`` at most :data:`QUICK_VOXELS` (odd stays odd,
so that a beam through the centre still runs down a column), photon counts and requested
simulation times become at most :data:`QUICK_PHOTONS` photons, the heat simulation at most
:data:`QUICK_UPDATES` updates per pulse and no movie, and no progress bars. The same
script thus runs in seconds (``validation/port_examples.py``, ``tests/test_port.py``).
"""

from __future__ import annotations

import os
import re

__all__ = ["QUICK_HEAT_MESH", "QUICK_PHOTONS", "QUICK_UPDATES", "QUICK_VOXELS", "quick",
           "quick_enabled", "readtable"]

#: voxels along each axis at most (61 where the script's count is odd): small enough for
#: seconds, large enough that the examples' absolute voxel indices (Example 21's
#: ``M(51,51,:)``) stay inside the grid
QUICK_VOXELS = 60
QUICK_PHOTONS = 2000  #: photons per Monte Carlo run at most
QUICK_UPDATES = 5  #: heat-simulation updates per pulse at most
QUICK_HEAT_MESH = (12, 12, 12)  #: divisions of the heat simulation's mesh

_CLASSES: dict[type, type] = {}


def quick_enabled() -> bool:
    """True when ``MCMATLAB_PY_QUICK`` asks for small runs."""
    return os.environ.get("MCMATLAB_PY_QUICK", "") not in ("", "0")


def _voxels(n):
    if not isinstance(n, int) or n <= QUICK_VOXELS:
        return n
    return QUICK_VOXELS + (n % 2 != QUICK_VOXELS % 2)


def _photons(n):
    return n if n is None else min(int(n), QUICK_PHOTONS)


def _small(owner: str, name: str, value, obj):
    if owner == "G" and name in ("nx", "ny", "nz"):
        return {name: _voxels(value)}
    if owner in ("MC", "FMC"):
        if name == "n_photons_requested":
            return {name: _photons(value)}
        if name == "simulation_time_requested" and value is not None:
            return {name: value, "n_photons_requested": QUICK_PHOTONS}
        if name == "progress":
            return {name: False}
    if owner == "HS":
        if name == "n_updates":
            return {name: min(int(value), QUICK_UPDATES)}
        if name in ("make_movie", "progress"):
            return {name: False}
    return {name: value}


def _quick_class(cls: type) -> type:
    if cls not in _CLASSES:
        owner = cls._owner_label

        def __setattr__(self, name, value):  # noqa: N807 (a method of the class made here)
            for key, v in _small(owner, name, value, self).items():
                super(quick_cls, self).__setattr__(key, v)

        quick_cls = type(f"Quick{cls.__name__}", (cls,), {"__setattr__": __setattr__})
        _CLASSES[cls] = quick_cls
    return _CLASSES[cls]


def quick(model):
    """Make ``model`` small from here on when ``MCMATLAB_PY_QUICK`` is set; returns it.

    The settings already made are made small too. Without the variable, nothing changes.
    """
    if not quick_enabled():
        return model
    for part in ("G", "MC", "FMC", "HS"):
        obj = getattr(model, part)
        if type(obj).__name__.startswith("Quick"):
            continue
        obj.__class__ = _quick_class(type(obj))
        for name, value in list(vars(obj).items()):
            if not name.startswith("_"):
                setattr(obj, name, value)
    model.MC.progress = model.FMC.progress = model.HS.progress = False
    model.HS.make_movie = False
    model.HS.mesh_divisions = QUICK_HEAT_MESH
    return model


def _valid_name(header: str) -> str:
    """MATLAB's ``matlab.lang.makeValidName`` (what ``readtable`` does to column headers)."""
    words = header.strip().split()
    name = words[0] + "".join(w[:1].upper() + w[1:] for w in words[1:]) if words else "Var"
    name = re.sub(r"\W", "_", name)
    return name if name[:1].isalpha() else "x" + name


def readtable(path):
    """MATLAB's ``readtable`` of a text file of numeric columns, with a header line.

    Lines that are not all numbers come before the data; the last of them names the
    columns (tab- or comma-separated, else whitespace), turned into MATLAB's valid names
    (``"##Wavelength (nm)"`` -> ``x__Wavelength_nm_``). Returns an object with one numpy
    array per column.
    """
    from types import SimpleNamespace

    import numpy as np

    header, rows = None, []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            text = line.strip()
            if not text:
                continue
            fields = [f for f in re.split(r"[\t,]+|\s+", text) if f]
            try:
                rows.append([float(f) for f in fields])
            except ValueError:
                if not rows:
                    header = text
    if not rows:
        raise ValueError(f"readtable: no numeric rows in {path!r}")
    width = min(len(r) for r in rows)
    data = np.array([r[:width] for r in rows])
    sep = "\t" if header and "\t" in header else ("," if header and "," in header else None)
    names = [h for h in (header.split(sep) if header else []) if h.strip()]
    names = [_valid_name(h) for h in names][:width]
    names += [f"Var{k + 1}" for k in range(len(names), width)]
    return SimpleNamespace(**{n: data[:, k] for k, n in enumerate(names)})
