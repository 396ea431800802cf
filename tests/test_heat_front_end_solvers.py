"""The heat front end's choice of operator and solver (``model.HS``): media layered in depth
on the tensor-product operator, solved directly; ``HS.use_gpu`` on numba's CUDA simulator;
the finer heat mesh for optics that follow the temperature."""

import json
import os
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import fem
from mcmatlab_py import Medium, Model
from mcmatlab_py.heat.mesh import FINE_MESH_MAX_NODES, heat_mesh_divisions

MODEL = textwrap.dedent("""
    import numpy as np
    from mcmatlab_py import Medium, Model

    def layered_model(mass="lumped", nz=8, boundary=0, nxy=6):
        m = Model()
        G = m.G
        G.nx, G.ny, G.nz, G.Lx, G.Ly, G.Lz = nxy, nxy, nz, 0.1, 0.1, 0.08
        G.media = [Medium("water", mua=1e-8, mus=1e-8, g=1.0, VHC=4.19, TC=5.8e-3),
                   Medium("tissue", mua=1.0, mus=100.0, g=0.9, VHC=3.76, TC=3.7e-3)]
        G.geom_func = lambda X, Y, Z: np.where(Z > 0.03, 1, 0)
        x, y, z = np.meshgrid(G.x, G.y, G.z, indexing="ij")
        m.MC.NA = np.exp(-20 * z) * np.exp(-(x**2 + y**2) / 0.001) * (z > 0.03)
        m.MC.NA /= m.MC.NA.sum() * G.dx * G.dy * G.dz  # W/cm^3 per W, all absorbed
        HS = m.HS
        HS.P, HS.duration_on, HS.duration_off, HS.T_initial, HS.progress = 0.1, 0.2, 0.1, 37.0, False
        HS.heat_boundary_type, HS.mass = boundary, mass
        HS.temp_sensor_positions = [(0, 0, 0.035), (0.02, 0, 0.05)]
        return m
""")
exec(MODEL)  # noqa: S102 - the same model in this process and in the simulator's


def _heat(m):
    m.simulate_heat_distribution()
    return m.HS


@pytest.mark.parametrize("mass", ["lumped", "averaged"])
def test_layered_media_take_the_direct_tensor_product_solver(mass, monkeypatch):
    made = []
    real = fem.HeatStepper

    def spy(*a, **kw):
        st = real(*a, **kw)
        made.append((st.operator, st.method))
        return st

    monkeypatch.setattr(fem, "HeatStepper", spy)
    HS = _heat(layered_model(mass))  # noqa: F821 - defined by exec(MODEL)
    assert made and all(op == "kronecker" and method == "fast" for op, method in made), made
    assert np.all(np.isfinite(HS.sensor_temps))


@pytest.mark.parametrize("mass", ["lumped", "averaged"])
def test_layered_tensor_product_conserves_the_absorbed_energy(mass):
    m = layered_model(mass)  # noqa: F821
    m.HS.duration_off = 0.0
    HS = _heat(m)
    # the heat content on the nodes, with the operator's own mass (insulating faces)
    st = fem.HeatStepper(HS.mesh, *_element_media(m), 1.0, operator="kronecker", mass=mass)
    gained = float(np.sum(st.M @ (HS.T_nodes - 37.0)))
    assert gained == pytest.approx(0.1 * 0.2, rel=1e-6)


def _element_media(m):
    grid = fem.BoxGrid(m.G.nx, m.G.ny, m.G.nz, m.G.Lx, m.G.Ly, m.G.Lz)
    X, Y, Z = np.meshgrid(grid.x, grid.y, grid.z, indexing="ij")
    M = np.asarray(m.G.geom_func(X, Y, Z)).ravel()[fem.element_voxel_index(m.HS.mesh, grid)]
    return np.where(M == 0, 4.19, 3.76), np.where(M == 0, 5.8e-3, 3.7e-3)


def test_layered_agrees_with_the_p1_tetrahedra_away_from_the_edges():
    """The two operators differ only on the box's edges and the side faces' interface
    lines: sensors inside read the same rise to the discretisation's difference there."""
    a = _heat(layered_model("lumped")).sensor_temps[-1] - 37.0  # noqa: F821
    m = layered_model("lumped")  # noqa: F821
    orig = fem.HeatStepper

    def p1(*args, **kw):
        kw.pop("operator", None)
        return orig(*args, **kw)

    try:
        fem.HeatStepper = p1
        b = _heat(m).sensor_temps[-1] - 37.0
    finally:
        fem.HeatStepper = orig
    assert np.allclose(a, b, rtol=0.02), (a, b)


def test_use_gpu_without_a_gpu_names_the_setting():
    pytest.importorskip("numba_cuda", reason="the gpu extra (numba-cuda) is not installed")
    from fem.gpu import gpu_available

    if gpu_available():
        pytest.skip("a CUDA GPU is present")
    m = layered_model()  # noqa: F821
    m.HS.use_gpu = True
    with pytest.raises(RuntimeError, match=r"HS.use_gpu = False"):
        m.simulate_heat_distribution()


def test_use_gpu_rejects_a_non_boolean():
    m = layered_model()  # noqa: F821
    m.HS.use_gpu = "yes"
    with pytest.raises(ValueError, match="HS.use_gpu must be True or False"):
        m.simulate_heat_distribution()


def test_use_gpu_on_the_simulator_agrees_with_the_cpu():
    """HS.use_gpu = True on numba's CUDA simulator (a subprocess) against the CPU run: the
    solves stop at a relative residual of 1e-9, so the sensors agree far inside 1e-6 K."""
    pytest.importorskip("numba_cuda", reason="the gpu extra (numba-cuda) is not installed")
    script = MODEL + textwrap.dedent("""
        import json, sys
        sys.setswitchinterval(1e-4)
        m = layered_model(nz=4, nxy=3)
        m.HS.dt = 0.02  # the same steps on both sides
        m.HS.use_gpu = True
        m.simulate_heat_distribution()
        print(json.dumps(m.HS.sensor_temps.tolist()))
    """)
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    gpu = np.array(json.loads(out.stdout.strip().splitlines()[-1]))
    m = layered_model(nz=4, nxy=3)  # noqa: F821
    m.HS.dt = 0.02
    cpu = _heat(m).sensor_temps
    assert gpu.shape == cpu.shape
    assert np.max(np.abs(gpu - cpu)) < 1e-6


def _coupled(n, follows):
    m = Model()
    m.G.nx = m.G.ny = m.G.nz = n
    mus = (lambda wl, FR, T, FD: 100.0 + T) if follows == "T" else (
        lambda wl, FR, T, FD: 100.0 + 1e-3 * FR)
    m.G.media = [Medium("a", mua=1.0, mus=mus, g=0.9, VHC=3.7, TC=0.005)]
    return m


def test_optics_that_follow_the_temperature_get_a_heat_mesh_twice_as_fine():
    m = _coupled(10, "T")
    assert heat_mesh_divisions(m.G, m.HS) == (20, 20, 20)
    m.HS.mesh_divisions = (7, 7, 7)  # the user's choice stands
    assert heat_mesh_divisions(m.G, m.HS) == (7, 7, 7)
    assert heat_mesh_divisions(_coupled(10, "FR").G, Model().HS) is None
    assert heat_mesh_divisions(Model().G, Model().HS) is None


def test_a_fine_mesh_too_large_is_not_taken_and_the_warning_names_the_setting():
    n = round((FINE_MESH_MAX_NODES ** (1 / 3)) / 2) + 2
    m = _coupled(n, "T")
    with pytest.warns(UserWarning, match=r"HS.mesh_divisions"):
        assert heat_mesh_divisions(m.G, m.HS) is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert heat_mesh_divisions(m.G, m.HS, warn=False) is None
