"""Point location in tetrahedral meshes: containing element and barycentrics.

A uniform bucket grid over the mesh's bounding box lists the elements whose
bounding boxes overlap each bucket; a point is tested against its bucket's
elements only.  The grid is built once per mesh and cached on it.
"""

from __future__ import annotations

import numpy as np

from . import _kernels

__all__ = ["locate"]


class _Buckets:
    def __init__(self, mesh):
        p = np.ascontiguousarray(mesh.p, dtype=np.float64)
        t = np.ascontiguousarray(mesh.t, dtype=np.int64)
        lo, hi = p.min(axis=1), p.max(axis=1)
        ext = np.maximum(hi - lo, 1e-12 * max(float(np.max(hi - lo)), 1e-300))
        ne = t.shape[1]
        # about one bucket per 2 elements, shaped like the box
        cell = (np.prod(ext) / max(ne / 2.0, 1.0)) ** (1.0 / 3.0)
        nb = np.clip(np.ceil(ext / cell), 1, 512).astype(np.int64)
        self.p, self.t, self.lo = p, t, lo
        self.inv_h = nb / ext
        self.nb = nb
        self.start, self.items = _kernels.build_buckets(p, t, lo, self.inv_h, nb)


def locate(mesh, points, tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """Containing element and barycentric coordinates of points.

    Parameters
    ----------
    mesh : skfem.MeshTet
    points : array (3, n)
        cm, as ``mesh.p``.
    tol : float
        Barycentric tolerance: points up to ``tol`` (relative to the element
        size) outside an element still count as inside, so points on faces,
        edges and vertices are found.

    Returns
    -------
    elem : int64 array (n,)
        Containing element, -1 for points outside the mesh.
    bary : float array (4, n)
        Barycentric weights of ``mesh.t[:, elem]``, in [0, 1], summing to 1
        (0 where ``elem == -1``).
    """
    x = np.ascontiguousarray(points, dtype=np.float64)
    b = getattr(mesh, "_fem_buckets", None)
    if b is None or b.p.shape != mesh.p.shape or b.t.shape != mesh.t.shape:
        b = _Buckets(mesh)
        try:
            mesh._fem_buckets = b
        except AttributeError:  # pragma: no cover
            pass
    n = x.shape[1]
    elem = np.empty(n, dtype=np.int64)
    bary = np.zeros((4, n))
    _kernels.locate_points(x, b.p, b.t, b.lo, b.inv_h, b.nb, b.start, b.items, tol, elem, bary)
    return elem, bary
