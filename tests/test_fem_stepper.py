"""HeatStepper: invariants, equivalence of the solver paths, boundary conditions, input checks."""

import numpy as np
import pytest

from fem import (
    BoxGrid,
    FaceBC,
    HeatBoundary,
    HeatStepper,
    box_mesh,
    element_voxel_index,
    march,
    probe_matrix,
    voxel_load_matrix,
)

C, K = 3.9, 0.0052  # J cm^-3 K^-1, W cm^-1 K^-1 (water-like tissue)

BOUNDARIES = {
    "insulating": HeatBoundary(),
    "fixed": HeatBoundary.from_mcmatlab(1),
    "convective": HeatBoundary.from_mcmatlab(2, temperature=20.0, h=0.01),
    "mixed": HeatBoundary({
        "z-": FaceBC("convective", temperature=20.0, h=0.005),
        "x+": FaceBC("convective", temperature=25.0, h=0.05),
        "z+": FaceBC("fixed", temperature=37.0),
        "y-": FaceBC("fixed"),
    }),
}


def _ensemble(mesh, N, seed=0):
    rng = np.random.default_rng(seed)
    n = mesh.p.shape[1]
    T = 37.0 + rng.normal(size=(N, n))
    f = 0.01 * rng.uniform(size=(N, n))
    return T, f, rng.uniform(0.5, 2.0, N), rng.uniform(0.5, 2.0, N)


@pytest.mark.parametrize("bc", list(BOUNDARIES))
@pytest.mark.parametrize("theta", [1.0, 0.5])
def test_fast_path_equals_sparse_paths(bc, theta):
    mesh = box_mesh(5, 4, 3, 0.5, 0.4, 0.3)
    T, f, vs, ts = _ensemble(mesh, 5)
    kw = dict(theta=theta, boundary=BOUNDARIES[bc])
    fast = HeatStepper(mesh, C, K, 0.2, **kw)
    direct = HeatStepper(mesh, C, K, 0.2, method="direct", **kw)
    pcg = HeatStepper(mesh, C, K, 0.2, method="pcg", rtol=1e-14, **kw)
    assert (fast.method, direct.method, pcg.method) == ("fast", "direct", "pcg")
    Tf, Td, Tp = T, T, T
    for _ in range(3):
        Tf, Td, Tp = (s.step(X, f, vs, ts) for s, X in ((fast, Tf), (direct, Td), (pcg, Tp)))
    scale = np.abs(Td).max()
    assert np.abs(Tf - Td).max() <= 1e-10 * scale
    assert np.abs(Tp - Td).max() <= 1e-10 * scale
    # a member alone gives the same as inside the ensemble (scales are per member)
    one = fast.step(T[2], f[2], vs[2], ts[2])
    np.testing.assert_allclose(one, fast.step(T, f, vs, ts)[2], rtol=0, atol=1e-10 * scale)


def test_auto_method_choice():
    mesh = box_mesh(3, 3, 2, 0.3, 0.3, 0.2)
    assert HeatStepper(mesh, C, K, 0.1).method == "fast"
    assert HeatStepper(mesh, C, K, 0.1, lumped=False).method == "direct"
    het = np.full(mesh.t.shape[1], C)
    het[:6] *= 1.1
    assert HeatStepper(mesh, het, K, 0.1).method == "direct"
    assert HeatStepper(mesh, het, K, 0.1, direct_max_nodes=10).method == "pcg"
    with pytest.raises(ValueError, match="method='fast' is not applicable"):
        HeatStepper(mesh, het, K, 0.1, method="fast")


@pytest.mark.parametrize("lumped", [True, False])
@pytest.mark.parametrize("heterogeneous", [False, True])
def test_energy_conservation_and_equilibration(lumped, heterogeneous):
    """Insulated box: int c T grows by exactly the deposited energy (1^T K = 0),
    and the field ends uniform."""
    grid = BoxGrid(6, 6, 4, 0.3, 0.3, 0.2)
    mesh = grid.mesh()
    media = np.zeros(grid.shape, dtype=int)
    media[:, :, :2] = 1
    vox = element_voxel_index(mesh, grid)
    vhc = np.array([C, 3.4])[media.ravel()[vox]] if heterogeneous else C
    tc = np.array([K, 0.0037])[media.ravel()[vox]] if heterogeneous else K
    S = np.zeros(grid.shape)
    S[2:4, 2:4, 0] = 50.0  # W/cm^3 under the "beam"
    load = voxel_load_matrix(mesh, grid) @ S.ravel()
    dt, n_on = 0.05, 20
    stepper = HeatStepper(mesh, vhc, tc, dt, theta=0.5, lumped=lumped)
    T = np.full(mesh.p.shape[1], 37.0)
    E0 = stepper.energy(T)
    for _ in range(n_on):
        T = stepper.step(T, load)
    deposited = load.sum() * dt * n_on
    assert abs(stepper.energy(T) - E0 - deposited) <= 1e-8 * deposited
    long = HeatStepper(mesh, vhc, tc, 1e3, theta=1.0, lumped=lumped)
    for _ in range(30):
        T = long.step(T)
    assert abs(long.energy(T) - E0 - deposited) <= 1e-8 * deposited
    T_mean = 37.0 + deposited / long.energy(np.ones_like(T))
    np.testing.assert_allclose(T, T_mean, rtol=0, atol=1e-8)


def test_backward_euler_lumped_keeps_maximum_principle():
    mesh = box_mesh(6, 6, 4, 0.3, 0.3, 0.2)
    rng = np.random.default_rng(5)
    T = rng.uniform(30, 40, mesh.p.shape[1])
    s = HeatStepper(mesh, C, K, 10.0)  # large step
    for _ in range(5):
        T_new = s.step(T)
        assert T_new.min() >= T.min() - 1e-12 and T_new.max() <= T.max() + 1e-12
        T = T_new


def test_fixed_faces_hold_and_convective_relaxes_to_ambient():
    mesh = box_mesh(4, 4, 4, 0.2, 0.2, 0.2)
    n = mesh.p.shape[1]
    T0 = np.full(n, 37.0) + np.random.default_rng(1).normal(size=n)
    held = HeatStepper(mesh, C, K, 0.1, boundary=HeatBoundary.from_mcmatlab(1))
    T = held.run(T0, 5)
    np.testing.assert_array_equal(T[held.fixed], T0[held.fixed])  # MCmatlab type 1
    bc = HeatBoundary({"z-": FaceBC("fixed", temperature=10.0)})
    s = HeatStepper(mesh, C, K, 0.1, boundary=bc)
    top = np.flatnonzero(mesh.p[2] == 0)
    np.testing.assert_array_equal(np.sort(s.fixed), top)
    np.testing.assert_array_equal(s.step(T0)[top], 10.0)
    conv = HeatStepper(mesh, C, K, 1e4, boundary=HeatBoundary.from_mcmatlab(
        2, temperature=20.0, h=0.01))
    np.testing.assert_allclose(conv.run(T0, 40), 20.0, atol=1e-8)


def test_probe_style_shapes_single_and_ensemble():
    mesh = box_mesh(3, 3, 2, 0.3, 0.3, 0.2)
    s = HeatStepper(mesh, C, K, 0.1)
    T = np.full(mesh.p.shape[1], 37.0)
    assert s.step(T).shape == T.shape
    assert s.step(np.stack([T, T]), load=np.zeros_like(T)).shape == (2, T.size)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [(dict(vhc=-1.0), r"vhc must be > 0 and finite, got vhc\[0\]=-1.0"),
     (dict(tc=-1.0), r"tc must be >= 0 and finite, got tc\[0\]=-1.0"),
     (dict(dt=0.0), r"dt must be > 0, got 0.0"),
     (dict(dt=-0.1), r"dt must be > 0, got -0.1"),
     (dict(theta=1.5), r"theta must be in \[0, 1\], got 1.5"),
     (dict(method="lu"), "method must be one of"),
     (dict(vhc=np.ones(3)), r"vhc must be a scalar or have shape")],
)
def test_bad_input_names_field_and_value(kwargs, match):
    mesh = box_mesh(2, 2, 2, 0.2, 0.2, 0.2)
    args = dict(vhc=C, tc=K, dt=0.1) | kwargs
    with pytest.raises(ValueError, match=match):
        HeatStepper(mesh, **args)


def test_bad_step_input():
    mesh = box_mesh(2, 2, 2, 0.2, 0.2, 0.2)
    s = HeatStepper(mesh, C, K, 0.1)
    T = np.zeros((3, mesh.p.shape[1]))
    with pytest.raises(ValueError, match=r"vhc_scale must be > 0, got vhc_scale\[1\]=-2.0"):
        s.step(T, vhc_scale=[1.0, -2.0, 1.0])
    with pytest.raises(ValueError, match=r"tc_scale must be a scalar or have shape \(3,\)"):
        s.step(T, tc_scale=[1.0, 2.0])
    with pytest.raises(ValueError, match="load must have shape"):
        s.step(T, load=np.zeros(5))
    with pytest.raises(ValueError, match="T must have shape"):
        s.step(np.zeros(5))


def test_boundary_validation():
    with pytest.raises(ValueError, match="h must be > 0 for a convective face, got -1"):
        FaceBC("convective", temperature=20.0, h=-1)
    with pytest.raises(ValueError, match="temperature .* required"):
        FaceBC(2, h=0.1)
    with pytest.raises(ValueError, match="kind must be one of"):
        FaceBC(3)
    with pytest.raises(ValueError, match="faces keys must be in"):
        HeatBoundary({"top": 0})
    assert HeatBoundary({"z-": 1})["z-"].kind == "fixed"
    assert HeatBoundary.from_mcmatlab(0).is_insulated


def test_march_is_the_loop_of_steps_with_probes_and_callback():
    mesh = box_mesh(4, 3, 3, 0.4, 0.3, 0.3)
    stepper = HeatStepper(mesh, C, K, 0.1)
    T0, f, _, _ = _ensemble(mesh, 3)
    P = probe_matrix(mesh, np.array([[0.0, 0.0, 0.0], [0.1, 0.05, 0.2]]).T)
    times = np.array([0.0, 0.1, 0.2, 0.3])
    seen = []
    T, readings = march(lambda T, t0, t1: stepper.step(T, f if t1 < 0.25 else None), T0, times,
                        P, lambda k, t1, a, b: seen.append((k, t1, a.shape, b.shape)))
    ref = [T0]
    for k in range(3):
        ref.append(stepper.step(ref[-1], f if times[k + 1] < 0.25 else None))
    np.testing.assert_array_equal(T, ref[-1])
    assert readings.shape == (4, 3, 2)
    np.testing.assert_allclose(readings, [(P @ R.T).T for R in ref], rtol=1e-14)
    assert seen == [(k, t, (3, mesh.p.shape[1]), (3, mesh.p.shape[1]))
                    for k, t in ((1, 0.1), (2, 0.2), (3, 0.3))]
    T1, r1 = march(lambda T, t0, t1: stepper.step(T), T0[0], times[:2])  # one field, no probes
    assert T1.shape == T0[0].shape and r1 is None
    with pytest.raises(ValueError, match="times must increase"):
        march(lambda T, t0, t1: T, T0, [0.0, 0.2, 0.1])


@pytest.mark.parametrize("method", ["fast", "direct", "pcg"])
@pytest.mark.parametrize("shape", ["one", "member", "ensemble"])
def test_a_step_leaves_its_input_unchanged(method, shape):
    """The step returns new temperatures; the caller's (the previous step's, used for the
    damage integral) stay as they were, on every solver path and for one member too."""
    mesh = box_mesh(5, 4, 3, 0.5, 0.4, 0.3)
    T, f, _, _ = _ensemble(mesh, 3)
    T = {"one": T[0], "member": T[:1], "ensemble": T}[shape]
    kept = T.copy()
    new = HeatStepper(mesh, C, K, 0.2, method=method).step(T, f[0])
    np.testing.assert_array_equal(T, kept)
    assert np.abs(new - kept).max() > 1e-3


def test_a_step_of_another_length_by_the_mass_scale():
    """A stepper built for dt steps dt' when VHC is scaled by dt / dt' (the error-controlled
    heat run takes every step length on one stepper)."""
    mesh = box_mesh(5, 4, 3, 0.5, 0.4, 0.3)
    T, f, _, _ = _ensemble(mesh, 1)
    for method in ("fast", "direct", "pcg"):
        ref = HeatStepper(mesh, C, K, 0.05, method=method, rtol=1e-14).step(T[0], f[0])
        other = HeatStepper(mesh, C, K, 0.2, method=method, rtol=1e-14)
        got = other.step(T, f[:1], vhc_scale=np.array([0.2 / 0.05]))[0]
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
