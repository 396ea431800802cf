r"""Moving a voxel-wise constant power density onto a mesh as a P1 load vector.

The load of node ``i`` is :math:`f_i = \int S\,\phi_i` (W) for a power density
``S`` (W cm^-3) constant on each voxel.  :func:`voxel_load_matrix` returns the
sparse operator ``L`` (npoints, nvoxels) with ``f = L @ S.ravel()`` (C order of
``(nx, ny, nz)``); for an ensemble ``F = S_members.reshape(N, -1) @ L.T``
gives (N, npoints).  Each column of ``L`` sums to its voxel's volume, so the
total power ``sum(f) = sum(S * dV)`` is conserved exactly in both modes:

- aligned meshes (every element inside one voxel, e.g. :func:`fem.mesh.box_mesh`
  of the voxel grid or of a refinement of it): exact,
  ``f_i += S_v V_e / 4`` for the four vertices of element ``e`` in voxel ``v``;
- other meshes: each voxel is sampled by a regular sub-grid of midpoints
  (``n_sub`` per axis), each point carries ``S dV / n_sub^3`` and spreads it
  to the vertices of its containing element by barycentric weights
  (second-order accurate, exact for the total).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .locate import locate
from .mesh import BoxGrid, _same_box, element_volumes, element_voxel_index, structured_grid

__all__ = ["corner_load_matrix", "load_vector", "voxel_load_matrix"]


def _aligned_voxels(mesh, grid: BoxGrid) -> np.ndarray | None:
    """Voxel of each element if every element lies inside one voxel, else None (the
    box mesh of ``grid`` itself goes to :func:`_box_load_matrix` before this)."""
    mesh_grid = structured_grid(mesh)
    if mesh_grid is not None and _same_box(mesh_grid, grid):
        # a box mesh over the same box: aligned where each axis splits every voxel alike
        return None if _refinement(mesh_grid, grid) is None else element_voxel_index(mesh, grid)
    p, t = mesh.p, mesh.t
    c = p[:, t].mean(axis=1)
    ijk = grid.voxel_of_points(c)
    if (ijk < 0).any():
        return None
    for a, (h, lo) in enumerate(zip(grid.spacing, grid.lower, strict=True)):
        lo_v = lo + ijk[a] * h
        xa = p[a][t]
        tol = 1e-9 * h
        if np.any(xa < lo_v - tol) or np.any(xa > lo_v + h + tol):
            return None
    return (ijk[0] * grid.ny + ijk[1]) * grid.nz + ijk[2]


def _refinement(mesh_grid: BoxGrid, grid: BoxGrid) -> tuple[int, int, int] | None:
    """Cells of ``mesh_grid`` per voxel of ``grid`` along each axis, or None where an axis
    does not split every voxel alike."""
    if any(m % n for m, n in zip(mesh_grid.shape, grid.shape, strict=True)):
        return None
    return tuple(m // n for m, n in zip(mesh_grid.shape, grid.shape, strict=True))


def _box_load_matrix(mesh, grid: BoxGrid) -> sp.csr_matrix:
    """:func:`voxel_load_matrix` of ``box_mesh(grid)``: each voxel's 8 corners, built
    column by column (no COO of 24 entries per voxel: at 4 M voxels that was 2 GB of
    temporaries). Every voxel is split alike, so the weights of its corners, the
    ``V_e / 4`` of the elements that share each corner, come from the first voxel."""
    vol = element_volumes(mesh)[:6]
    t0 = mesh.t[:, :6]  # the elements of voxel 0, whose lower corner is node 0
    offsets, where = np.unique(t0.ravel(), return_inverse=True)
    weights = np.bincount(where, weights=np.tile(vol / 4.0, 4), minlength=offsets.size)
    n = mesh.p.shape[1]
    idx = np.int32 if n < 2**31 and 8 * grid.nvoxels < 2**31 else np.int64
    i, j, k = np.unravel_index(np.arange(grid.nvoxels, dtype=idx), grid.shape)
    base = (i * (grid.ny + 1) + j) * (grid.nz + 1) + k
    del i, j, k
    rows = (base[:, None] + offsets.astype(idx)[None, :]).ravel()
    del base
    m = offsets.size
    indptr = np.arange(0, m * grid.nvoxels + 1, m, dtype=idx)
    L = sp.csc_matrix((np.tile(weights, grid.nvoxels), rows, indptr), shape=(n, grid.nvoxels))
    del rows
    return L.tocsr()


def _default_n_sub(mesh, grid: BoxGrid) -> np.ndarray:
    h_mesh = (6.0 * element_volumes(mesh).mean()) ** (1.0 / 3.0)
    return np.clip(np.ceil(2.0 * np.array(grid.spacing) / h_mesh), 2, 16).astype(int)


def voxel_load_matrix(mesh, grid: BoxGrid, n_sub=None) -> sp.csr_matrix:
    """Sparse operator from voxel power density to P1 nodal loads.

    Parameters
    ----------
    mesh : skfem.MeshTet
        Must cover the voxel box.
    grid : BoxGrid
        The voxel grid of the power density.
    n_sub : int or 3 ints, optional
        Sub-samples per voxel and axis for non-aligned meshes; default
        ``ceil(2 d / h_mesh)`` clipped to [2, 16] (``d`` voxel size,
        ``h_mesh`` the mean element size), so each element gets samples.

    Returns
    -------
    scipy.sparse.csr_matrix
        Shape (npoints, nvoxels), entries in cm^3: ``f = L @ S.ravel()``.

    Raises
    ------
    ValueError
        If a voxel sample point lies outside the mesh (its power would be
        lost), naming the point.
    """
    if not isinstance(grid, BoxGrid):
        raise ValueError(f"grid must be a BoxGrid, got {type(grid).__name__}")
    n = mesh.p.shape[1]
    if structured_grid(mesh) == grid:
        return _box_load_matrix(mesh, grid)
    vox = _aligned_voxels(mesh, grid)
    if vox is not None:
        w = element_volumes(mesh) / 4.0
        rows = mesh.t.ravel()
        cols = np.tile(vox, 4)
        vals = np.tile(w, 4)
        return sp.csr_matrix((vals, (rows, cols)), shape=(n, grid.nvoxels))

    ns = _default_n_sub(mesh, grid) if n_sub is None else np.broadcast_to(n_sub, 3).astype(int)
    if np.any(ns < 1):
        raise ValueError(f"n_sub must be >= 1, got {n_sub!r}")
    # sub-sample offsets inside one voxel (midpoints of a regular sub-grid)
    offs = [(np.arange(m) + 0.5) / m * h for m, h in zip(ns, grid.spacing, strict=True)]
    O = np.stack(np.meshgrid(*offs, indexing="ij"), axis=0).reshape(3, -1)
    nsub = O.shape[1]
    weight = grid.dx * grid.dy * grid.dz / nsub
    # voxels in chunks of about 2.5 x 10^5 sample points; each chunk's columns are summed
    # into a CSC block of its own and the blocks are stacked: 164 MB over the start for
    # 100 x 100 x 50 voxels onto 20 x 20 x 10 (4 x 10^6 points with a running sparse sum
    # had peaked at 1.2 GB in a cold identify)
    chunk = max(1, 250_000 // nsub)
    lower = np.array(grid.lower)
    idx = np.int32 if max(n, grid.nvoxels) < 2**31 else np.int64
    blocks = []
    for v0 in range(0, grid.nvoxels, chunk):
        v = np.arange(v0, min(v0 + chunk, grid.nvoxels))
        i, j, k = np.unravel_index(v, grid.shape)
        corner = lower[:, None] + np.array(grid.spacing)[:, None] * np.vstack([i, j, k])
        pts = (corner[:, :, None] + O[:, None, :]).reshape(3, -1)
        elem, bary = locate(mesh, pts)
        out = np.flatnonzero(elem < 0)
        if out.size:
            q = pts[:, out[0]]
            raise ValueError(
                f"voxel sample point {tuple(q)} is outside the mesh; the mesh must cover the "
                f"voxel grid {grid}"
            )
        rows = mesh.t[:, elem].astype(idx).ravel()
        cols = np.tile(np.repeat((v - v0).astype(idx), nsub), 4)
        B = sp.csc_matrix((weight * bary.ravel(), (rows, cols)), shape=(n, v.size))
        B.sum_duplicates()
        blocks.append(B)
    return sp.hstack(blocks, format="csc").tocsr()


def corner_load_matrix(mesh_grid: BoxGrid, grid: BoxGrid) -> sp.csr_matrix | None:
    r"""The load of the tensor-product (trilinear, vertex-centred) operator: each cell's power
    an eighth to each of its corners, ``(npoints, nvoxels)`` cm^3, ``f = L @ S.ravel()``.

    With a voxel power density constant on each cell this is :math:`\int S N_i` of the
    trilinear shape functions, and the integral over each node's dual cell (the vertex-
    centred finite volumes): the partner of :func:`fem.layered.tensor_product_operators`'
    masses, as :func:`voxel_load_matrix` (``V_e / 4`` per tetrahedron's vertex) is of the P1
    operator's. The two agree inside the box for a uniform density and differ on its edges
    (a P1 corner on its voxel's Kuhn diagonal takes ``V / 4``, the others ``V / 12``; here
    every corner ``V / 8``). ``mesh_grid``: the box mesh's grid, the voxels' own or a
    refinement of them over the same box (cells inside one voxel each); None otherwise.
    """
    ratio = _refinement(mesh_grid, grid) if _same_box(mesh_grid, grid) else None
    if ratio is None:
        return None
    idx = np.int32 if 8 * mesh_grid.nvoxels < 2**31 else np.int64
    i, j, k = np.unravel_index(np.arange(mesh_grid.nvoxels, dtype=idx), mesh_grid.shape)
    voxel = ((i // ratio[0]) * grid.ny + j // ratio[1]) * grid.nz + k // ratio[2]
    base = mesh_grid.node_index(i, j, k).astype(idx)
    del i, j, k
    sy, sx = mesh_grid.nz + 1, (mesh_grid.ny + 1) * (mesh_grid.nz + 1)
    corners = np.array([a * sx + b * sy + c for a in (0, 1) for b in (0, 1) for c in (0, 1)],
                       dtype=idx)
    rows = (base[:, None] + corners[None, :]).ravel()
    cols = np.repeat(voxel, 8)
    vol = mesh_grid.dx * mesh_grid.dy * mesh_grid.dz / 8.0
    L = sp.csr_matrix((np.full(rows.size, vol), (rows, cols)),
                      shape=(mesh_grid.npoints, grid.nvoxels))
    L.sum_duplicates()
    return L


def load_vector(mesh, grid: BoxGrid, S) -> np.ndarray:
    """Nodal loads (W) of power densities S (W/cm^3).

    Parameters
    ----------
    S : array (nx, ny, nz) or (N, nx, ny, nz)

    Returns
    -------
    array (npoints,) or (N, npoints)
    """
    S = np.asarray(S, dtype=float)
    L = voxel_load_matrix(mesh, grid)
    if S.shape == grid.shape:
        return L @ S.ravel()
    if S.ndim == 4 and S.shape[1:] == grid.shape:
        return (L @ S.reshape(S.shape[0], -1).T).T
    raise ValueError(f"S must have shape {grid.shape} or (N, *{grid.shape}), got {S.shape}")
