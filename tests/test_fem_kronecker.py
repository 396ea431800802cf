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
def test_fast_path_equals_sparse_lu_with_member_scales(mesh, boundary):
    rng = np.random.default_rng(0)
    n = mesh.p.shape[1]
    T, f = rng.random((4, n)), 1e-3 * rng.random((4, n))
    s1, s2 = rng.uniform(0.5, 2, 4), rng.uniform(0.5, 2, 4)
    fast = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, boundary=boundary, operator="kronecker")
    lu = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, boundary=boundary, operator="kronecker",
                         method="direct")
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
