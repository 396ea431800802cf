"""Media evaluated on the voxels, and split into sub-media (MCmatlab's ``nBins``).

A medium whose ``mua``, ``mus`` or ``g`` depends on fluence rate, temperature or
fractional damage has different properties in every voxel; the Monte Carlo kernel
takes one set per medium. As MCmatlab does (``getOpticalMediaProperties``,
``getThermalMediaProperties`` and its ``getDownsampledParamVals``), such a medium is
split into ``n_bins`` sub-media: each property is scaled to unit range over the
medium's voxels, ``n_bins`` representative voxels are picked by farthest-point
sampling (the first the farthest from the mean, each next the farthest from those
picked), every voxel joins its nearest representative, and the sub-media are the
representatives' values, sorted. Media that depend on nothing but wavelength keep one
sub-medium each and the medium map unchanged, so that plain media run exactly as before.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .media import OPTICAL_FIELDS, THERMAL_FIELDS, Medium

__all__ = [
    "OpticalMediaProperties",
    "ThermalMediaProperties",
    "farthest_point_bins",
    "optical_media_properties",
    "state_field",
    "thermal_media_properties",
]


@dataclass
class OpticalMediaProperties:
    """The sub-media the Monte Carlo runs on (MCmatlab's ``MC.mediaProperties`` and ``MC.M``)."""

    mua: np.ndarray  #: (n_sub,) cm^-1
    mus: np.ndarray  #: (n_sub,) cm^-1
    g: np.ndarray  #: (n_sub,) anisotropy
    n: np.ndarray  #: (n_sub,) refractive index
    parent: np.ndarray  #: (n_sub,) int, index of the medium in ``G.media``
    names: list[str]  #: (n_sub,) the parent media's names
    M: np.ndarray  #: (nx, ny, nz) int32 sub-medium index of every voxel


@dataclass
class ThermalMediaProperties:
    """The sub-media of the heat simulation (MCmatlab's ``HS.mediaProperties`` and ``HS.M``)."""

    VHC: np.ndarray  #: (n_sub,) J cm^-3 K^-1 (NaN where the medium has none)
    TC: np.ndarray  #: (n_sub,) W cm^-1 K^-1 (NaN where the medium has none)
    E: np.ndarray  #: (n_sub,) J/mol (NaN where not given)
    A: np.ndarray  #: (n_sub,) 1/s (NaN where not given)
    parent: np.ndarray  #: (n_sub,) int, index of the medium in ``G.media``
    names: list[str]
    M: np.ndarray  #: (nx, ny, nz) int32 sub-medium index of every voxel


def state_field(owner: str, value, shape: tuple[int, int, int], *, lower: float = -np.inf,
                upper: float = np.inf) -> float | np.ndarray:
    """Check a voxel field given as a number or an array of ``shape``; return it as float(s).

    Raises ValueError naming ``owner`` and the value if it is not finite or outside
    ``[lower, upper]``.
    """
    if isinstance(value, bool):
        raise ValueError(f"{owner} must be a number or an array of shape {shape}, got {value!r}")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{owner} must be a number or an array of shape {shape}, "
                         f"got {value!r}") from None
    if arr.ndim != 0 and arr.shape != tuple(shape):
        raise ValueError(f"{owner} must be a number or an array of shape {shape}, "
                         f"got shape {arr.shape}")
    bad = ~np.isfinite(arr) | (arr < lower) | (arr > upper)
    if bad.any():
        v = float(arr[bad].flat[0]) if arr.ndim else float(arr)
        raise ValueError(f"{owner} must be finite and in [{lower}, {upper}], got {v!r}")
    return float(arr) if arr.ndim == 0 else arr


def farthest_point_bins(values: np.ndarray, n_bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Split ``n`` points into ``n_bins`` groups by farthest-point sampling.

    Parameters
    ----------
    values : (n, k) array
        One row of properties per voxel (e.g. mua, mus, g).
    n_bins : int
        Number of representatives (some may be repeats when fewer distinct rows exist).

    Returns
    -------
    reps : (n_bins, k) array
        The representatives' rows, sorted lexicographically.
    labels : (n,) int array
        Index into ``reps`` of each point's nearest representative (in the scaled space).
    """
    values = np.asarray(values, dtype=np.float64)
    n = values.shape[0]
    span = values.max(axis=0) - values.min(axis=0)
    varying = span > 0
    labels = np.zeros(n, dtype=np.int64)
    if not varying.any():
        return np.repeat(values[:1], n_bins, axis=0), labels
    z = values[:, varying] / span[varying]  # each property scaled to unit range
    chosen = [int(np.argmax(((z - z.mean(axis=0)) ** 2).sum(axis=1)))]
    dist = ((z - z[chosen[0]]) ** 2).sum(axis=1)
    for j in range(1, n_bins):
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        d = ((z - z[nxt]) ** 2).sum(axis=1)
        closer = d < dist  # ties stay with the earlier representative
        labels[closer] = j
        dist = np.where(closer, d, dist)
    reps = values[chosen]
    order = np.lexsort(reps.T[::-1])
    rank = np.empty(n_bins, dtype=np.int64)
    rank[order] = np.arange(n_bins)
    return reps[order], rank[labels]


def _voxel_state(field, idx: np.ndarray) -> np.ndarray:
    """(len(idx),) values of a voxel field (a number or an (nx, ny, nz) array) at flat ``idx``."""
    if np.ndim(field) == 0:
        return np.full(idx.size, float(field))
    return np.asarray(field, dtype=np.float64).ravel()[idx]


def _split(media: list[Medium], M: np.ndarray, fields: tuple[str, ...], dependent, evaluate):
    """Shared splitting: ``dependent(m)`` says whether to bin medium m, ``evaluate(m, field,
    idx)`` gives (len(idx),) values of ``field`` on the voxels ``idx`` (flat indices)."""
    flat = M.ravel()
    columns = {f: [] for f in fields}
    parent = []
    M_sub = np.empty_like(flat, dtype=np.int32)
    start = 0
    for i, m in enumerate(media):
        idx = np.flatnonzero(flat == i)
        if not dependent(m):
            for f in fields:
                columns[f].append(np.array([evaluate(m, f, None)]))
            M_sub[idx] = start
            parent.append(i)
            start += 1
            continue
        probe = idx if idx.size else None  # a medium on no voxel: evaluated once at the mean
        size = max(idx.size, 1)
        vals = np.column_stack([np.broadcast_to(np.atleast_1d(evaluate(m, f, probe)), (size,))
                                for f in fields])
        reps, labels = farthest_point_bins(vals, m.n_bins)
        for j, f in enumerate(fields):
            columns[f].append(reps[:, j])
        if idx.size:
            M_sub[idx] = start + labels
        parent.extend([i] * m.n_bins)
        start += m.n_bins
    if start > np.iinfo(np.int32).max:
        raise ValueError(f"too many sub-media ({start})")
    out = {f: np.concatenate(columns[f]) for f in fields}
    return out, np.array(parent, dtype=np.int64), M_sub.reshape(M.shape)


def optical_media_properties(media: list[Medium], M: np.ndarray, wavelength: float | None = None,
                             FR: float | np.ndarray = 0.0, T: float | np.ndarray = 37.0,
                             FD: float | np.ndarray = 0.0) -> OpticalMediaProperties:
    """The Monte Carlo's sub-media at ``wavelength`` (nm) for the voxel fields FR, T, FD.

    Parameters
    ----------
    media : list of Medium
        ``G.media``.
    M : (nx, ny, nz) int array
        Medium index of every voxel (``G.medium_map()``).
    wavelength : float, optional
        nm; needed when a property is a function of wavelength.
    FR, T, FD : float or (nx, ny, nz) array
        Fluence rate (W/cm^2), temperature (deg C) and fractional damage (0..1) seen by
        media whose properties depend on them.

    Returns
    -------
    OpticalMediaProperties
        Plain media give ``M`` itself and one sub-medium each.
    """
    if not any(m.is_state_dependent for m in media):
        mua, mus, g, n = (np.array([m.value(f, wavelength) for m in media], dtype=np.float64)
                          for f in ("mua", "mus", "g", "n"))
        return OpticalMediaProperties(mua, mus, g, n, np.arange(len(media)),
                                      [m.name for m in media], M)

    def evaluate(m: Medium, field: str, idx):
        if field == "n" or idx is None and not m.is_state_dependent:
            return m.value(field, wavelength)
        if idx is None:
            state = [np.atleast_1d(np.mean(s)) for s in (FR, T, FD)]
        else:
            state = [_voxel_state(s, idx) for s in (FR, T, FD)]
        return m.values(field, wavelength, *state)

    fields = (*OPTICAL_FIELDS, "n")
    out, parent, M_sub = _split(list(media), np.asarray(M), fields,
                                lambda m: m.is_state_dependent, evaluate)
    return OpticalMediaProperties(out["mua"], out["mus"], out["g"], out["n"], parent,
                                  [media[p].name for p in parent], M_sub)


def thermal_media_properties(media: list[Medium], M: np.ndarray, T: float | np.ndarray = 37.0,
                             FD: float | np.ndarray = 0.0) -> ThermalMediaProperties:
    """The heat simulation's sub-media for the voxel fields T (deg C) and FD (0..1).

    Media whose ``VHC`` or ``TC`` is a function of (T, FD) are split into ``n_bins``
    sub-media as in :func:`optical_media_properties`; ``E`` and ``A`` carry over.
    """
    def dependent(m: Medium) -> bool:
        return any(m.depends_on_state(f) for f in THERMAL_FIELDS)

    def evaluate(m: Medium, field: str, idx):
        if getattr(m, field) is None:
            return np.full(1 if idx is None else idx.size, np.nan)
        if idx is None and not dependent(m):
            return m.value(field)
        if idx is None:
            T_v, FD_v = (np.atleast_1d(np.mean(s)) for s in (T, FD))
        else:
            T_v, FD_v = (_voxel_state(s, idx) for s in (T, FD))
        return m.values(field, None, np.zeros_like(T_v), T_v, FD_v)

    out, parent, M_sub = _split(list(media), np.asarray(M), THERMAL_FIELDS, dependent, evaluate)
    E = np.array([np.nan if media[p].E is None else media[p].E for p in parent], dtype=float)
    A = np.array([np.nan if media[p].A is None else media[p].A for p in parent], dtype=float)
    return ThermalMediaProperties(out["VHC"], out["TC"], E, A, parent,
                                  [media[p].name for p in parent], M_sub)
