"""Analytic references and convergence rates of the heat core (scikit-fem's test_convergence style)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla

from fem import BoxGrid, FaceBC, HeatBoundary, HeatStepper, mass_matrix

C, K = 4.0, 0.005
ALPHA = K / C  # cm^2/s
L = np.array([0.4, 0.3, 0.2])  # cm


def _coords(mesh):
    return mesh.p[0] + L[0] / 2, mesh.p[1] + L[1] / 2, mesh.p[2]  # x' = x + Lx/2


def _l2(mesh, e):
    """L2 norm of the P1 function with nodal values e (consistent mass)."""
    return float(np.sqrt(e @ (mass_matrix(mesh, 1.0, lumped=False) @ e)))


def test_modal_decay_in_insulated_box():
    """T0 = cos(pi x'/Lx) cos(pi y'/Ly) cos(pi z/Lz) decays as exp(-alpha lambda t).

    On the Kuhn mesh the lumped P1 operator is the 7-point stencil away from the
    box edges, whose eigenvalue for this mode is known exactly:
    lambda_h = sum 4/h^2 sin^2(pi h / 2L) = lambda (1 - O(h^2)).  The computed
    amplitude must match the exact decay within that known error (plus the
    Crank-Nicolson error of the same mode, and a quarter for the box edges)."""
    lam = np.sum((np.pi / L) ** 2)
    t_end = 1.0 / (ALPHA * lam)
    exact = np.exp(-1.0)
    errors = []
    for n in (4, 8, 16):
        g = BoxGrid(n, n, n, *L)
        mesh = g.mesh()
        x, y, z = _coords(mesh)
        phi = np.cos(np.pi * x / L[0]) * np.cos(np.pi * y / L[1]) * np.cos(np.pi * z / L[2])
        n_steps = 50
        dt = t_end / n_steps
        T = HeatStepper(mesh, C, K, dt, theta=0.5).run(phi, n_steps)
        w = mass_matrix(mesh, 1.0).diagonal()
        amp = (w * T * phi).sum() / (w * phi * phi).sum()
        h = np.array(g.spacing)
        lam_h = np.sum(4 / h**2 * np.sin(np.pi * h / (2 * L)) ** 2)
        zz = ALPHA * lam_h * dt
        predicted = ((1 - zz / 2) / (1 + zz / 2)) ** n_steps  # exact CN amplitude of the 7-point mode
        assert abs(amp - exact) <= 1.25 * abs(predicted - exact)
        errors.append(abs(amp - exact))
    assert errors[2] < errors[1] / 3.5 < errors[0] / 3.5**2


def test_spatial_order_two_in_l2():
    """L2 error of two exact modes at t_end; CN with small dt so time error is negligible."""
    lam1 = (np.pi / L[0]) ** 2 + (np.pi / L[2]) ** 2
    lam2 = (2 * np.pi / L[1]) ** 2
    t_end = 0.5 / (ALPHA * lam1)
    hs, errs = [], []
    for n in (8, 16, 32):  # n = 4 is pre-asymptotic for the cos(2 pi y'/Ly) mode
        g = BoxGrid(n, n, n, *L)
        mesh = g.mesh()
        x, y, z = _coords(mesh)
        m1 = np.cos(np.pi * x / L[0]) * np.cos(np.pi * z / L[2])
        m2 = 0.5 * np.cos(2 * np.pi * y / L[1])
        n_steps = 100
        T = HeatStepper(mesh, C, K, t_end / n_steps, theta=0.5).run(m1 + m2, n_steps)
        exact = m1 * np.exp(-ALPHA * lam1 * t_end) + m2 * np.exp(-ALPHA * lam2 * t_end)
        hs.append(g.dx)
        errs.append(_l2(mesh, T - exact))
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert slope == pytest.approx(2.0, abs=0.2)


@pytest.mark.parametrize(("theta", "order"), [(1.0, 1.0), (0.5, 2.0)])
def test_temporal_order(theta, order):
    """Against the exact time integration of the same semi-discrete system
    (dense generalized eigendecomposition), with a convective top and a load."""
    g = BoxGrid(4, 4, 3, *L)
    mesh = g.mesh()
    bc = HeatBoundary({"z-": FaceBC("convective", temperature=20.0, h=0.02)})
    x, y, z = _coords(mesh)
    T0 = 37.0 + 5 * np.exp(-((x - 0.2) ** 2 + (y - 0.15) ** 2) / 0.01) * (1 - z / L[2])
    load = 1e-3 * (1 + x)  # W per node
    t_end = 2.0
    ref = HeatStepper(mesh, C, K, 1.0, theta=theta, boundary=bc)
    Mm, A = ref.M.toarray(), (ref.K + ref.R).toarray()
    q = ref.g + load
    T_inf = np.linalg.solve(A, q)
    mu, V = sla.eigh(A, Mm)
    T_exact = T_inf + V @ (np.exp(-mu * t_end) * (V.T @ (Mm @ (T0 - T_inf))))
    dts, errs = [], []
    for n_steps in (8, 16, 32, 64):
        s = HeatStepper(mesh, C, K, t_end / n_steps, theta=theta, boundary=bc)
        T = s.run(T0, n_steps, load)
        dts.append(t_end / n_steps)
        errs.append(np.abs(T - T_exact).max())
    slope = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert slope == pytest.approx(order, abs=0.15)


def _fd_module():
    path = Path(__file__).parents[1] / "validation" / "fem_fd_reference.py"
    spec = importlib.util.spec_from_file_location("fem_fd_reference", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_fem_and_finite_differences_converge_together():
    """Independent cell-centred FD solver (validation/fem_fd_reference.py) and
    the FEM solve the same steady problem; their coarse-voxel averages approach
    each other at second order (the long study refines further)."""
    res = _fd_module().fem_vs_fd((1, 2, 4), theta=1.0, n_steps=1, t_end=1e9)
    h = np.array([r[0] for r in res])
    d = np.array([r[1] for r in res])
    assert np.all(d[1:] < d[:-1] / 3.0)
    assert np.polyfit(np.log(h), np.log(d), 1)[0] == pytest.approx(2.0, abs=0.3)
