"""Point probes: P1 interpolation of nodal fields at sensor positions."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .locate import locate

__all__ = ["GroupMaxima", "probe_matrix"]


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


class GroupMaxima:
    """The highest value each group of nodes has reached (e.g. each medium's nodes), kept
    up to date after every step in one pass over the nodes.

    Parameters
    ----------
    groups : sequence of int arrays
        The node indices of each group (a group may be empty; groups may share nodes).
    """

    def __init__(self, groups):
        from ._kernels import group_maxima

        self._kernel = group_maxima
        groups = [np.asarray(g, dtype=np.int64).ravel() for g in groups]
        self.nodes = np.concatenate(groups) if groups else np.zeros(0, np.int64)
        self.starts = np.concatenate([[0], np.cumsum([g.size for g in groups])]).astype(np.int64)
        self.highest = int(self.nodes.max()) if self.nodes.size else -1

    def update(self, values: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``out[g] = max(out[g], values[group g].max())``, in place ((ngroups,) float64);
        an empty group leaves its entry."""
        values = np.ascontiguousarray(values, dtype=np.float64)
        if self.highest >= values.size:
            raise ValueError(f"the groups hold node {self.highest}, the values only "
                             f"{values.size}")
        if out.dtype != np.float64 or out.shape != (self.starts.size - 1,):
            raise ValueError(f"out must be ({self.starts.size - 1},) float64, got "
                             f"{out.dtype} {out.shape}")
        self._kernel(values, self.nodes, self.starts, out)
        return out
