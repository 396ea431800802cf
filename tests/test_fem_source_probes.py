"""Voxel power density -> P1 loads, and point probes."""

import numpy as np
import pytest
from skfem import MeshTet

from fem import BoxGrid, box_mesh, load_vector, probe_matrix, voxel_load_matrix


def _power(grid: BoxGrid, S: np.ndarray) -> float:
    return float(S.sum() * grid.dx * grid.dy * grid.dz)


@pytest.mark.parametrize(
    "mesh_grid",
    [BoxGrid(4, 5, 3, 0.4, 0.5, 0.3),  # the voxel grid itself (aligned)
     BoxGrid(8, 10, 6, 0.4, 0.5, 0.3),  # a refinement (aligned)
     BoxGrid(3, 3, 2, 0.4, 0.5, 0.3),  # coarser (not aligned)
     BoxGrid(7, 6, 5, 0.4, 0.5, 0.3)],  # unrelated (not aligned)
)
def test_total_power_conserved(mesh_grid):
    grid = BoxGrid(4, 5, 3, 0.4, 0.5, 0.3)
    S = np.random.default_rng(0).uniform(0, 10, grid.shape)
    mesh = mesh_grid.mesh()
    L = voxel_load_matrix(mesh, grid)
    assert L.shape == (mesh.p.shape[1], grid.nvoxels)
    f = L @ S.ravel()
    assert abs(f.sum() - _power(grid, S)) <= 1e-10 * _power(grid, S)
    # batched members
    SN = np.stack([S, 2 * S, 0 * S])
    F = SN.reshape(3, -1) @ L.T
    np.testing.assert_allclose(F, np.stack([f, 2 * f, 0 * f]), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(load_vector(mesh, grid, SN), F, rtol=1e-13, atol=1e-15)


def test_total_power_conserved_on_scikit_fem_mesh():
    grid = BoxGrid(4, 4, 2, 1.0, 1.0, 0.5)
    mesh = MeshTet.init_tensor(np.linspace(-0.5, 0.5, 4), np.linspace(-0.5, 0.5, 5),
                               np.linspace(0, 0.5, 3))
    S = np.random.default_rng(1).uniform(0, 1, grid.shape)
    f = voxel_load_matrix(mesh, grid) @ S.ravel()
    assert abs(f.sum() - _power(grid, S)) <= 1e-10 * _power(grid, S)


def test_aligned_load_is_exact():
    """f_i = int S phi_i exactly; for S = 1 in one voxel and 0 elsewhere,
    corners on the voxel diagonal get 6 V/24 = V/4, the other six corners V/12."""
    grid = BoxGrid(3, 3, 3, 0.3, 0.3, 0.3)
    mesh = grid.mesh()
    S = np.zeros(grid.shape)
    S[1, 1, 1] = 5.0
    f = voxel_load_matrix(mesh, grid) @ S.ravel()
    V = grid.dx * grid.dy * grid.dz
    expected = np.zeros(mesh.p.shape[1])
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                n = grid.node_index(1 + di, 1 + dj, 1 + dk)
                expected[n] = 5.0 * V * (0.25 if di == dj == dk else 1 / 12)
    np.testing.assert_allclose(f, expected, rtol=1e-12, atol=1e-18)
    # a linear power density: int S phi_i computed with the exact P1 quadrature
    # of a piecewise-constant S equals the voxel-centre value times V_e / 4 summed
    S = 1.0 + grid.x[:, None, None] + 2 * grid.y[None, :, None] + grid.z[None, None, :]
    f = voxel_load_matrix(mesh, grid) @ S.ravel()
    assert f.sum() == pytest.approx(_power(grid, S), rel=1e-13)


def test_non_aligned_load_converges_to_exact():
    """On a coarse mesh, refining the sub-sampling converges to int S phi_i."""
    grid = BoxGrid(6, 6, 4, 0.6, 0.6, 0.4)
    mesh = BoxGrid(2, 2, 2, 0.6, 0.6, 0.4).mesh()
    S = np.random.default_rng(2).uniform(0, 1, grid.shape)
    fs = [voxel_load_matrix(mesh, grid, n_sub=k) @ S.ravel() for k in (2, 4, 8, 32)]
    errs = [np.abs(f - fs[-1]).max() for f in fs[:-1]]
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 0.02 * np.abs(fs[-1]).max()


def test_load_outside_mesh_raises():
    grid = BoxGrid(2, 2, 2, 1.0, 1.0, 1.0)
    mesh = BoxGrid(3, 3, 3, 0.5, 0.5, 0.5).mesh()
    with pytest.raises(ValueError, match="outside the mesh"):
        voxel_load_matrix(mesh, grid)


def test_probes_exact_for_linear_functions_incl_boundary_points():
    mesh = box_mesh(4, 3, 5, 0.4, 0.3, 0.5)
    rng = np.random.default_rng(3)
    pts = np.hstack([
        rng.uniform([-0.2, -0.15, 0], [0.2, 0.15, 0.5], size=(20, 3)).T,
        np.array([[0, 0, 0], [0.2, 0.15, 0.5], [-0.2, 0, 0.25], [0.05, -0.15, 0.1]]).T,
    ])  # last four: top surface, a corner, a face, an edge-ish point
    P = probe_matrix(mesh, pts)
    assert P.shape == (pts.shape[1], mesh.p.shape[1])
    u = 1.0 + 2 * mesh.p[0] - 3 * mesh.p[1] + 0.5 * mesh.p[2]
    np.testing.assert_allclose(P @ u, 1.0 + 2 * pts[0] - 3 * pts[1] + 0.5 * pts[2],
                               rtol=0, atol=1e-13)
    np.testing.assert_allclose(P.sum(axis=1), 1.0, rtol=1e-14)
    U = np.stack([u, 2 * u])
    np.testing.assert_allclose(U @ P.T, np.stack([P @ u, 2 * (P @ u)]))
    # a node: weight 1 on that node
    n = 7
    np.testing.assert_allclose(probe_matrix(mesh, mesh.p[:, n]).toarray().ravel(),
                               np.eye(mesh.p.shape[1])[n], atol=1e-12)


def test_probe_outside_raises_naming_point():
    mesh = box_mesh(2, 2, 2, 1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match=r"points\[:, 1\] = \(0.0, 0.0, -0.1\) is outside"):
        probe_matrix(mesh, np.array([[0, 0, 0.5], [0, 0, -0.1]]).T)
    with pytest.raises(ValueError, match="shape"):
        probe_matrix(mesh, np.zeros((4, 2)))


def test_structured_locate_matches_the_bucket_search():
    """On box meshes the element comes from the coordinates (no bucket grid, whose cache
    costs about 0.9 KB per node): same interpolation as the generic search, nodes, faces
    and points outside included."""
    import sys

    import fem.locate  # noqa: F401 - the module (fem.locate is also the function)

    L = sys.modules["fem.locate"]
    mesh = fem.BoxGrid(7, 5, 4, 0.7, 0.5, 0.3).mesh()
    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.35, -0.25, 0.0], [0.35, 0.25, 0.3], size=(2000, 3)).T
    pts[:, :50] = mesh.p[:, rng.integers(0, mesh.p.shape[1], 50)]  # nodes (on faces too)
    pts[:, 50:60] += 1.0  # outside
    pts[0, 60:70] = 0.35  # on the box's face
    e1, b1 = L.locate(mesh, pts)
    assert not hasattr(mesh, "_fem_buckets")
    b = L._Buckets(mesh)
    e2, b2 = np.empty(pts.shape[1], dtype=np.int64), np.zeros((4, pts.shape[1]))
    L._kernels.locate_points(np.ascontiguousarray(pts), b.p, b.t, b.lo, b.inv_h, b.nb,
                             b.start, b.items, 1e-10, e2, b2)
    np.testing.assert_array_equal(e1 < 0, e2 < 0)
    ok = e1 >= 0
    f = np.sin(3 * mesh.p[0]) + mesh.p[1] ** 2 + mesh.p[2]
    v1 = np.einsum("kn,kn->n", b1[:, ok], f[mesh.t[:, e1[ok]]])
    v2 = np.einsum("kn,kn->n", b2[:, ok], f[mesh.t[:, e2[ok]]])
    np.testing.assert_allclose(v1, v2, atol=1e-12)
    assert b1.min() >= 0 and np.allclose(b1[:, ok].sum(axis=0), 1)


def test_group_maxima_keep_each_groups_running_maximum():
    import fem

    gm = fem.GroupMaxima([np.array([0, 2]), np.array([], int), np.array([1, 2, 3])])
    out = np.array([5.0, -np.inf, 0.0])
    gm.update(np.array([1.0, 4.0, 3.0, -2.0]), out)
    np.testing.assert_array_equal(out, [5.0, -np.inf, 4.0])
    gm.update(np.array([9.0, 0.0, 0.0, 0.0]), out)
    np.testing.assert_array_equal(out, [9.0, -np.inf, 4.0])
    with pytest.raises(ValueError, match="node 3"):
        gm.update(np.zeros(3), out)


def test_box_mesh_load_and_locate_fast_paths_equal_the_general_ones():
    """Box meshes over the voxel box: the aligned refinement's loads by the cells' voxels,
    and the sub-sampled loads of a coarser mesh located from the coordinates, equal the
    element by element sums and the bucket search."""
    import sys

    import fem.locate  # noqa: F401

    Lmod = sys.modules["fem.locate"]
    grid = BoxGrid(6, 4, 5, 0.6, 0.4, 0.5)
    S = np.random.default_rng(3).uniform(0, 1, grid.shape)
    fine = BoxGrid(12, 8, 10, 0.6, 0.4, 0.5).mesh()
    f = voxel_load_matrix(fine, grid) @ S.ravel()
    vol = np.abs(np.linalg.det(np.stack([fine.p[:, fine.t[a]] - fine.p[:, fine.t[0]]
                                         for a in (1, 2, 3)], axis=1).transpose(2, 0, 1))) / 6
    centroid = grid.voxel_of_points(fine.p[:, fine.t].mean(axis=1))
    Se = S[centroid[0], centroid[1], centroid[2]]
    expected = np.bincount(fine.t.ravel(), weights=np.tile(Se * vol / 4, 4),
                           minlength=fine.p.shape[1])
    np.testing.assert_allclose(f, expected, rtol=1e-12, atol=1e-15)
    coarse = BoxGrid(4, 3, 3, 0.6, 0.4, 0.5).mesh()
    pts = np.random.default_rng(5).uniform([-0.3, -0.2, 0.0], [0.3, 0.2, 0.5], (500, 3)).T
    e1, b1 = Lmod.locate(coarse, pts)
    b = Lmod._Buckets(coarse)
    e2, b2 = np.empty(pts.shape[1], dtype=np.int64), np.zeros((4, pts.shape[1]))
    Lmod._kernels.locate_points(np.ascontiguousarray(pts), b.p, b.t, b.lo, b.inv_h, b.nb,
                                b.start, b.items, 1e-10, e2, b2)
    fvals = np.cos(coarse.p[0]) + coarse.p[2] ** 2
    np.testing.assert_allclose(np.einsum("kn,kn->n", b1, fvals[coarse.t[:, e1]]),
                               np.einsum("kn,kn->n", b2, fvals[coarse.t[:, e2]]), atol=1e-12)


def test_corner_load_gives_each_corner_an_eighth_of_each_cell():
    """The tensor-product operator's load: columns sum to the voxel's volume, an interior
    node of a uniform density gets its dual cell's power as the P1 load does, a box corner
    an eighth of its voxel (the P1 load: 1/4 or 1/12 by the Kuhn diagonal); a refinement
    spreads each voxel over its cells; not built for a coarser mesh."""
    import fem

    grid = BoxGrid(3, 2, 2, 0.3, 0.2, 0.2)
    V = grid.dx * grid.dy * grid.dz
    C = fem.corner_load_matrix(grid, grid)
    np.testing.assert_allclose(np.asarray(C.sum(axis=0)).ravel(), V, rtol=1e-13)
    P = voxel_load_matrix(grid.mesh(), grid)
    f_c, f_p = C @ np.ones(grid.nvoxels), P @ np.ones(grid.nvoxels)
    inner = grid.node_index(1, 1, 1)
    assert f_c[inner] == pytest.approx(f_p[inner], rel=1e-13) == pytest.approx(V, rel=1e-13)
    assert f_c[grid.node_index(0, 0, 0)] == pytest.approx(V / 8)
    assert f_p[grid.node_index(0, 0, 0)] == pytest.approx(V / 4)
    fine = BoxGrid(6, 4, 2, 0.3, 0.2, 0.2)
    F = fem.corner_load_matrix(fine, grid)
    S = np.random.default_rng(0).uniform(0, 1, grid.shape)
    assert (F @ S.ravel()).sum() == pytest.approx(S.sum() * V, rel=1e-13)
    assert fem.corner_load_matrix(BoxGrid(2, 2, 2, 0.3, 0.2, 0.2), grid) is None


def test_layered_block_heated_uniformly_heats_each_layer_uniformly():
    """Two layers of different heat capacity, heated uniformly, insulated: the heat run takes
    the tensor-product operator (media layered in depth) and its load; every node plane of a
    layer stays uniform, the box's edges and corners included (the P1 load with that
    operator's finite-volume mass had heated them 4/3, 2 or 2/3 as fast)."""
    from mcmatlab_py import Medium, Model

    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 3, 3, 4
    G.Lx = G.Ly = 0.3
    G.Lz = 0.4
    G.media = [Medium("top", mua=1.0, mus=1.0, VHC=3.0, TC=0.005),
               Medium("bottom", mua=1.0, mus=1.0, VHC=4.0, TC=0.004)]
    G.geom_func = lambda X, Y, Z: (Z > 0.2).astype(int)
    model.MC.NA = np.full((3, 3, 4), 10.0)
    HS = model.HS
    HS.P, HS.T_initial, HS.progress, HS.duration_on = 0.1, 37.0, False, 0.5
    model.simulate_heat_distribution()
    T = HS.T_nodes.reshape(4, 4, 5)
    for k in range(5):
        assert np.ptp(T[:, :, k]) < 1e-9, (k, np.ptp(T[:, :, k]))
    assert T[:, :, 0].mean() > 37.1  # it did heat
