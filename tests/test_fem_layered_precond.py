"""PCG on media layered in z with something across the layers (MCmatlab's Example 4: a vessel
in the dermis), preconditioned by the layered operator of the layers' mean VHC and TC."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla

import fem
from fem.fastdiag import KroneckerSolver
from fem.layered import layer_means
from fem.mesh import element_volumes

GRID = fem.BoxGrid(12, 10, 12, 0.12, 0.1, 0.12)


def vessel_in_layers(grid):
    """Per-element VHC, TC: water over tissue, a vessel along y below the interface."""
    mesh = grid.mesh()
    x, _, z = mesh.p[:, mesh.t].mean(axis=1)  # element centroids
    vhc = np.where(z < 0.03, 4.19, 3.76)
    tc = np.where(z < 0.03, 5.8e-3, 3.7e-3)
    blood = x**2 + (z - 0.07) ** 2 < 0.025**2
    vhc[blood], tc[blood] = 3.80, 5.2e-3
    return mesh, vhc, tc


@pytest.fixture(scope="module")
def problem():
    return vessel_in_layers(GRID)


def volume_mean_preconditioner(stepper, mesh, vhc, tc, dt):
    """The former preconditioner: fast diagonalization of the volume-averaged operator."""
    vol = element_volumes(mesh)
    kron = KroneckerSolver(GRID, stepper.boundary, float(vol @ vhc / vol.sum()),
                           float(vol @ tc / vol.sum()), dt, 1.0, None, None, None,
                           stepper._free_mask(), exact=False)
    return lambda R, a, b: kron.solve(np.ascontiguousarray(R.T), a * dt, b).T


def test_layer_means():
    c = np.repeat(np.broadcast_to([1.0, 2.0, 4.0], (2, 2, 3)).ravel(), 6)
    grid = fem.BoxGrid(2, 2, 3, 1.0, 1.0, 1.0)
    means, ratio = layer_means(grid, c)
    np.testing.assert_array_equal(means, [1.0, 2.0, 4.0])
    assert ratio == 1.0
    c[:6] = 3.0  # one voxel of the first layer
    means, ratio = layer_means(grid, c)
    assert means[0] == pytest.approx(1.5) and ratio == 3.0


@pytest.mark.parametrize("boundary", [fem.HeatBoundary(),
                                      fem.HeatBoundary.from_mcmatlab(1, temperature=37.0)])
@pytest.mark.parametrize("dt", [1e-3, 1e-1])
def test_layer_mean_pcg_converges_in_fewer_iterations(problem, boundary, dt):
    mesh, vhc, tc = problem
    st = fem.HeatStepper(mesh, vhc, tc, dt, boundary=boundary, method="pcg", rtol=1e-10)
    assert st._solver.precond is not None
    st._solver.jacobi_below = 0.0  # the preconditioners compared, not the switch to Jacobi
    T0 = np.full(mesh.p.shape[1], 37.0)
    load = np.where(mesh.p[2] < 0.05, 1e-4, 0.0)
    expected = exact_step(st, T0, load, dt)
    T = st.step(T0, load)
    layered_its = st._solver.last_iterations
    assert np.abs(T - expected).max() <= 1e-8 * np.abs(expected).max()
    st._solver.precond = volume_mean_preconditioner(st, mesh, vhc, tc, dt)
    T_old = st.step(T0, load)
    assert np.abs(T_old - expected).max() <= 1e-8 * np.abs(expected).max()
    assert layered_its < st._solver.last_iterations


def exact_step(st, T0, load, dt):
    """The exact solution of one (P1, lumped) backward Euler step, by sparse LU."""
    f = st.free
    A = (st.M / dt + st.K + st.R).tocsr()
    rhs = st.M @ T0 / dt + st.g + load
    expected = T0.copy()
    if st.fixed.size:
        expected[st.fixed] = st.fixed_values
        rhs = rhs - A[:, st.fixed] @ expected[st.fixed]
    expected[f] = spla.spsolve(A[f][:, f].tocsc(), rhs[f])
    return expected


def test_short_steps_switch_to_jacobi(problem):
    """Where the mass dominates the step matrix (stiffness over mass on the diagonal below
    fem.stepper.JACOBI_BELOW), a solve uses Jacobi; longer steps the layer means. Both
    reach the exact step; the step length enters as a scale on the mass, per solve."""
    mesh, vhc, tc = problem
    dt = 0.1
    st = fem.HeatStepper(mesh, vhc, tc, dt, method="pcg", rtol=1e-10)
    T0 = np.full(mesh.p.shape[1], 37.0)
    load = np.where(mesh.p[2] < 0.05, 1e-4, 0.0)
    ratio = dt * st._solver._k_over_m  # stiffness over mass at the stepper's own step
    assert ratio > fem.stepper.JACOBI_BELOW
    for scale, jacobi in ((1.0, False), (10 * ratio / fem.stepper.JACOBI_BELOW, True)):
        T = st.step(T0[None], load[None], vhc_scale=np.array([scale]))[0]
        assert st._solver.last_jacobi == jacobi
        expected = exact_step(fem.HeatStepper(mesh, vhc, tc, dt / scale, method="pcg"), T0,
                              load, dt / scale)
        assert np.abs(T - expected).max() <= 1e-8 * np.abs(expected).max()


def test_homogeneous_keeps_the_volume_mean_solver():
    """One medium: the preconditioner is the fast diagonalization, as before (bit for bit)."""
    mesh = GRID.mesh()
    st = fem.HeatStepper(mesh, 3.76, 3.7e-3, 1e-2, method="pcg")
    free_vars = st._solver.precond.__code__.co_freevars
    solver = st._solver.precond.__closure__[free_vars.index("solver")].cell_contents
    assert isinstance(solver, KroneckerSolver)
