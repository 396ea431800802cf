"""Tables for the transport kernel: custom phase functions and smoothed interface normals.

* :func:`phase_function_tables`: a medium's ``custom_phase_func`` (MCmatlab's
  ``customPhaseFunc``, example 21) tabulated as the density of the scattering angle,
  ``p(theta) sin(theta)`` on ``PHASE_TABLE_SIZE`` equispaced angles in [0, pi], sampled
  exactly as a piecewise-linear density by the kernel (MCmatlab draws from 200 bins).
* :func:`interface_normals`: unit normals of refractive-index interfaces at every voxel,
  the method of MCmatlab (Tran & Jacques 2020, J. Biomed. Opt. 25(2) 025001, example
  17): for each refractive index, the Sobel gradient of the indicator of the voxels
  that have it, smoothed by the penalised least-squares filter of ``smoothn``
  (Garcia 2010, Comput. Stat. Data Anal. 54:1167) with smoothing parameter
  ``max(1, round(smoothing_length_scale / max(dx, dy, dz)))`` as MCmatlab passes it.
  A voxel's normal points into the region of its own refractive index.
"""

from __future__ import annotations

import numpy as np

from ..geometry.media import n_arguments

__all__ = ["interface_normals", "phase_function_table", "phase_function_tables", "smoothn_filter"]

#: nodes of a tabulated phase function (the kernel bisects it: ~12 steps per scattering)
PHASE_TABLE_SIZE = 4001


def phase_function_table(medium, wavelength: float | None = None) -> np.ndarray:
    """(2 * PHASE_TABLE_SIZE,) table of ``medium.custom_phase_func`` (see :func:`pwl_table`).

    The phase function is a function of the scattering angle theta (rad) returning
    values per solid angle, not necessarily normalised: ``f(theta)`` or, as MCmatlab,
    ``f(wavelength, theta)``; or an array of such values at equispaced angles over
    [0, pi] (at least 2).
    """
    from ..light.source import pwl_table

    f = medium.custom_phase_func
    label = f"Medium({medium.name!r}).custom_phase_func"
    if callable(f):
        theta = np.linspace(0.0, np.pi, PHASE_TABLE_SIZE)
        k = n_arguments(f)
        if k == 2:
            if wavelength is None:
                raise ValueError(f"{label} is a function of (wavelength, theta): set "
                                 "MC.wavelength (nm)")
            p = f(wavelength, theta)
        elif k == 1:
            p = f(theta)
        else:
            raise ValueError(f"{label} must be a function of (theta) or (wavelength, theta), "
                             f"got {f!r} taking {k} arguments")
        try:
            p = np.broadcast_to(np.asarray(p, dtype=np.float64), theta.shape)
        except ValueError:
            raise ValueError(f"{label} must return one value per angle (called with an array of "
                             f"{theta.size} angles), got shape {np.shape(p)}") from None
    else:
        p = np.asarray(f, dtype=np.float64)
        theta = np.linspace(0.0, np.pi, p.size)
    q = p * np.sin(theta)
    if not np.all(np.isfinite(q)) or np.any(p < 0) or not q.sum() > 0:
        raise ValueError(f"{label} must give finite, non-negative values, not all zero "
                         "(away from theta = 0 and pi)")
    return pwl_table(q)


def phase_function_tables(media, parent: np.ndarray, wavelength: float | None = None
                          ) -> tuple[np.ndarray, np.ndarray]:
    """``(phase_idx, phase_tab)`` for the kernel.

    ``parent`` (n_sub,) gives the medium of each (sub-)medium the kernel sees.
    ``phase_idx`` (n_sub,) int32 is the row of ``phase_tab`` (n_tables, 2 L) float64
    that a sub-medium scatters with, or -1 for Henyey-Greenstein with its ``g``.
    """
    rows: dict[int, int] = {}
    tabs = []
    for i, m in enumerate(media):
        if getattr(m, "custom_phase_func", None) is not None:
            rows[i] = len(tabs)
            tabs.append(phase_function_table(m, wavelength))
    idx = np.array([rows.get(int(p), -1) for p in parent], dtype=np.int32)
    tab = np.array(tabs) if tabs else np.zeros((1, 2), dtype=np.float64)
    return idx, np.ascontiguousarray(tab, dtype=np.float64)


def smoothn_filter(y: np.ndarray, s: float, spacing) -> np.ndarray:
    """``smoothn`` with a fixed smoothing parameter ``s`` (no robust weights): one DCT filter.

    ``z = IDCT(Gamma * DCT(y))``, ``Gamma = 1 / (1 + s Lambda^2)``, ``Lambda`` the
    eigenvalues of the second-difference operator with spacings relative to the
    largest (Garcia 2010, eq. 13 with order 2).
    """
    from scipy.fft import dctn, idctn

    spacing = np.asarray(spacing, dtype=np.float64)
    rel = spacing / spacing.max()
    lam = np.zeros(y.shape)
    for axis, n in enumerate(y.shape):
        shape = [1] * y.ndim
        shape[axis] = n
        lam = lam + ((2 - 2 * np.cos(np.pi * np.arange(n) / n)) / rel[axis] ** 2).reshape(shape)
    gamma = 1.0 / (1.0 + s * lam**2)
    return idctn(gamma * dctn(y, norm="ortho"), norm="ortho")


def interface_normals(M: np.ndarray, nref: np.ndarray, spacing, smoothing_length_scale: float
                      ) -> np.ndarray:
    """(nx * ny * nz * 3,) float32 unit normals (x, y, z per voxel, C order of (nx, ny, nz)).

    ``M`` (nx, ny, nz) are the medium indices into ``nref`` (refractive indices, inf
    allowed). A zero-length gradient gives a zero vector (the kernel then uses the
    voxel face).
    """
    from scipy.ndimage import sobel

    nmap = nref[M]
    out = np.zeros(M.shape + (3,), dtype=np.float64)
    s = max(1, round(smoothing_length_scale / max(spacing))) if smoothing_length_scale > 0 else 0
    for value in np.unique(nmap):
        mask = nmap == value
        indicator = mask.astype(np.float64)
        for axis in range(3):
            grad = sobel(indicator, axis=axis, mode="nearest") / spacing[axis]
            if s:
                grad = smoothn_filter(grad, s, spacing)
            out[..., axis][mask] = grad[mask]
    norm = np.sqrt((out**2).sum(axis=-1, keepdims=True))
    np.divide(out, norm, out=out, where=norm > 0)
    return np.ascontiguousarray(out, dtype=np.float32).ravel()
