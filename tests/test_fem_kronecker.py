"""HeatStepper(operator="kronecker"): the tensor-product (vertex-centred finite-volume) operator."""

import numpy as np
import pytest

import fem


@pytest.fixture(scope="module")
def mesh():
    return fem.BoxGrid(6, 5, 4, 0.5, 0.4, 0.25).mesh()


@pytest.mark.parametrize("boundary", [
    fem.HeatBoundary(),
    fem.HeatBoundary.from_mcmatlab(2, temperature=20.0, h=1e-3),
    fem.HeatBoundary({"z-": fem.FaceBC("convective", temperature=5.0, h=2e-3),
                      "z+": fem.FaceBC("fixed", temperature=37.0)}),
])
@pytest.mark.parametrize("mass", ["lumped", "averaged", "consistent"])
def test_fast_path_equals_sparse_lu_with_member_scales(mesh, boundary, mass):
    rng = np.random.default_rng(0)
    n = mesh.p.shape[1]
    T, f = rng.random((4, n)), 1e-3 * rng.random((4, n))
    s1, s2 = rng.uniform(0.5, 2, 4), rng.uniform(0.5, 2, 4)
    fast = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, boundary=boundary, operator="kronecker",
                           mass=mass)
    lu = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, boundary=boundary, operator="kronecker",
                         method="direct", mass=mass)
    assert fast.method == "fast" and lu.method == "direct"
    np.testing.assert_allclose(fast.step(T, f, s1, s2), lu.step(T, f, s1, s2), atol=1e-11)


def test_conserves_energy_and_matches_p1_inside(mesh):
    n = mesh.p.shape[1]
    f = np.random.default_rng(1).random(n) * 1e-3
    kron = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, operator="kronecker")
    p1 = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1)
    Tk = Tp = np.zeros(n)
    for _ in range(20):
        Tk, Tp = kron.step(Tk, f), p1.step(Tp, f)
    assert kron.energy(Tk) == pytest.approx(20 * 0.1 * f.sum(), rel=1e-10)
    # the operators differ only on the box edges: same mass and stiffness elsewhere
    dM = np.abs(kron.M.diagonal() - p1.M.diagonal())
    g = fem.BoxGrid(6, 5, 4, 0.5, 0.4, 0.25)
    i, j, k = np.unravel_index(np.arange(n), tuple(m + 1 for m in g.shape))
    on_edge = ((i % 6 == 0).astype(int) + (j % 5 == 0) + (k % 4 == 0)) >= 2
    assert dM[~on_edge].max() < 1e-15 and dM[on_edge].max() > 0


def test_needs_a_structured_homogeneous_mesh(mesh):
    with pytest.raises(ValueError, match="operator='kronecker' is not applicable"):
        fem.HeatStepper(mesh, np.linspace(3, 4, mesh.t.shape[1]), 0.0037, 0.1,
                        operator="kronecker")
    with pytest.raises(ValueError, match="operator must be"):
        fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, operator="fd")


def test_averaged_mass_gives_fourth_order_modes():
    """Lowest Neumann mode of the 1-D pencil (K, M): exact (pi/L)^2. The lumped mass errs
    as h^2 (error / 4 when h halves), the averaged one as h^4 (error / 16)."""
    import scipy.linalg as sla

    from fem.fastdiag import one_d_mass, one_d_operators

    def err(n, kind):
        h = 1.0 / n
        lam = sla.eigh(one_d_operators(n, h)[1], one_d_mass(n, h, kind), eigvals_only=True)[1]
        return abs(lam - np.pi ** 2) / np.pi ** 2

    assert 3.5 < err(8, "lumped") / err(16, "lumped") < 4.5
    assert 14 < err(8, "averaged") / err(16, "averaged") < 18
    assert err(16, "averaged") < err(16, "lumped") / 50


def test_averaged_mass_conserves_energy(mesh):
    stepper = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, operator="kronecker", mass="averaged")
    rng = np.random.default_rng(1)
    T = rng.random(mesh.p.shape[1])
    f = 1e-3 * rng.random(mesh.p.shape[1])
    T1 = stepper.step(T, f)
    np.testing.assert_allclose(stepper.energy(T1), stepper.energy(T) + 0.1 * f.sum(), rtol=1e-12)
    # on P1 the averaged mass is the mean of the lumped and the consistent P1 masses
    p1 = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, mass="averaged")
    np.testing.assert_allclose(p1.energy(p1.step(T, f)), p1.energy(T) + 0.1 * f.sum(),
                               rtol=1e-9)
    with pytest.raises(ValueError, match="needs operator='kronecker'"):
        fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, mass="consistent")
    with pytest.raises(ValueError, match="mass must be one of"):
        fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, operator="kronecker", mass="spectral")


def test_consistent_mass_is_the_trilinear_hexahedron():
    """mass="consistent": the tensor product of 1-D consistent masses and stiffnesses is the
    Q1 (trilinear hexahedral) element's, as scikit-fem assembles it on the same box."""
    import skfem
    from skfem.models.poisson import laplace, mass

    grid = fem.BoxGrid(4, 3, 2, 0.4, 0.3, 0.2)
    tet = grid.mesh()
    st = fem.HeatStepper(tet, 2.0, 0.5, 0.1, operator="kronecker", mass="consistent")
    x, y, z = (np.linspace(lo, hi, n + 1) for lo, hi, n in
               zip(tet.p.min(axis=1), tet.p.max(axis=1), grid.shape, strict=True))
    hexes = skfem.MeshHex.init_tensor(x, y, z)
    basis = skfem.Basis(hexes, skfem.ElementHex1())
    M, K = 2.0 * mass.assemble(basis), 0.5 * laplace.assemble(basis)
    # the same nodes: match each hexahedral mesh node to the tetrahedral mesh's
    order = np.lexsort(np.round(tet.p, 9)[::-1])
    perm = np.empty_like(order)
    perm[np.lexsort(np.round(hexes.p, 9)[::-1])] = order
    P = np.zeros((tet.p.shape[1], tet.p.shape[1]))
    P[perm, np.arange(perm.size)] = 1.0
    np.testing.assert_allclose(P @ M.toarray() @ P.T, st.M.toarray(), atol=1e-14)
    np.testing.assert_allclose(P @ K.toarray() @ P.T, st.K.toarray(), atol=1e-13)
