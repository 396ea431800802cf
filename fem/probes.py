"""Point probes: P1 interpolation of nodal fields at sensor positions."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .locate import locate

__all__ = ["probe_matrix"]


def probe_matrix(mesh, points) -> sp.csr_matrix:
    """Sparse P1 interpolation operator at points.

    Parameters
    ----------
    mesh : skfem.MeshTet
    points : array (3, n) or (3,)
        cm, as ``mesh.p`` (a list of ``(x, y, z)`` sensor rows must be
        transposed).  Points on faces, edges or vertices of elements and on
        the mesh boundary (e.g. ``(0, 0, 0)`` on the top surface) are fine.

    Returns
    -------
    scipy.sparse.csr_matrix
        Shape (n, npoints), the barycentric weights of each point's
        containing element: ``T_probe = P @ T`` for T (npoints,), or
        ``T @ P.T`` for an ensemble (N, npoints).  Exact for fields linear on
        each element.

    Raises
    ------
    ValueError
        For a point outside the mesh (naming it) or a bad shape.
    """
    x = np.asarray(points, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] != 3:
        raise ValueError(f"points must have shape (3, n) like mesh.p, got {np.shape(points)}")
    if not np.all(np.isfinite(x)):
        raise ValueError("points must be finite")
    elem, bary = locate(mesh, x)
    out = np.flatnonzero(elem < 0)
    if out.size:
        q = int(out[0])
        raise ValueError(f"points[:, {q}] = {tuple(x[:, q].tolist())} is outside the mesh")
    n = x.shape[1]
    # four entries per point, row by row: CSR directly (a COO of 4 n entries and its
    # conversion cost ~100 bytes per point more at the peak)
    idx = np.int32 if max(mesh.p.shape[1], 4 * n) < 2**31 else np.int64
    indices = mesh.t[:, elem].T.astype(idx).ravel()
    indptr = np.arange(0, 4 * n + 1, 4, dtype=idx)
    # the four vertices of an element are distinct nodes: no duplicate entries
    return sp.csr_matrix((bary.T.ravel(), indices, indptr), shape=(n, mesh.p.shape[1]))
