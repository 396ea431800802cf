"""Kuhn box meshes, P1 assembly and mesh checks."""

import numpy as np
import pytest
import scipy.sparse as sp
from skfem import Basis, BilinearForm, ElementTetP1, MeshTet, asm
from skfem.helpers import dot, grad

from fem import (
    BoxGrid,
    box_mesh,
    check_mesh,
    element_volumes,
    element_voxel_index,
    lumped_mass,
    mass_matrix,
    stiffness_matrix,
    structured_grid,
)
from fem.fastdiag import one_d_operators


def test_box_mesh_counts_orientation_and_volume():
    g = BoxGrid(3, 4, 2, 1.0, 0.8, 0.5)
    m = g.mesh()
    assert m.p.shape == (3, 4 * 5 * 3)
    assert m.t.shape == (4, 6 * 3 * 4 * 2)
    vol = element_volumes(m, signed=True)
    np.testing.assert_allclose(vol, g.dx * g.dy * g.dz / 6, rtol=1e-12)  # all positive
    assert m.p[0].min() == -0.5 and m.p[1].max() == pytest.approx(0.4) and m.p[2].min() == 0
    # node numbering is C order of the node grid
    i, j, k = 2, 3, 1
    n = g.node_index(i, j, k)
    np.testing.assert_allclose(m.p[:, n], [g.x_nodes[i], g.y_nodes[j], g.z_nodes[k]])
    check_mesh(m)
    assert structured_grid(m) == g
    assert structured_grid(MeshTet.init_tensor(*g.node_axes())) is None
    # box_mesh records its grid; the detection from the nodes and elements finds the same
    copy = MeshTet(m.p.copy(), m.t.copy(), sort_t=False)
    assert not hasattr(copy, "_fem_structured_grid") and structured_grid(copy) == g


def test_element_voxel_index_maps_media():
    g = BoxGrid(3, 2, 4, 0.3, 0.2, 0.4)
    m = g.mesh()
    idx = element_voxel_index(m, g)
    np.testing.assert_array_equal(idx, np.repeat(np.arange(g.nvoxels), 6))
    media = np.arange(g.nvoxels).reshape(g.shape)
    c = m.p[:, m.t].mean(axis=1)
    vox = g.voxel_of_points(c)
    np.testing.assert_array_equal(media.ravel()[idx], media[vox[0], vox[1], vox[2]])


def _fd_stencil_matrix(g: BoxGrid) -> sp.csr_matrix:
    """7-point stencil: K_x (x) M_y (x) M_z + ... with 1-D lumped masses (the FV scheme)."""
    ops = [one_d_operators(n, h) for n, h in zip(g.shape, g.spacing, strict=True)]
    Mx, My, Mz = (sp.diags_array(m) for m, _ in ops)
    Kx, Ky, Kz = (sp.csr_matrix(K) for _, K in ops)
    return (sp.kron(sp.kron(Kx, My), Mz) + sp.kron(sp.kron(Mx, Ky), Mz)
            + sp.kron(sp.kron(Mx, My), Kz)).tocsr()


def _n_boundary_axes(g: BoxGrid, nodes):
    i, j, k = np.unravel_index(nodes, g.node_shape)
    return ((i == 0) | (i == g.nx)).astype(int) + ((j == 0) | (j == g.ny)) + ((k == 0) | (k == g.nz))


def test_kuhn_stiffness_is_seven_point_stencil():
    g = BoxGrid(4, 3, 5, 0.4, 0.6, 0.25)  # unequal spacings
    m = g.mesh()
    K = stiffness_matrix(m, 1.0, prune=False)
    # orthoschemes: only axis-aligned neighbours couple (non-path pairs exactly 0)
    A = K.tocoo()
    di = np.abs(np.diff(np.vstack(np.unravel_index(A.row, g.node_shape)) -
                        np.vstack(np.unravel_index(A.col, g.node_shape)), axis=0))
    off = A.row != A.col
    nonaxis = off & (np.abs(np.vstack(np.unravel_index(A.row, g.node_shape))
                            - np.vstack(np.unravel_index(A.col, g.node_shape))).sum(0) > 1)
    assert di.shape[1] == A.nnz
    np.testing.assert_allclose(A.data[nonaxis], 0.0, atol=1e-15 * np.abs(A.data).max())
    # inside and on faces the weights are those of the 7-point stencil
    # (h_y h_z / h_x inside, halved on a face); they differ only on the 12 box edges
    D = (K - _fd_stencil_matrix(g)).tocoo()
    bad = np.abs(D.data) > 1e-12 * np.abs(K.data).max()
    nodes = np.unique(np.r_[D.row[bad], D.col[bad]])
    assert nodes.size > 0
    assert _n_boundary_axes(g, nodes).min() >= 2
    # on a box edge the Kuhn split gives 1/3 or 1/6 of h_y h_z / h_x instead of 1/4
    n0, n1 = g.node_index(1, 0, 0), g.node_index(2, 0, 0)
    w = -K[n0, n1] / (g.dy * g.dz / g.dx)
    assert min(abs(w - 1 / 3), abs(w - 1 / 6)) < 1e-12


def test_lumped_mass_is_kronecker_except_on_box_edges():
    g = BoxGrid(3, 4, 2, 0.3, 0.4, 0.2)
    m = g.mesh()
    ML = lumped_mass(m, 2.0)
    mk = [one_d_operators(n, h)[0] for n, h in zip(g.shape, g.spacing, strict=True)]
    Mk = 2.0 * np.kron(np.kron(mk[0], mk[1]), mk[2])
    diff = np.flatnonzero(np.abs(ML - Mk) > 1e-14)
    assert _n_boundary_axes(g, diff).min() >= 2
    np.testing.assert_allclose(ML.sum(), 2.0 * 0.3 * 0.4 * 0.2, rtol=1e-13)


@pytest.mark.parametrize("mesh", [box_mesh(3, 2, 2, 1.0, 1.0, 0.5),
                                  MeshTet.init_ball().refined(1)])
def test_assembly_matches_scikit_fem(mesh):
    rng = np.random.default_rng(0)
    c = rng.uniform(1, 3, mesh.t.shape[1])
    basis = Basis(mesh, ElementTetP1())
    cq = np.repeat(c[:, None], basis.X.shape[1], axis=1)

    @BilinearForm
    def lap(u, v, w):
        return w.c * dot(grad(u), grad(v))

    @BilinearForm
    def mass(u, v, w):
        return w.c * u * v

    Ks, Ms = asm(lap, basis, c=cq), asm(mass, basis, c=cq)
    np.testing.assert_allclose((stiffness_matrix(mesh, c) - Ks).toarray(), 0,
                               atol=1e-13 * abs(Ks).max())
    np.testing.assert_allclose((mass_matrix(mesh, c, lumped=False) - Ms).toarray(), 0,
                               atol=1e-13 * abs(Ms).max())
    np.testing.assert_allclose(lumped_mass(mesh, c), np.asarray(Ms.sum(axis=1)).ravel(),
                               rtol=1e-12)


def test_check_mesh_rejects_inverted_and_degenerate_elements():
    m = box_mesh(2, 2, 2, 1.0, 1.0, 1.0)
    p = m.p.copy()
    centre = np.argmin(np.linalg.norm(p - np.array([[0], [0], [0.5]]), axis=0))
    p[:, centre] += [0.8, 0.0, 0.0]  # through the neighbours' opposite faces
    with pytest.raises(ValueError, match="inverted"):
        check_mesh(MeshTet(p, m.t, sort_t=False))
    p = m.p.copy()
    t = m.t.copy()
    p2 = np.hstack([p, p[:, [0]]])
    t[3, 0] = p.shape[1]  # a copy of vertex 0: zero volume
    with pytest.raises(ValueError, match="degenerate: volume=0.0"):
        check_mesh(MeshTet(p2, t, sort_t=False))
    check_mesh(MeshTet.init_ball().refined(1))  # scikit-fem's sorted (mixed-orientation) t


@pytest.mark.parametrize(("field", "value"), [("nx", 0), ("Ly", -1.0), ("Lz", 0.0), ("nz", 2.5)])
def test_box_grid_validation_names_field(field, value):
    kw = dict(nx=2, ny=2, nz=2, Lx=1.0, Ly=1.0, Lz=1.0)
    kw[field] = value
    with pytest.raises(ValueError, match=rf"{field} must be .*{value}"):
        BoxGrid(**kw)


def test_structured_stiffness_equals_generic_assembly():
    from fem.assembly import _assemble

    g = BoxGrid(4, 3, 5, 0.4, 0.3, 0.5)
    m = g.mesh()
    k = np.random.default_rng(0).uniform(1, 2, m.t.shape[1])
    fast, generic = stiffness_matrix(m, k), _assemble(m, k, kind=0, prune_rtol=1e-13)
    assert fast.nnz == generic.nnz
    np.testing.assert_allclose((fast - generic).toarray(), 0, atol=1e-14 * abs(generic).max())


@pytest.mark.parametrize("mesh_dims, voxel_dims", [
    ((7, 9, 11), (5, 6, 4)),  # coarser voxels, not aligned
    ((4, 6, 3), (6, 9, 5)),  # a mesh coarser than the voxels
    ((10, 12, 8), (5, 6, 4)),  # a refinement (aligned)
    ((67, 5, 3), (100, 7, 2)),
])
def test_box_element_voxel_index_equals_the_centroids(mesh_dims, voxel_dims):
    """On another box mesh over the same box the voxels follow axis by axis from the node
    axes: the same indices as the elements' centroids gathered from the mesh."""
    L = (0.31, 0.2, 0.17)
    m = BoxGrid(*mesh_dims, *L).mesh()
    g = BoxGrid(*voxel_dims, *L)
    vox = g.voxel_of_points(m.p[:, m.t].mean(axis=1))
    expected = (vox[0] * g.ny + vox[1]) * g.nz + vox[2]
    np.testing.assert_array_equal(element_voxel_index(m, g), expected)
    # another box: the general path (a centroid outside the voxels is named)
    with pytest.raises(ValueError, match="outside the voxel grid"):
        element_voxel_index(m, BoxGrid(*voxel_dims, 0.2, 0.2, 0.17))


def test_seven_point_csr_is_the_diagonal_matrix_without_zeros():
    """The stiffness's CSR arrays built from its diagonals: the matrix that scipy's DIA
    format gives, exact zeros dropped (insulating elements), columns sorted."""
    import fem._kernels as kernels

    rng = np.random.default_rng(4)
    n, strides = 60, np.array([1, 4, 20])
    W = rng.uniform(0.5, 2.0, (3, n))
    W[rng.random((3, n)) < 0.3] = 0.0
    diag = rng.uniform(1.0, 3.0, n)
    diag[[3, 17]] = 0.0
    indptr, indices, data = np.empty(n + 1, np.int32), np.empty(7 * n, np.int32), np.empty(7 * n)
    nnz = kernels.seven_point_csr(diag, W, strides, indptr, indices, data)
    A = sp.csr_matrix((data[:nnz], indices[:nnz], indptr), shape=(n, n))
    bands = [diag] + [-W[a, :n - s] for a, s in enumerate(strides) for _ in (0, 1)]
    offsets = [0] + [o for s in strides for o in (s, -s)]
    B = sp.diags_array(bands, offsets=offsets, shape=(n, n), format="csr")
    B.eliminate_zeros()
    B.sort_indices()
    np.testing.assert_array_equal(A.indptr, B.indptr)
    np.testing.assert_array_equal(A.indices, B.indices)
    np.testing.assert_array_equal(A.data, B.data)
