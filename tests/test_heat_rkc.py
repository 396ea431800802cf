"""Explicit heat steps: Runge-Kutta-Chebyshev (``HS.integrator = "rkc"`` or ``"auto"``).

Against the exact decay of a discrete mode first (stability polynomial, second-order
convergence, error control), then invariants (heat balance) and equivalences (the implicit
TR-BDF2 run, the automatic choice)."""

import math

import numpy as np
import pytest
import scipy.sparse as sp

from mcmatlab_py import Medium, Model
from mcmatlab_py.heat.rkc import (
    STABILITY_PER_STAGE2,
    RKCSteps,
    choose_integrator,
    rkc_coefficients,
    spectral_radius,
    stages_for,
)


def one_step_factor(s, z):
    """RKC's stability polynomial P_s(z): one step on y' = lambda y, z = h lambda."""
    A = sp.csr_array(np.array([[-z]]))  # h = 1, m = 1: F = -A y = z y
    ctl = RKCSteps(A, np.ones(1), np.zeros(1), np.array([], int), lambda a, b: None, 1.0, 1.0)
    y = np.ones(1)
    # s stages exactly: step() picks s from h rho, so give it the h that needs s
    mu, nu, mut, gt = rkc_coefficients(s)
    Ypp, Yp = y, y + mut[1] * (z * y)
    for j in range(2, s + 1):
        Ypp, Yp = Yp, ((1 - mu[j] - nu[j]) * y + mu[j] * Yp + nu[j] * Ypp + mut[j] * z * Yp
                       + gt[j] * z * y)
    assert ctl.rho == pytest.approx(abs(z))
    return float(Yp[0])


@pytest.mark.parametrize("s", [2, 5, 17, 60])
def test_stability_polynomial(s):
    """P_s(z) = 1 + z + z^2/2 + O(z^3) (second order), |P_s| <= 1 on [-beta(s), 0] with
    beta(s) = (2/3)(s^2 - 1)(1 - 2 eps / 15) (Sommeijer et al. 1998; -> 0.653 s^2), beyond
    it the polynomial grows, and stages_for keeps h rho within beta."""
    for z in (-1e-3, -2e-3):
        assert one_step_factor(s, z) == pytest.approx(1 + z + z * z / 2, abs=2 * abs(z) ** 3)
    beta = 2.0 / 3.0 * (s * s - 1) * (1 - 2 * (2 / 13) / 15)
    assert beta / s**2 <= STABILITY_PER_STAGE2 + 1e-3
    zs = -np.linspace(0.0, 0.995 * beta, 400)
    assert max(abs(one_step_factor(s, z)) for z in zs) <= 1.0 + 1e-9
    assert abs(one_step_factor(s, -1.1 * beta)) > 1.0
    for hr in (0.5 * beta, beta, 3.0 * beta):
        n = stages_for(hr, 1.0)
        assert 2.0 / 3.0 * (n * n - 1) * (1 - 2 * (2 / 13) / 15) >= hr


def chain(n=40, length=1.0, vhc=4.0, tc=0.5):
    """1-D lumped P1 heat on [0, length], insulated ends: (A, m, x); A W/K, m J/K."""
    h = length / n
    main = np.full(n + 1, 2.0)
    main[[0, -1]] = 1.0
    A = sp.diags_array([-np.ones(n), main, -np.ones(n)], offsets=[-1, 0, 1]) * (tc / h)
    m = np.full(n + 1, vhc * h)
    m[[0, -1]] *= 0.5
    return sp.csr_array(A), m, np.linspace(0.0, length, n + 1)


def mode(n=40, k=3, length=1.0, vhc=4.0, tc=0.5):
    """A cosine mode of the chain and its exact decay rate (1/s): an eigenvector of m^-1 A."""
    A, m, x = chain(n, length, vhc, tc)
    h = length / n
    lam = 2.0 * tc / (vhc * h * h) * (1.0 - math.cos(k * math.pi * h / length))
    u = np.cos(k * math.pi * x / length)
    np.testing.assert_allclose(A @ u, lam * m * u, atol=1e-9 * lam)
    return A, m, u, lam


def fixed_steps(ctl, T, h, n):
    load = ctl.g
    F = ctl._rate(T, load)
    for _ in range(n):
        T, F = ctl.step(T, F, load, h)
    return T


def test_second_order_convergence_against_exact_decay():
    """Steps of fixed length several times the explicit bound 2/rho (s > 2 stages): the
    error of the mode at t = 0.4 s falls as h^2 (slope fitted by np.polyfit)."""
    A, m, u, lam = mode()
    ctl = RKCSteps(A, m, np.zeros(m.size), np.array([], int), lambda a, b: None, 1.0, 1.0)
    t_end, errs, hs = 0.4, [], []
    for n in (8, 16, 32, 64):
        h = t_end / n
        assert stages_for(h, ctl.rho) >= 3  # the Chebyshev stages, not a 2-stage RK
        T = fixed_steps(ctl, u.copy(), h, n)
        errs.append(np.abs(T - math.exp(-lam * t_end) * u).max())
        hs.append(h)
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert slope == pytest.approx(2.0, abs=0.15)


@pytest.mark.parametrize("rtol", [1e-2, 1e-3, 1e-4])
def test_error_control_meets_the_tolerance(rtol):
    """Error-controlled steps over five decay times: the error stays within rtol of the
    spread, as TR-BDF2's (mcmatlab_py.heat.steps), and the steps grow as the mode decays."""
    A, m, u, lam = mode(k=1)
    ctl = RKCSteps(A, m, np.zeros(m.size), np.array([], int), lambda a, b: None, rtol,
                   1e-3, spread=2.0)
    t_end = 5.0 / lam
    T = ctl.advance(u.copy(), 0.0, t_end)
    err = np.abs(T - math.exp(-lam * t_end) * u).max()
    assert err <= rtol * 2.0
    assert max(ctl.lengths) >= 8 * min(ctl.lengths)
    assert ctl.n_products >= 2 * ctl.n_accepted  # s >= 2 products a step


def test_heat_balance_with_insulating_faces():
    """3-D: the heat content rises by exactly the energy the load brought, pulses with
    edges inside the interval included (RKC keeps linear invariants)."""
    import fem

    mesh = fem.box_mesh(6, 5, 4, 0.06, 0.05, 0.04)
    vhc = np.where(mesh.p[2, mesh.t].mean(0) > 0.02, 4.0, 3.0)
    st = fem.HeatStepper(mesh, vhc, 0.005, 1e-3)
    rng = np.random.default_rng(1)
    f = rng.random(mesh.p.shape[1]) * 1e-3  # W

    def load(t0, t1):  # on during [0, 0.05) s
        on = max(0.0, min(t1, 0.05) - t0) / (t1 - t0)
        return on * f if on > 0 else None

    T0 = 37.0 + rng.random(mesh.p.shape[1])
    ctl = RKCSteps(st.K + st.R, st._m_lumped, st.g, st.fixed, load, 1e-4, 1e-3, spread=1.0)
    T = ctl.advance(T0, 0.0, 0.05)
    T = ctl.advance(T, 0.05, 0.2)
    gained = st._m_lumped @ (T - T0)
    assert gained == pytest.approx(f.sum() * 0.05, rel=1e-10)
    assert ctl.n_accepted > 2


def block(**hs):
    """10^3 voxels, two media (the lower half denser), heated in the middle."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 10
    G.Lx = G.Ly = G.Lz = 0.1
    G.media = [Medium("a", mua=1.0, mus=1.0, VHC=3.9, TC=0.005),
               Medium("b", mua=1.0, mus=1.0, VHC=3.0, TC=0.004)]
    G.geom_func = lambda X, Y, Z: np.where((Z > 0.05) & (X > 0), 1, 0)
    NA = np.zeros((10, 10, 10))
    NA[4:6, 4:6, 3:5] = 1 / (8 * 0.01**3)
    model.MC.NA = NA
    HS = model.HS
    HS.progress = False
    HS.temp_sensor_positions = [(0, 0, 0.04), (0.02, 0, 0.05)]
    for k, v in hs.items():
        setattr(HS, k, v)
    model.simulate_heat_distribution()
    return HS


SHORT = dict(P=0.3, duration_on=2e-3, duration_off=4e-3, n_pulses=3, duration_end=1e-2)
LONG = dict(P=0.002, duration_on=20.0, duration_off=10.0)  # s: the explicit bound is 13 ms


def test_automatic_choice_short_pulses_take_rkc_long_ones_the_implicit_steps():
    """The cost model: ms pulses near the explicit bound (13 ms here) go to RKC, a 20 s pulse
    to TR-BDF2, whose run is then bit for bit the implicit one's."""
    short = block(**SHORT)
    assert short.integrator_used == "rkc"
    long_auto = block(**LONG)
    assert long_auto.integrator_used == "implicit"
    long_impl = block(integrator="implicit", **LONG)
    assert np.array_equal(long_auto.T_nodes, long_impl.T_nodes)
    assert np.array_equal(long_auto.sensor_temps, long_impl.sensor_temps)
    # the model itself: rho = 2000/s (explicit bound 1 ms), a solve of 10 products
    assert choose_integrator(2000.0, [1e-3, 4e-3], 22.0) == "rkc"
    assert choose_integrator(2000.0, [10.0, 5.0], 22.0) == "implicit"


def test_rkc_run_agrees_with_the_implicit_run():
    """A short-pulse run on two media against TR-BDF2 at rtol 1e-9: RKC's error falls with
    rtol as the implicit run's does (measured 4.0e-4, 1.6e-4, 4.3e-5, 9.8e-6 of the peak
    rise at rtol 1e-3 ... 1e-6; TR-BDF2 4.3e-4 ... 6.8e-6), nodes and sensors."""
    ref = block(integrator="implicit", rtol=1e-9, **SHORT)
    rise = ref.max_media_temps.max() - 37.0
    assert rise > 20.0
    for rtol, bound in ((1e-3, 1e-3), (1e-4, 4e-4), (1e-6, 3e-5)):
        hs = block(integrator="rkc", rtol=rtol, **SHORT)
        assert hs.integrator_used == "rkc"
        assert np.abs(hs.T_nodes - ref.T_nodes).max() <= bound * rise
        assert np.abs(hs.sensor_temps[-1] - ref.sensor_temps[-1]).max() <= bound * rise
        np.testing.assert_allclose(hs.max_media_temps, ref.max_media_temps,
                                   atol=10 * bound * rise)
    # the readings end on the run's end; the pulses' edges are steps
    assert hs.sensor_times[-1] == pytest.approx(ref.sensor_times[-1])
    for edge in (2e-3, 6e-3, 8e-3, 0.018):
        assert np.min(np.abs(hs.sensor_times - edge)) < 1e-12


def test_rkc_needs_the_lumped_mass():
    with pytest.raises(ValueError, match="lumped"):
        block(integrator="rkc", mass="averaged", **SHORT)
    assert block(mass="averaged", **SHORT).integrator_used == "implicit"


def test_spectral_radius_bounds_the_stiffest_mode():
    A, m, u, lam = mode(k=40)  # the stiffest cosine of the chain
    rho = spectral_radius(A, m)
    assert lam <= rho <= 1.01 * lam


def test_banded_products_equal_the_sparse_matrix_ones():
    """The structured mesh's stiffness (the conductivity differing from element to element)
    plus a lumped convective face is applied from its three diagonals: the same products as
    the CSR matrix's, bit for bit; a fourth diagonal or an unsymmetric entry is refused."""
    import fem
    from fem.banded import banded_operator
    from mcmatlab_py.heat.rkc import _tendency, _tendency_banded

    mesh = fem.box_mesh(5, 4, 6, 0.5, 0.4, 0.6)
    rng = np.random.default_rng(3)
    tc = rng.uniform(1e-3, 6e-3, mesh.t.shape[1])
    A = sp.csr_array(fem.stiffness_matrix(mesh, tc)) + sp.diags_array(
        rng.uniform(0, 1e-3, mesh.p.shape[1]))
    op = banded_operator(A)
    assert op is not None
    assert list(op[2]) == [1, 7, 35]  # z, y and x neighbours: nz + 1, (ny + 1)(nz + 1)
    A = sp.csr_array(A)
    n = A.shape[0]
    Y, load, w = rng.normal(size=n), rng.normal(size=n), rng.uniform(0.5, 2, n)
    got, want = np.empty(n), np.empty(n)
    _tendency_banded(*op, Y, load, w, got)
    _tendency(A.indptr.astype(np.int64), A.indices.astype(np.int32), A.data, Y, load, w, want)
    np.testing.assert_array_equal(got, want)  # summed in the CSR row's order: bit for bit
    B = A.tolil()
    B[0, 8] = B[8, 0] = -1e-4  # a fourth distance between coupled nodes
    assert banded_operator(B) is None
    ctl = RKCSteps(sp.csr_array(B), np.ones(n), np.zeros(n), np.array([], int),
                   lambda a, b: None, 1e-3, 1e-3)  # any other pattern: the CSR kernels
    assert ctl._banded is None and ctl._csr is not None
    B = sp.csr_array(B)
    np.testing.assert_allclose(ctl._rate(Y, load), load - B @ Y, atol=1e-13 * np.abs(B @ Y).max())
    C = A.tolil()
    C[0, 1] = 2 * C[0, 1]  # A[0, 1] != A[1, 0]
    assert banded_operator(C) is None


def test_banded_and_sparse_steps_agree():
    """RKC's steps from the banded products and from the CSR matrix: the same temperatures
    bit for bit, on a chain with a held node."""
    A, m, u, lam = mode(k=2)
    runs = []
    for banded in (True, False):
        ctl = RKCSteps(A, m, np.zeros(m.size), np.array([0]), lambda a, b: None, 1e-3, 1e-3,
                       spread=2.0)
        if not banded:  # as for an operator of any other pattern
            A_csr = sp.csr_array(A)
            ctl._banded = None
            ctl._csr = (A_csr.indptr.astype(np.int64), A_csr.indices.astype(np.int32),
                        A_csr.data)
        runs.append(ctl.advance(u.copy(), 0.0, 2.0 / lam))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert runs[0][0] == u[0]  # held
