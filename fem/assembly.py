r"""P1 mass, stiffness and convective (Robin) boundary matrices.

For the heat equation :math:`c\,\partial_t T = \nabla\cdot(k\nabla T) + S`
(``c`` = VHC in J cm^-3 K^-1, ``k`` = TC in W cm^-1 K^-1, ``S`` in W cm^-3)
the P1 Galerkin system is :math:`M \dot T + K T + R T = f + g` with

.. math::

    M_{ij} = \int c\,\phi_i\phi_j,\quad K_{ij} = \int k\,\nabla\phi_i\cdot\nabla\phi_j,\quad
    R_{ij} = \sum_{\text{faces}} h\int_\Gamma \phi_i\phi_j,\quad
    g_i = \sum_{\text{faces}} h\,T_{amb}\int_\Gamma \phi_i.

``c`` and ``k`` are constant per element.  The default lumped mass is the
row sum (vertex quadrature, :math:`c_e V_e / 4` per vertex): with it and a
stiffness whose off-diagonal entries are <= 0 (as on the Kuhn meshes of
:func:`fem.mesh.box_mesh`) backward Euler keeps a discrete maximum principle,
as MCmatlab's finite-volume scheme does.  The assembly is vectorised (a numba
kernel producing COO triplets), a few seconds for 3 million elements; the
results equal scikit-fem's ``BilinearForm`` assembly (a test).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import _kernels
from .bc import FACES, HeatBoundary, face_facets
from .mesh import KUHN_PATHS, element_volumes, structured_grid

__all__ = [
    "element_coefficient",
    "lumped_mass",
    "mass_matrix",
    "robin_load",
    "robin_matrix",
    "stiffness_matrix",
]


def element_coefficient(mesh, value, name: str, *, allow_zero: bool = False) -> np.ndarray:
    """Validate a positive per-element coefficient; scalar or (nelements,).

    ``allow_zero``: 0 is taken too (a conductivity of 0: a perfect insulator).

    Raises
    ------
    ValueError
        Naming ``name`` and the first bad value (non-finite or <= 0, < 0 with
        ``allow_zero``) or the bad shape.
    """
    ne = mesh.t.shape[1]
    c = np.asarray(value, dtype=np.float64)
    if c.ndim == 0:
        c = np.full(ne, float(c))
    if c.shape != (ne,):
        raise ValueError(f"{name} must be a scalar or have shape ({ne},), got shape {c.shape}")
    bad = np.flatnonzero(~np.isfinite(c) | ((c < 0) if allow_zero else (c <= 0)))
    if bad.size:
        raise ValueError(f"{name} must be {'>=' if allow_zero else '>'} 0 and finite, got "
                         f"{name}[{bad[0]}]={float(c[bad[0]])!r}")
    return c


def lumped_mass(mesh, vhc) -> np.ndarray:
    """Row-sum lumped mass, J/K per node, shape (npoints,): sum of vhc_e V_e / 4."""
    c = element_coefficient(mesh, vhc, "vhc")
    w = c * element_volumes(mesh) / 4.0
    n = mesh.p.shape[1]
    return sum(np.bincount(mesh.t[a], weights=w, minlength=n) for a in range(4))


def mass_matrix(mesh, vhc, lumped: bool = True) -> sp.csr_matrix:
    """VHC-weighted P1 mass matrix, J/K, (npoints, npoints).

    Parameters
    ----------
    mesh : skfem.MeshTet
    vhc : float or array (nelements,)
        J cm^-3 K^-1.
    lumped : bool
        Row-sum lumping (diagonal) if True, else the consistent mass
        :math:`c_e V_e (1 + \\delta_{ab}) / 20`.
    """
    if lumped:
        return sp.diags_array(lumped_mass(mesh, vhc), format="csr")
    return _assemble(mesh, element_coefficient(mesh, vhc, "vhc"), kind=1, prune_rtol=-1.0)


def stiffness_matrix(mesh, tc, prune: bool = True) -> sp.csr_matrix:
    """TC-weighted P1 stiffness matrix, W/K, (npoints, npoints).

    Parameters
    ----------
    mesh : skfem.MeshTet
    tc : float or array (nelements,)
        W cm^-1 K^-1 (>= 0; 0: an insulating element).
    prune : bool
        Drop entries below ``1e-13`` of their row's diagonal: on Kuhn meshes
        the face and body diagonals of a voxel couple with exactly zero weight
        (orthogonal barycentric gradients), and dropping them halves the
        number of stored entries.
    """
    k = element_coefficient(mesh, tc, "tc", allow_zero=True)
    grid = structured_grid(mesh)
    if grid is not None and prune:
        return _kuhn_stiffness(grid, k)
    return _assemble(mesh, k, kind=0, prune_rtol=1e-13 if prune else -1.0)


def _kuhn_stiffness(grid, k: np.ndarray) -> sp.csr_matrix:
    """P1 stiffness of ``box_mesh(grid)`` from the path edges only.

    In an orthoscheme only consecutive path vertices couple, with
    :math:`K_{ab} = -k_e V_e / h^2` for a path edge along an axis of spacing h
    (see :func:`fem.mesh.box_mesh`), and P1 stiffness rows sum to zero, so the
    matrix is a 7-diagonal sum of edge Laplacians; equal to the generic
    assembly to rounding (a test), and 20 times faster.
    """
    n = grid.npoints
    nx, ny, nz = grid.nx, grid.ny, grid.nz
    V = grid.dx * grid.dy * grid.dz / 6.0
    strides = [(grid.ny + 1) * (grid.nz + 1), grid.nz + 1, 1]
    # k of simplex s of every voxel, (6, nx, ny, nz): element 6 v + s is path KUHN_PATHS[s]
    k_s = np.ascontiguousarray(np.moveaxis(k.reshape(nx, ny, nz, 6), -1, 0))
    diag = np.zeros(n)
    W = np.empty((3, n))  # the path edges' weights along z, y, x (strides ascending)
    for axis, h in enumerate(grid.spacing):
        # the path's edge along `axis` starts at the voxel corner offset by the axes the path
        # takes before it (kuhn_path_edges); summed on the node grid by slices: 0.2 s at
        # 10^6 voxels, against 2.9 s for a bincount over the elements' path edges
        w = np.zeros((nx + 1, ny + 1, nz + 1))
        for j, path in enumerate(KUHN_PATHS):
            d = np.zeros(3, dtype=int)
            d[list(path[:list(path).index(axis)])] = 1
            w[d[0]:d[0] + nx, d[1]:d[1] + ny, d[2]:d[2] + nz] += k_s[j]
        w = w.ravel() * (V / h**2)
        s = strides[axis]
        diag += w
        diag[s:] += w[:-s]
        W[2 - axis] = w
    # the CSR arrays straight from the diagonals (no DIA matrix and conversion)
    index = np.int32 if 7 * n < 2**31 else np.int64
    indptr = np.empty(n + 1, dtype=index)
    indices = np.empty(7 * n, dtype=index)
    data = np.empty(7 * n)
    nnz = _kernels.seven_point_csr(diag, W, np.array(strides[::-1], dtype=np.int64), indptr,
                                   indices, data)
    return sp.csr_matrix((data[:nnz], indices[:nnz], indptr), shape=(n, n))


def _assemble(mesh, coef: np.ndarray, kind: int, prune_rtol: float) -> sp.csr_matrix:
    """Element matrices straight into CSR: row buckets, per-row sort and merge."""
    p = np.ascontiguousarray(mesh.p, dtype=np.float64)
    t = np.ascontiguousarray(mesh.t, dtype=np.int64)
    n = p.shape[1]
    deg = np.bincount(t.ravel(), minlength=n)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(4 * deg, out=indptr[1:])
    cols = np.empty(indptr[-1], dtype=np.int32)
    vals = np.empty(indptr[-1], dtype=np.float64)
    _kernels.scatter_rows(p, t, coef, kind, indptr, cols, vals)
    counts = np.empty(n, dtype=np.int64)
    _kernels.merge_rows(indptr, cols, vals, prune_rtol, counts)
    indptr = _kernels.compact_rows(indptr, cols, vals, counts)
    nnz = int(indptr[-1])
    return sp.csr_matrix((vals[:nnz].copy(), cols[:nnz].copy(), indptr), shape=(n, n))


def _face_mass(mesh, face: str, lumped: bool):
    """Rows, cols, values of int_face phi_i phi_j (cm^2)."""
    f = face_facets(mesh, face)
    p = mesh.p
    a = p[:, f[1]] - p[:, f[0]]
    b = p[:, f[2]] - p[:, f[0]]
    area = 0.5 * np.linalg.norm(np.cross(a, b, axis=0), axis=0)
    if lumped:
        return f.ravel(), f.ravel(), np.tile(area / 3.0, 3)
    rows = np.repeat(f, 3, axis=0).ravel()
    cols = np.tile(f, (3, 1)).ravel()
    local = (np.ones((3, 3)) + np.eye(3)).ravel() / 12.0
    return rows, cols, (local[:, None] * area[None, :]).ravel()


def robin_matrix(mesh, boundary: HeatBoundary, lumped: bool = True) -> sp.csr_matrix:
    r"""Convective boundary matrix :math:`\sum h\int_\Gamma\phi_i\phi_j`, W/K.

    Only the ``"convective"`` faces of ``boundary`` contribute; lumped
    (vertex quadrature, diagonal) by default.
    """
    n = mesh.p.shape[1]
    R = sp.csr_matrix((n, n))
    for face in FACES:
        bc = boundary[face]
        if bc.kind == "convective":
            r, c, v = _face_mass(mesh, face, lumped)
            R = R + sp.csr_matrix((bc.h * v, (r, c)), shape=(n, n))
    return R.tocsr()


def robin_load(mesh, boundary: HeatBoundary) -> np.ndarray:
    r"""Convective load :math:`\sum h\,T_{amb}\int_\Gamma\phi_i`, W, shape (npoints,)."""
    n = mesh.p.shape[1]
    g = np.zeros(n)
    for face in FACES:
        bc = boundary[face]
        if bc.kind == "convective":
            r, _, v = _face_mass(mesh, face, lumped=True)
            g += np.bincount(r, weights=bc.h * bc.temperature * v, minlength=n)
    return g
