"""Structured tetrahedral meshes of a voxel box, element->voxel maps and mesh checks.

Layout (shared by the whole project): a voxel grid has ``(nx, ny, nz)`` cells
with ``x`` in ``[-Lx/2, Lx/2]``, ``y`` in ``[-Ly/2, Ly/2]`` and ``z`` in
``[0, Lz]``; ``z`` points into the tissue and ``z = 0`` is the irradiated top
surface.  A structured mesh of that grid has its nodes at the voxel corners,
numbered in C order of the ``(nx + 1, ny + 1, nz + 1)`` node grid::

    node(i, j, k) = (i * (ny + 1) + j) * (nz + 1) + k

and each voxel ``v = (i * ny + j) * nz + k`` is split into the six Kuhn
(Freudenthal) tetrahedra ``6 v, ..., 6 v + 5``: the path simplices from the
voxel's low corner to its high corner that step once along each axis, in the
six possible axis orders.  They are orthoschemes, so the gradients of the
barycentric functions of their non-path vertices pairs are orthogonal and the
P1 stiffness couples only axis-aligned neighbours (see :func:`box_mesh`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from skfem import MeshTet

from . import _kernels
from .checks import check_number

__all__ = [
    "BoxGrid",
    "box_mesh",
    "check_mesh",
    "element_voxel_index",
    "element_volumes",
    "structured_grid",
]


def _positive_int(name: str, value) -> int:
    return check_number(name, value, integer=True, lo=1)


def _positive_float(name: str, value) -> float:
    return check_number(name, value, lo=0.0, lo_open=True)


@dataclass(frozen=True)
class BoxGrid:
    """A regular voxel grid over the simulation cuboid.

    Describes both the voxel grids of the Monte Carlo model (power density,
    media maps: arrays of shape ``(nx, ny, nz)``) and the structured meshes
    built on them (:meth:`mesh`).
    """

    nx: int  #: number of voxels along x
    ny: int  #: number of voxels along y
    nz: int  #: number of voxels along z (depth)
    Lx: float  #: cm, extent along x; x in [-Lx/2, Lx/2]
    Ly: float  #: cm, extent along y; y in [-Ly/2, Ly/2]
    Lz: float  #: cm, extent along z; z in [0, Lz], z = 0 the top surface

    def __post_init__(self):
        for name in ("nx", "ny", "nz"):
            object.__setattr__(self, name, _positive_int(name, getattr(self, name)))
        for name in ("Lx", "Ly", "Lz"):
            object.__setattr__(self, name, _positive_float(name, getattr(self, name)))

    @property
    def shape(self) -> tuple[int, int, int]:
        """Voxel grid shape ``(nx, ny, nz)``."""
        return (self.nx, self.ny, self.nz)

    @property
    def node_shape(self) -> tuple[int, int, int]:
        """Node grid shape ``(nx + 1, ny + 1, nz + 1)``."""
        return (self.nx + 1, self.ny + 1, self.nz + 1)

    @property
    def nvoxels(self) -> int:
        return self.nx * self.ny * self.nz

    @property
    def npoints(self) -> int:
        """Number of nodes of the structured mesh."""
        return (self.nx + 1) * (self.ny + 1) * (self.nz + 1)

    @property
    def dx(self) -> float:
        """cm, voxel size along x."""
        return self.Lx / self.nx

    @property
    def dy(self) -> float:
        """cm, voxel size along y."""
        return self.Ly / self.ny

    @property
    def dz(self) -> float:
        """cm, voxel size along z."""
        return self.Lz / self.nz

    @property
    def spacing(self) -> tuple[float, float, float]:
        """cm, ``(dx, dy, dz)``."""
        return (self.dx, self.dy, self.dz)

    @property
    def lower(self) -> np.ndarray:
        """cm, shape (3,): the corner ``(-Lx/2, -Ly/2, 0)``."""
        return np.array([-self.Lx / 2, -self.Ly / 2, 0.0])

    @property
    def x_nodes(self) -> np.ndarray:
        """cm, shape (nx + 1,): node (voxel corner) x coordinates."""
        return np.linspace(-self.Lx / 2, self.Lx / 2, self.nx + 1)

    @property
    def y_nodes(self) -> np.ndarray:
        """cm, shape (ny + 1,): node y coordinates."""
        return np.linspace(-self.Ly / 2, self.Ly / 2, self.ny + 1)

    @property
    def z_nodes(self) -> np.ndarray:
        """cm, shape (nz + 1,): node z coordinates (depth)."""
        return np.linspace(0.0, self.Lz, self.nz + 1)

    @property
    def x(self) -> np.ndarray:
        """cm, shape (nx,): voxel centre x coordinates (MCmatlab's ``model.G.x``)."""
        return (np.arange(self.nx) + 0.5) * self.dx - self.Lx / 2

    @property
    def y(self) -> np.ndarray:
        """cm, shape (ny,): voxel centre y coordinates."""
        return (np.arange(self.ny) + 0.5) * self.dy - self.Ly / 2

    @property
    def z(self) -> np.ndarray:
        """cm, shape (nz,): voxel centre z coordinates."""
        return (np.arange(self.nz) + 0.5) * self.dz

    def node_axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Node coordinates along each axis, cm."""
        return (self.x_nodes, self.y_nodes, self.z_nodes)

    def node_index(self, i, j, k):
        """Flat node number of node grid index ``(i, j, k)`` (C order)."""
        return (np.asarray(i) * (self.ny + 1) + np.asarray(j)) * (self.nz + 1) + np.asarray(k)

    def voxel_of_points(self, points: np.ndarray) -> np.ndarray:
        """Voxel index triples of points, shape (3, n) int; -1 where outside.

        Points on an interior voxel face go to the upper voxel, points on the
        upper boundary to the last voxel.
        """
        pts = np.asarray(points, dtype=float)
        out = np.empty(pts.shape, dtype=np.int64)
        for a, (n, h, lo) in enumerate(zip(self.shape, self.spacing, self.lower, strict=True)):
            s = (pts[a] - lo) / h
            idx = np.floor(s).astype(np.int64)
            tol = 1e-9
            idx = np.where((idx == n) & (s <= n + tol), n - 1, idx)
            idx = np.where((idx == -1) & (s >= -tol), 0, idx)
            out[a] = np.where((idx < 0) | (idx >= n), -1, idx)
        return out

    def mesh(self) -> MeshTet:
        """The structured Kuhn mesh of this grid (:func:`box_mesh`)."""
        return box_mesh(self.nx, self.ny, self.nz, self.Lx, self.Ly, self.Lz)


# The six Kuhn simplices of the unit cube: corner offsets (4 vertices x 3 axes)
# along the path 0 -> e_s0 -> e_s0 + e_s1 -> (1, 1, 1).  For odd permutations the
# last two vertices are swapped so that every tetrahedron is positively oriented.
def _kuhn_offsets() -> np.ndarray:
    out = []
    for perm in itertools.permutations(range(3)):
        verts = [np.zeros(3, dtype=np.int64)]
        for axis in perm:
            v = verts[-1].copy()
            v[axis] = 1
            verts.append(v)
        if np.linalg.det(np.array(verts[1:]) - verts[0]) < 0:
            verts[2], verts[3] = verts[3], verts[2]
        out.append(verts)
    return np.array(out)  # (6, 4, 3)


_KUHN = _kuhn_offsets()
#: (6, 3): the axis order of each Kuhn simplex's path, in element order.
KUHN_PATHS = np.array(list(itertools.permutations(range(3))))


def kuhn_path_edges(grid: BoxGrid) -> tuple[np.ndarray, np.ndarray]:
    """Path edges of every element of ``box_mesh(grid)``.

    Returns
    -------
    lower : int64 array (3, nelements)
        Lower node of the element's path edge along x, y and z (row = axis).
    axis_order : int array (6, 3)
        :data:`KUHN_PATHS`.
    """
    i, j, k = np.meshgrid(np.arange(grid.nx), np.arange(grid.ny), np.arange(grid.nz),
                          indexing="ij")
    base = grid.node_index(i.ravel(), j.ravel(), k.ravel())
    strides = np.array([(grid.ny + 1) * (grid.nz + 1), grid.nz + 1, 1])
    lower = np.empty((3, 6, base.size), dtype=np.int64)
    for s, perm in enumerate(KUHN_PATHS):
        off = 0
        for axis in perm:  # the path reaches the edge along `axis` at offset `off`
            lower[axis, s] = base + off
            off += strides[axis]
    return lower.transpose(0, 2, 1).reshape(3, -1), KUHN_PATHS


def box_mesh(nx: int, ny: int, nz: int, Lx: float, Ly: float, Lz: float) -> MeshTet:
    r"""Structured tetrahedral (Kuhn) mesh of the voxel box.

    Parameters
    ----------
    nx, ny, nz : int
        Number of voxels per axis; the mesh has ``(nx+1)(ny+1)(nz+1)`` nodes at
        the voxel corners and ``6 nx ny nz`` elements.
    Lx, Ly, Lz : float
        cm, box extents; ``x`` in ``[-Lx/2, Lx/2]``, ``y`` in ``[-Ly/2, Ly/2]``,
        ``z`` in ``[0, Lz]``.

    Returns
    -------
    skfem.MeshTet
        Nodes numbered in C order of the node grid, elements ``6 v .. 6 v + 5``
        in voxel ``v`` (C order of ``(nx, ny, nz)``), all positively oriented
        (``sort_t=False`` keeps the orientation).

    Notes
    -----
    Each tetrahedron is an orthoscheme :math:`v_0 v_1 v_2 v_3` whose edges
    :math:`v_{i+1} - v_i` are mutually orthogonal.  Its barycentric gradients
    are :math:`\nabla\lambda_0 = -e_{s_0}/h_{s_0}`,
    :math:`\nabla\lambda_i = e_{s_{i-1}}/h_{s_{i-1}} - e_{s_i}/h_{s_i}`,
    :math:`\nabla\lambda_3 = e_{s_2}/h_{s_2}`, so only consecutive path vertices
    (axis-aligned neighbours) couple in the P1 stiffness, with weight
    :math:`-V/h^2 = -h_y h_z / (6 h_x)` for an x step.  Summed over the voxels
    around an edge this is the 7-point stencil (weight :math:`h_y h_z / h_x`
    inside, half of it on a face).  On the twelve edges of the box the split
    is not symmetric: an edge lying on a voxel's Kuhn diagonal plane gets 1/3,
    the others 1/6, of :math:`h_y h_z / h_x` instead of the finite-volume 1/4
    (:mod:`fem.fastdiag` corrects for this exactly).
    """
    grid = BoxGrid(nx, ny, nz, Lx, Ly, Lz)
    xs, ys, zs = grid.node_axes()
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    p = np.vstack([X.ravel(), Y.ravel(), Z.ravel()])

    strides = np.array([(grid.ny + 1) * (grid.nz + 1), grid.nz + 1, 1])
    local = _KUHN @ strides  # (6, 4) node-number offsets from each voxel's low corner
    t = np.empty((4, 6 * grid.nvoxels), dtype=np.int32)
    _kernels.kuhn_elements(grid.nx, grid.ny, grid.nz, local.astype(np.int64), t)
    mesh = MeshTet(p, t, sort_t=False)
    try:  # structured_grid's answer, known here (detecting it sorts every element's nodes)
        mesh._fem_structured_grid = grid
    except AttributeError:  # pragma: no cover - frozen mesh classes
        pass
    return mesh


def element_volumes(mesh, signed: bool = False) -> np.ndarray:
    """Element volumes, cm^3, shape (nelements,); signed if ``signed``."""
    vol = np.empty(mesh.t.shape[1])
    _kernels.tet_volumes(np.ascontiguousarray(mesh.p, dtype=np.float64),
                         np.ascontiguousarray(mesh.t), vol)
    return vol if signed else np.abs(vol)


def element_voxel_index(mesh, grid: BoxGrid) -> np.ndarray:
    """Flat voxel index (C order of ``grid.shape``) of each element's centroid.

    Parameters
    ----------
    mesh : skfem.MeshTet
    grid : BoxGrid

    Returns
    -------
    numpy.ndarray
        int64, shape (nelements,).  Media per element are then
        ``medium_map.ravel()[element_voxel_index(mesh, grid)]``.

    Raises
    ------
    ValueError
        If an element centroid lies outside the grid.
    """
    mesh_grid = structured_grid(mesh)
    if mesh_grid == grid:
        return np.repeat(np.arange(grid.nvoxels), 6)
    if mesh_grid is not None and _same_box(mesh_grid, grid):
        index = _box_element_voxels(mesh_grid, grid)
        if index is not None:
            return index
    c = mesh.p[:, mesh.t].mean(axis=1)
    ijk = grid.voxel_of_points(c)
    bad = np.flatnonzero((ijk < 0).any(axis=0))
    if bad.size:
        e = int(bad[0])
        raise ValueError(
            f"mesh element {e} has centroid {tuple(c[:, e])} outside the voxel grid {grid}"
        )
    return (ijk[0] * grid.ny + ijk[1]) * grid.nz + ijk[2]


def _same_box(a: BoxGrid, b: BoxGrid) -> bool:
    """Whether two grids span the same cuboid (the same extents, to the last bit)."""
    return (a.Lx, a.Ly, a.Lz) == (b.Lx, b.Ly, b.Lz)


def _box_element_voxels(mesh_grid: BoxGrid, grid: BoxGrid) -> np.ndarray | None:
    """:func:`element_voxel_index` of ``box_mesh(mesh_grid)`` over the same box, from the
    node axes: along each axis the centroid of each simplex in each cell is the mean of its
    vertices' coordinates (summed in vertex order, as ``mesh.p[:, mesh.t].mean(axis=1)``:
    the same numbers), and the voxel index follows axis by axis, without gathering the
    (3, 4, nelements) coordinates. None if a centroid lies outside the grid."""
    per_axis = []
    for a, xs in enumerate(mesh_grid.node_axes()):
        cells = np.arange(mesh_grid.shape[a])[:, None]
        c = xs[cells + _KUHN[:, 0, a]]
        for v in range(1, 4):
            c = c + xs[cells + _KUHN[:, v, a]]
        pts = np.zeros((3, c.size))
        pts[a] = (c / 4).ravel()
        per_axis.append(grid.voxel_of_points(pts)[a].reshape(c.shape))  # (cells, 6)
    ix, iy, iz = per_axis
    if min(ix.min(), iy.min(), iz.min()) < 0:
        return None
    index = ((ix[:, None, None, :] * grid.ny + iy[None, :, None, :]) * grid.nz
             + iz[None, None, :, :])
    return index.reshape(-1)


def structured_grid(mesh) -> BoxGrid | None:
    """The :class:`BoxGrid` whose :func:`box_mesh` equals ``mesh``, or None.

    Used to detect meshes on which :mod:`fem.fastdiag` applies.  The node
    coordinates must match to 1e-12 relative and the elements exactly.
    """
    cached = getattr(mesh, "_fem_structured_grid", False)
    if cached is not False:
        return cached
    grid = _detect_grid(mesh)
    try:
        mesh._fem_structured_grid = grid
    except AttributeError:  # pragma: no cover - frozen mesh classes
        pass
    return grid


def _detect_grid(mesh) -> BoxGrid | None:
    p, t = mesh.p, mesh.t
    if p.shape[0] != 3 or t.shape[0] != 4:
        return None
    lo, hi = p.min(axis=1), p.max(axis=1)
    L = hi - lo
    if np.any(L <= 0) or abs(lo[0] + hi[0]) > 1e-12 * L[0] or abs(lo[1] + hi[1]) > 1e-12 * L[1]:
        return None
    if abs(lo[2]) > 1e-12 * L[2]:
        return None
    # node count per axis from the first rows of the C-ordered node grid
    nz1 = int(np.argmax(p[2] >= hi[2] - 1e-12 * L[2])) + 1
    if nz1 < 2 or p.shape[1] % nz1:
        return None
    rest = p.shape[1] // nz1
    ny1 = int(np.argmax(p[1, ::nz1] >= hi[1] - 1e-12 * L[1])) + 1
    if ny1 < 2 or rest % ny1:
        return None
    nx1 = rest // ny1
    if nx1 < 2 or t.shape[1] != 6 * (nx1 - 1) * (ny1 - 1) * (nz1 - 1):
        return None
    grid = BoxGrid(nx1 - 1, ny1 - 1, nz1 - 1, L[0], L[1], L[2])
    ref = box_mesh(*grid.shape, grid.Lx, grid.Ly, grid.Lz)
    if not np.allclose(ref.p, p, rtol=0, atol=1e-12 * L.max()):
        return None
    if not np.array_equal(np.sort(ref.t, axis=0), np.sort(t, axis=0)):
        return None
    return grid


def check_mesh(mesh, rtol: float = 1e-8) -> None:
    """Raise ValueError for degenerate or inverted (folded) tetrahedra.

    Parameters
    ----------
    mesh : skfem.MeshTet
        Any tetrahedral mesh; vertex order (orientation) may differ between
        elements, as scikit-fem sorts ``t`` by default.
    rtol : float
        An element is degenerate if ``6 |V| <= rtol * l_max^3`` with
        ``l_max`` its longest edge.

    Raises
    ------
    ValueError
        Naming the first bad element, its vertices and its volume.  An
        element is inverted if it and a neighbour across a shared face lie on
        the same side of that face (the mesh folds over itself), which is
        what moving a node through the opposite face produces, whatever the
        orientation convention.
    """
    p, t = mesh.p, mesh.t
    if p.ndim != 2 or p.shape[0] != 3:
        raise ValueError(f"mesh.p must have shape (3, npoints), got {p.shape}")
    if t.ndim != 2 or t.shape[0] != 4:
        raise ValueError(f"mesh.t must have shape (4, nelements), got {t.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("mesh.p contains non-finite coordinates")
    if t.min() < 0 or t.max() >= p.shape[1]:
        raise ValueError(f"mesh.t indices must be in [0, {p.shape[1]}), got [{t.min()}, {t.max()}]")
    vol = element_volumes(mesh, signed=True)
    edges = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    lmax = np.max([np.linalg.norm(p[:, t[a]] - p[:, t[b]], axis=0) for a, b in edges], axis=0)
    bad = np.flatnonzero(6 * np.abs(vol) <= rtol * lmax**3)
    if bad.size:
        e = int(bad[0])
        raise ValueError(
            f"mesh element {e} (vertices {t[:, e].tolist()}) is degenerate: volume={float(vol[e])!r}"
        )
    f2t, facets = mesh.f2t, mesh.facets
    inner = np.flatnonzero(f2t[1] >= 0)
    e0, e1 = f2t[0, inner], f2t[1, inner]
    fsum = facets[:, inner].astype(np.int64).sum(axis=0)
    o0 = t[:, e0].astype(np.int64).sum(axis=0) - fsum  # vertex opposite the facet
    o1 = t[:, e1].astype(np.int64).sum(axis=0) - fsum
    a = p[:, facets[0, inner]]
    n = np.cross(p[:, facets[1, inner]] - a, p[:, facets[2, inner]] - a, axis=0)
    s0 = np.einsum("ij,ij->j", n, p[:, o0] - a)
    s1 = np.einsum("ij,ij->j", n, p[:, o1] - a)
    folded = np.flatnonzero(s0 * s1 >= 0)
    if folded.size:
        f = int(folded[0])
        e = int(e1[f]) if abs(vol[e1[f]]) <= abs(vol[e0[f]]) else int(e0[f])
        raise ValueError(
            f"mesh element {e} (vertices {t[:, e].tolist()}) is inverted: it overlaps its "
            f"neighbour across facet {facets[:, inner[f]].tolist()}; signed volume={float(vol[e])!r}"
        )
