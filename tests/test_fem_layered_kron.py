"""fem.layered: direct solves of the tensor-product heat operator for media layered in z."""

import functools

import numpy as np
import pytest
import scipy.linalg as sla
from scipy.optimize import brentq

import fem
from fem.fastdiag import KroneckerSolver, one_d_mass, one_d_operators
from fem.layered import LayeredKroneckerSolver, layered_one_d

GRID = fem.BoxGrid(6, 5, 8, 0.5, 0.4, 0.3)


def per_element(grid, layers):
    """Per-element coefficient of box_mesh(grid) from per-layer values (nz,)."""
    return np.repeat(np.broadcast_to(np.asarray(layers, float), grid.shape).ravel(), 6)


def two_layers(grid, top=3):
    z = np.arange(grid.nz)
    return np.where(z < top, 4.19, 3.76), np.where(z < top, 5.8e-3, 3.7e-3)


@pytest.fixture(scope="module")
def mesh():
    return GRID.mesh()


BOUNDARIES = [
    fem.HeatBoundary(),
    fem.HeatBoundary({"z-": fem.FaceBC("convective", temperature=5.0, h=2e-3),
                      "z+": fem.FaceBC("fixed", temperature=37.0),
                      "x-": fem.FaceBC("fixed", temperature=30.0)}),
    fem.HeatBoundary.from_mcmatlab(1, temperature=20.0),  # every face fixed
]


@pytest.mark.parametrize("boundary", BOUNDARIES)
@pytest.mark.parametrize("mass", ["lumped", "averaged", "consistent"])
@pytest.mark.parametrize("theta", [1.0, 0.5])
def test_equals_sparse_lu_of_the_same_matrices(mesh, boundary, mass, theta):
    rng = np.random.default_rng(0)
    n = mesh.p.shape[1]
    T, f = rng.random((4, n)), 1e-3 * rng.random((4, n))
    s1, s2 = rng.uniform(0.5, 2, 4), rng.uniform(0.5, 2, 4)  # per-member VHC, TC scales
    c, k = (per_element(GRID, v) for v in two_layers(GRID))
    kw = dict(theta=theta, boundary=boundary, operator="kronecker", mass=mass)
    fast = fem.HeatStepper(mesh, c, k, 0.1, **kw)
    lu = fem.HeatStepper(mesh, c, k, 0.1, method="direct", **kw)
    assert fast.method == "fast" and isinstance(fast._solver, LayeredKroneckerSolver)
    assert lu.method == "direct"
    np.testing.assert_allclose(fast.step(T, f, s1, s2), lu.step(T, f, s1, s2), rtol=0,
                               atol=1e-13)


@pytest.mark.parametrize("boundary", [BOUNDARIES[0], BOUNDARIES[2]])
@pytest.mark.parametrize("mass", ["averaged", "consistent"])
@pytest.mark.parametrize("layered", [False, True])
def test_theta_right_hand_side_in_one_pass_equals_the_sparse_products(mesh, boundary, mass,
                                                                       layered):
    rng = np.random.default_rng(5)
    n = mesh.p.shape[1]
    T, f = rng.random((5, n)), 1e-3 * rng.random((5, n))
    s1, s2 = rng.uniform(0.5, 2, 5), rng.uniform(0.5, 2, 5)
    c, k = (per_element(GRID, v) for v in two_layers(GRID)) if layered else (3.76, 3.7e-3)
    st = fem.HeatStepper(mesh, c, k, 0.1, theta=0.6, boundary=boundary, operator="kronecker",
                         mass=mass)
    assert st._theta_tridiag is not None
    x = st.step(T, f, s1, s2)
    st._theta_tridiag = None  # M T and K T as sparse products
    ref = st.step(T, f, s1, s2)
    np.testing.assert_allclose(x, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    assert np.abs(ref - T).max() > 1e-3  # the step moved the temperatures


def test_theta_right_hand_side_in_one_pass_only_where_it_applies(mesh):
    kw = dict(operator="kronecker", mass="averaged")
    assert getattr(fem.HeatStepper(mesh, 3.76, 3.7e-3, 0.1, theta=1.0, **kw),
                   "_theta_tridiag", None) is None  # backward Euler: no explicit part
    assert getattr(fem.HeatStepper(mesh, 3.76, 3.7e-3, 0.1, theta=0.5, boundary=BOUNDARIES[1],
                                   **kw), "_theta_tridiag", None) is None  # a convective face


@pytest.mark.parametrize("mass", ["lumped", "averaged", "consistent"])
def test_homogeneous_layers_equal_kronecker_solver(mass):
    boundary = BOUNDARIES[1]
    lay = LayeredKroneckerSolver(GRID, boundary, np.full(GRID.nz, 3.76),
                                 np.full(GRID.nz, 3.7e-3), 0.05, 0.5, mass=mass)
    free = np.zeros(GRID.npoints, dtype=bool)
    free[lay.free_nodes] = True
    ref = KroneckerSolver(GRID, boundary, 3.76, 3.7e-3, 0.05, 0.5, None, None, None, free,
                          exact=False, mass=mass)
    assert np.array_equal(lay.free_nodes, ref.free_nodes)
    rng = np.random.default_rng(2)
    r = rng.random((3, lay.free_nodes.size))
    s1, s2 = rng.uniform(0.5, 2, 3), rng.uniform(0.5, 2, 3)
    x = ref.solve(r, s1, s2)
    np.testing.assert_allclose(lay.solve(r, s1, s2), x, rtol=0, atol=1e-13 * np.abs(x).max())


@pytest.mark.parametrize("theta", [1.0, 0.5])
def test_insulated_box_gains_the_deposited_energy(mesh, theta):
    c, k = (per_element(GRID, v) for v in two_layers(GRID))
    st = fem.HeatStepper(mesh, c, k, 0.02, theta=theta, operator="kronecker", mass="averaged")
    assert st.method == "fast"
    n = mesh.p.shape[1]
    f = 1e-3 * np.random.default_rng(3).random(n)
    T = np.full(n, 37.0)
    e0 = st.energy(T)
    for _ in range(25):
        T = st.step(T, f)
    assert st.energy(T) - e0 == pytest.approx(25 * 0.02 * f.sum(), rel=1e-11)


def test_matches_p1_away_from_the_box_edges(mesh):
    """With media layered in z the P1 stiffness and lumped mass of the Kuhn mesh equal
    the layer-weighted Kronecker forms except on the twelve box edges and where the
    interface meets the four side faces (inside, an interface node has twelve tetrahedra
    on either side and its lateral links three; on a side face 8 against 4)."""
    c, k = (per_element(GRID, v) for v in two_layers(GRID, top=3))
    kron = fem.HeatStepper(mesh, c, k, 0.1, operator="kronecker")
    p1 = fem.HeatStepper(mesh, c, k, 0.1, method="direct")
    i, j, kk = np.unravel_index(np.arange(GRID.npoints), GRID.node_shape)
    side = (i % GRID.nx == 0) | (j % GRID.ny == 0)
    on_edge = ((i % GRID.nx == 0).astype(int) + (j % GRID.ny == 0) + (kk % GRID.nz == 0)) >= 2
    on_edge |= side & (kk == 3)
    dM = np.abs(kron.M.diagonal() - p1.M.diagonal())
    assert dM[~on_edge].max() < 1e-15 * p1.M.diagonal().max() and dM[on_edge].max() > 0
    dK = abs(kron.K - p1.K).tocsr()
    rows = np.repeat(np.arange(GRID.npoints), np.diff(dK.indptr))
    big = dK.data > 1e-13 * abs(p1.K).max()
    assert on_edge[rows[big]].all() and on_edge[dK.indices[big]].all()


def test_fallbacks():
    mesh = fem.BoxGrid(4, 3, 4, 0.4, 0.3, 0.2).mesh()
    g = fem.BoxGrid(4, 3, 4, 0.4, 0.3, 0.2)
    c, k = (per_element(g, v) for v in two_layers(g, top=2))
    conv_x = fem.HeatBoundary({"x+": fem.FaceBC("convective", temperature=20.0, h=1e-3)})
    st = fem.HeatStepper(mesh, c, k, 0.1, boundary=conv_x, operator="kronecker")
    assert st.method == "direct"  # x and y do not separate; same operator, sparse LU
    with pytest.raises(ValueError, match="convective x or y face"):
        fem.HeatStepper(mesh, c, k, 0.1, boundary=conv_x, operator="kronecker", method="fast")
    lateral = c.copy()
    lateral[:6] *= 2  # one voxel differs: not layered
    with pytest.raises(ValueError, match="homogeneous or vary only with depth"):
        fem.HeatStepper(mesh, lateral, k, 0.1, operator="kronecker")
    assert fem.layer_coefficients(g, lateral) is None
    np.testing.assert_array_equal(fem.layer_coefficients(g, c), two_layers(g, top=2)[0])
    # the P1 operator keeps its own solvers
    assert fem.HeatStepper(mesh, c, k, 0.1).method == "direct"


# ----------------------------------------------------------------- two-layer analytic
L, A = 1.0, 0.375  # cm, depth and the interface (a node for nz = 8, 16, 32, 64)
LX = 2.0  # cm, width: the lateral mode (1, 0, -1) on 2 voxels
C1, K1, C2, K2 = 1.0, 1.0, 3.0, 0.2  # a strong contrast: VHC x3, TC / 5


def _C(s, z):  # cos(sqrt(s) z), continued to s < 0
    return np.cos(np.sqrt(s) * z) if s >= 0 else np.cosh(np.sqrt(-s) * z)


def _S(s, z):  # sqrt(s) sin(sqrt(s) z) = -d/dz cos(sqrt(s) z)
    return np.sqrt(s) * np.sin(np.sqrt(s) * z) if s >= 0 else -np.sqrt(-s) * np.sinh(
        np.sqrt(-s) * z)


@functools.lru_cache
def exact_decay_rate(q2: float) -> float:
    """Slowest non-constant decay rate sigma of ``c u_t = (k u_z)_z - k q2 u`` on [0, L],
    insulated, two layers: u = cos(b1 z) above A, cos(b2 (L - z)) below, b_i^2 =
    sigma c_i / k_i - q2; continuity of u and k u_z at A gives the root of D."""
    def D(sig):
        s1, s2 = sig * C1 / K1 - q2, sig * C2 / K2 - q2
        return _C(s1, A) * K2 * _S(s2, L - A) + _C(s2, L - A) * K1 * _S(s1, A)

    sig = np.linspace(1e-6 + q2 * min(K1 / C1, K2 / C2) * (q2 > 0), 50.0, 5001)
    d = np.array([D(x) for x in sig])
    i = np.flatnonzero(np.sign(d[1:]) != np.sign(d[:-1]))[0]
    return brentq(D, sig[i], sig[i + 1], xtol=1e-15, rtol=1e-15)


def stepper_decay_rate(nz: int, mass: str, lateral: bool) -> tuple[float, float]:
    """The slowest decay rate of the discrete operator, by inverse iteration with the
    layered solver (backward Euler steps of 10^3 s), and the discrete lateral eigenvalue."""
    g = fem.BoxGrid(2, 1, nz, LX, 1.0, L)
    zc = g.z
    c, k = per_element(g, np.where(zc < A, C1, C2)), per_element(g, np.where(zc < A, K1, K2))
    st = fem.HeatStepper(g.mesh(), c, k, 1e3, operator="kronecker", mass=mass)
    assert st.method == "fast"
    # x nodes 0, 1, 2: the mode (1, 0, -1) is exact in x (or the constant), every y the same
    x_mode = np.array([1.0, 0.0, -1.0]) if lateral else np.ones(3)
    w = np.asarray(st.M.sum(axis=0)).ravel()

    def project(T):  # onto the x-y mode; the constant deflated (BE keeps it, factor 1)
        prof = T.reshape(3, 2, nz + 1).mean(axis=1)
        prof = 0.5 * (prof[0] - prof[2]) if lateral else prof.mean(axis=0)
        T = np.broadcast_to(x_mode[:, None, None] * prof, (3, 2, nz + 1)).ravel()
        return T if lateral else T - (w @ T) / w.sum()

    z_mode = np.cos(np.pi * np.arange(nz + 1) / nz)
    T = project(np.broadcast_to(x_mode[:, None, None] * z_mode, (3, 2, nz + 1)).ravel())
    for _ in range(40):
        T = project(st.step(T))
        T /= np.abs(T).max()
    sigma = (T @ (st.K @ T)) / (T @ (st.M @ T))
    q2 = sla.eigh(one_d_operators(2, LX / 2)[1], one_d_mass(2, LX / 2, mass),
                  eigvals_only=True)[1] if lateral else 0.0
    return sigma, q2


@pytest.mark.parametrize("lateral", [False, True])
@pytest.mark.parametrize("mass", ["lumped", "averaged"])
def test_two_layer_decay_rate_converges_at_second_order(mass, lateral):
    """Against the two-layer modal solution (q2: the discrete lateral eigenvalue, so that
    only the z discretisation errs): the error falls as h^2 (rate fitted on 4 meshes)."""
    nzs = np.array([8, 16, 32, 64])
    err = []
    for nz in nzs:
        sigma, q2 = stepper_decay_rate(int(nz), mass, lateral)
        err.append(abs(sigma - exact_decay_rate(q2)) / exact_decay_rate(q2))
    rate = -np.polyfit(np.log(nzs), np.log(err), 1)[0]
    assert 1.9 < rate < 2.1, (rate, err)
    assert err[-1] < 2e-3


def test_harmonic_lateral_weight_would_be_first_order():
    """The arithmetic weight of an interface node's lateral conductance is the right one:
    with the harmonic mean there instead, the 1-D z problem of a lateral mode
    (K_z + q2 M_z^k, M_z^c) converges at first order only."""
    q2 = 10.0

    def err(nz, harmonic):
        h = L / nz
        zc = (np.arange(nz) + 0.5) * h
        cd, co, _, _ = layered_one_d(h, np.where(zc < A, C1, C2))
        md, mo, kd, ko = layered_one_d(h, np.where(zc < A, K1, K2))
        if harmonic:
            md[round(A / h)] = h * 2 * K1 * K2 / (K1 + K2)
        S = np.diag(kd + q2 * md) + np.diag(ko + q2 * mo, 1) + np.diag(ko + q2 * mo, -1)
        Mc = np.diag(cd) + np.diag(co, 1) + np.diag(co, -1)
        sigma = sla.eigh(S, Mc, eigvals_only=True)[0]
        return abs(sigma - exact_decay_rate(q2))

    nzs = np.array([16, 32, 64, 128])
    rates = [-np.polyfit(np.log(nzs), np.log([err(n, hm) for n in nzs]), 1)[0]
             for hm in (False, True)]
    assert rates[0] > 1.9 and rates[1] < 1.2, rates


SIDE_CONVECTIVE = fem.HeatBoundary({"x-": fem.FaceBC("convective", temperature=20.0, h=1e-2)})


@pytest.mark.parametrize(("media", "boundary", "mass", "expected"), [
    ("layers", fem.HeatBoundary(), "lumped", "kronecker"),
    ("layers", fem.HeatBoundary(), "averaged", "kronecker"),
    ("layers", SIDE_CONVECTIVE, "lumped", "p1"),  # x and y do not separate
    ("one", fem.HeatBoundary(), "lumped", "p1"),  # P1's own exact fast solver
    ("one", SIDE_CONVECTIVE, "averaged", "kronecker"),
    ("insulator", fem.HeatBoundary(), "lumped", "p1"),
])
def test_auto_operator_takes_the_tensor_product_where_it_is_solved_directly(
        mesh, media, boundary, mass, expected):
    """``operator="auto"`` finds the layers once and steps as the operator it names."""
    c, k = (per_element(GRID, v) for v in two_layers(GRID))
    if media == "one":
        c, k = 3.7, 5.2e-3
    elif media == "insulator":
        k = np.where(np.arange(k.size) < 6, 0.0, k)
    kw = dict(boundary=boundary, mass=mass)
    auto = fem.HeatStepper(mesh, c, k, 0.1, operator="auto", **kw)
    named = fem.HeatStepper(mesh, c, k, 0.1, operator=expected, **kw)
    assert auto.operator == expected
    assert (auto.layers is not None) == (media == "layers" and expected == "kronecker")
    if auto.layers is not None:
        np.testing.assert_array_equal(auto.layers, two_layers(GRID))
    assert auto.method == named.method
    T = np.random.default_rng(0).uniform(30.0, 40.0, (2, mesh.p.shape[1]))
    np.testing.assert_array_equal(auto.step(T, vhc_scale=[1.0, 1.2]),
                                  named.step(T, vhc_scale=[1.0, 1.2]))
