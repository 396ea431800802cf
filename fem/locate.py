"""Point location in tetrahedral meshes: containing element and barycentrics.

On the structured Kuhn meshes of :func:`fem.mesh.box_mesh` the containing element
follows from the coordinates (the voxel, then the simplex whose path orders the axes by
decreasing local coordinate): no search structure at all. On other meshes a uniform
bucket grid over the bounding box lists the elements whose bounding boxes overlap each
bucket; a point is tested against its bucket's elements only. That grid is built once
per mesh and cached on it (about 0.9 KB per node: the reason for the structured path,
which heat runs on 10^6-node boxes would otherwise pay in memory).
"""

from __future__ import annotations

import numpy as np

from . import _kernels
from .mesh import _KUHN, KUHN_PATHS, structured_grid

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
    grid = structured_grid(mesh)
    if grid is not None:
        return _locate_structured(mesh, grid, x, tol)
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


# KUHN_PATHS[s] is the axis order of simplex s: the code 3 * first + second -> s
_PATH_OF_ORDER = np.full(9, -1, dtype=np.int64)
_PATH_OF_ORDER[3 * KUHN_PATHS[:, 0] + KUHN_PATHS[:, 1]] = np.arange(len(KUHN_PATHS))
#: the simplices whose last two vertices box_mesh swapped (orientation): (6,) bool
_SWAPPED = np.array([tuple(_KUHN[s, 2]) != tuple(np.eye(3, dtype=np.int64)[p[:2]].sum(axis=0))
                     for s, p in enumerate(KUHN_PATHS)])


def _locate_structured(mesh, grid, x: np.ndarray, tol: float):
    """:func:`locate` on ``box_mesh(grid)``: voxel and Kuhn simplex from the coordinates
    (:func:`fem._kernels.locate_structured`, one pass, no temporaries)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    n = x.shape[1]
    elem = np.empty(n, dtype=np.int64)
    bary = np.empty((4, n))
    _kernels.locate_structured(x, np.asarray(grid.lower, dtype=np.float64),
                               np.asarray(grid.spacing, dtype=np.float64),
                               np.asarray(grid.shape, dtype=np.int64), _PATH_OF_ORDER,
                               _SWAPPED, float(tol), elem, bary)
    return elem, bary
