"""The GPU Monte Carlo (``MC.use_gpu``) on numba's CUDA simulator, against the CPU kernel.

No GPU is needed: the CUDA kernel runs as Python threads in a subprocess that sets
``NUMBA_ENABLE_CUDASIM=1`` before ``numba.cuda`` is imported. Each CUDA thread runs its own
random stream, so the totals are compared statistically: a packet deposits or lets escape
a fraction ``a`` in [0, 1] of its weight, ``var(a) <= f (1 - f)`` for the mean ``f``, and the
difference of two independent runs of N packets has a standard error of at most
``sqrt(2 f (1 - f) / N)``. The energy balance is exact in fixed point on both.
"""

import json
import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from mcmatlab_py import Medium, Model, NotBuiltError
from mcmatlab_py.monte_carlo import gpu_available

pytestmark = pytest.mark.slow  # the CUDA simulator and the PTX compile take half a minute

pytest.importorskip("numba_cuda", reason="the gpu extra (numba-cuda) is not installed")

N_PHOTONS = 2000

# three cases: on 8 x 8 x 8 voxels one medium with matched interfaces (the kernel's fast
# path), and two layers of different refractive index under n_outside = 1 (Fresnel,
# refraction, the voxel walk), with Russian roulette off; and Example 17's droplet of
# water in air under a plane wave on 21 x 21 x 11 (smoothed normals; its totals run the
# curved path on both, but 2000 packets do not tell where the reflected light goes:
# tests/test_mc_curved.py checks that, on the CPU)
MODELS = textwrap.dedent("""
    import numpy as np
    from mcmatlab_py import Medium, Model

    def build(case, gpu, seed=1, n=2000):
        m = Model()
        G = m.G
        G.nx = G.ny = G.nz = 8
        G.Lx = G.Ly = G.Lz = 0.1
        MC = m.MC
        MC.n_photons_requested, MC.seed, MC.progress, MC.use_gpu = n, seed, False, gpu
        if case == "matched":
            G.media = [Medium("t", mua=10.0, mus=50.0, g=0.8)]
            G.geom_func = lambda X, Y, Z: np.zeros(X.shape, dtype=int)
            MC.light_source.source_type = 0
        elif case == "air":  # MCmatlab's air: the fluence rate from the track length
            G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0)]
            G.geom_func = lambda X, Y, Z: np.zeros(X.shape, dtype=int)
            MC.light_source.source_type = 0
        elif case == "curved":  # Example 17's droplet: smoothed normals, and reflections
            G.nx = G.ny = 21  # that travel on through the droplet's voxels
            G.nz = 11
            G.Lz = 0.05
            G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0, n=1.0),
                       Medium("water", mua=0.00036, mus=10.0, g=1.0, n=1.3)]
            G.geom_func = lambda X, Y, Z: np.where(
                X**2 + Y**2 + (Z - G.z[-1]) ** 2 < 0.04**2, 1, 0)
            MC.matched_interfaces = False
            MC.smoothing_length_scale = 1.0
            MC.boundary_type = 1
            MC.light_source.source_type = 2  # plane wave over the top face
        else:
            G.media = [Medium("a", mua=5.0, mus=30.0, g=0.7, n=1.0),
                       Medium("b", mua=15.0, mus=60.0, g=0.9, n=1.4)]
            G.geom_func = lambda X, Y, Z: np.where(Z > 0.04, 1, 0)
            MC.matched_interfaces = False
            MC.russian_roulette = False
            MC.boundary_type = 2
            MC.light_source.source_type = 1  # isotropic point inside
            MC.light_source.z_focus = 0.05
        return m

    def totals(MC):
        return {"absorbed": MC.absorbed_fraction, "top": MC.escaped["top"],
                "bottom": MC.escaped["bottom"], "sides": MC.escaped["sides"],
                "outside": MC.absorbed_outside_fraction, "specular": MC.specular_reflectance,
                "balance": MC.energy_balance, "NA_sum": float(MC.NA.sum()),
                "n": MC.n_photons, "NFR_max": float(MC.NFR.max()),
                "NFR_sum": float(MC.NFR.sum())}
""")

CASES = ("matched", "mismatched", "curved", "air")


def _namespace():
    ns = {}
    exec(MODELS, ns)  # the same model builder in both processes
    return ns


@pytest.fixture(scope="module")
def simulated():
    """The totals of both cases run with ``use_gpu`` on the CUDA simulator (one subprocess)."""
    script = MODELS + textwrap.dedent(f"""
        import json
        print(json.dumps({{c: totals(build(c, True, n={N_PHOTONS}).run_monte_carlo().MC)
                          for c in {CASES!r}}}))
    """)
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("case", CASES)
def test_simulated_gpu_agrees_with_cpu(simulated, case):
    gpu = simulated[case]
    ns = _namespace()
    model = ns["build"](case, False, seed=2, n=N_PHOTONS).run_monte_carlo()
    _assert_totals_agree(gpu, ns["totals"](model.MC), N_PHOTONS, model.G)


def _assert_totals_agree(gpu: dict, cpu: dict, n: int, G) -> None:
    """Both runs' fractions within 4 standard errors of their difference; the GPU's energy
    balance exact in fixed point, and NA * dV summed over the voxels its absorbed fraction."""
    assert gpu["n"] == n
    assert gpu["balance"] == pytest.approx(1.0, abs=1e-12)
    for key in ("absorbed", "top", "bottom", "sides"):
        f = 0.5 * (gpu[key] + cpu[key])
        se = math.sqrt(max(2.0 * f * (1.0 - f), 1e-12) / n)
        assert abs(gpu[key] - cpu[key]) < 4.0 * se, (key, gpu[key], cpu[key], se)
    assert gpu["NA_sum"] * G.dx * G.dy * G.dz == pytest.approx(gpu["absorbed"], rel=1e-12)


def test_simulated_gpu_tallies_the_track_length_in_air(simulated):
    """In air no packet interacts: the pencil beam's fluence rate is 1 / (dx dy) in each
    of the column's 8 voxels (0.1 / 8 cm on a side), zero elsewhere, on the GPU as on the CPU."""
    air = simulated["air"]
    beam = 1.0 / (0.1 / 8) ** 2
    assert air["NFR_max"] == pytest.approx(beam, rel=1e-6)
    assert air["NFR_sum"] == pytest.approx(8 * beam, rel=1e-6)


def _real_gpu() -> bool:
    """A CUDA GPU, not the simulator (whose runs are the test above)."""
    import numba

    return not numba.config.ENABLE_CUDASIM and gpu_available()


@pytest.mark.skipif(not _real_gpu(), reason="no CUDA GPU here (the simulator's runs are above)")
@pytest.mark.parametrize("case", CASES)
def test_real_gpu_agrees_with_cpu(case):
    """On a real GPU, 100 times the simulator's packets: the same bounds, 10 times tighter."""
    n = 100 * N_PHOTONS
    ns = _namespace()
    gpu = ns["totals"](ns["build"](case, True, seed=3, n=n).run_monte_carlo().MC)
    model = ns["build"](case, False, seed=4, n=n).run_monte_carlo()
    cpu = ns["totals"](model.MC)
    _assert_totals_agree(gpu, cpu, n, model.G)
    if case == "air":  # the track length: every packet down the same column
        assert gpu["NFR_sum"] == pytest.approx(cpu["NFR_sum"], rel=1e-6)
        assert gpu["NFR_max"] == pytest.approx(cpu["NFR_max"], rel=1e-6)


@pytest.mark.skipif(not _real_gpu(), reason="no CUDA GPU here")
def test_real_gpu_run_past_int64_fixed_point():
    """2^28 packets (twice what int64 holds at weight W_ONE = 2^36; under a second on an
    H200) through a thin absorbing slab with mus = 0: absorbed with chance 1 - exp(-mua d)."""
    n, mua, d = 2**28, 69.3, 0.01
    m = Model()
    m.G.nx = m.G.ny = m.G.nz = 1
    m.G.Lx = m.G.Ly = 1.0
    m.G.Lz = d
    m.G.media = [Medium("slab", mua=mua, mus=0.0, g=0.0)]
    m.G.geom_func = lambda X, Y, Z: np.zeros(X.shape, dtype=int)
    m.MC.n_photons_requested, m.MC.progress, m.MC.use_gpu = n, False, True
    m.MC.light_source.source_type = 0
    MC = m.run_monte_carlo().MC
    f = 1.0 - math.exp(-mua * d)
    assert MC.energy_balance == pytest.approx(1.0, abs=1e-12)
    assert abs(MC.absorbed_fraction - f) < 4.0 * math.sqrt(f * (1 - f) / n)


def _tiny(gpu=True) -> Model:
    m = Model()
    m.G.nx = m.G.ny = m.G.nz = 4
    m.G.Lx = m.G.Ly = m.G.Lz = 0.1
    m.G.media = [Medium("t", mua=1.0, mus=10.0, g=0.9)]
    m.G.geom_func = lambda X, Y, Z: np.zeros(X.shape, dtype=int)
    m.MC.n_photons_requested = 100
    m.MC.progress = False
    m.MC.use_gpu = gpu
    return m


def test_gpu_optional_outputs_are_not_built():
    m = _tiny()
    m.MC.calc_normalized_irradiance = True
    with pytest.raises(NotBuiltError, match="use_gpu runs the plain Monte Carlo only"):
        m.run_monte_carlo()


@pytest.mark.skipif(gpu_available(), reason="a CUDA GPU (or the simulator) is available here")
def test_gpu_missing_says_how_to_get_one():
    with pytest.raises(RuntimeError, match=r"numba.cuda.is_available\(\) is False"):
        _tiny().run_monte_carlo()


def test_use_gpu_is_validated():
    m = _tiny()
    m.MC.use_gpu = "yes"
    with pytest.raises(ValueError, match="MC.use_gpu must be True or False"):
        m.run_monte_carlo()


PTX = textwrap.dedent("""
    import types
    import numba.cuda.dispatcher as D
    # no GPU: device functions ask the current device for its compute capability
    D.get_current_device = lambda: types.SimpleNamespace(compute_capability=(8, 0))
    from numba import cuda, types as T
    from mcmatlab_py.monte_carlo import _cuda as KC
    f64, i64, i32, b = T.float64, T.int64, T.int32, T.boolean

    def A(dt, nd=1):
        return T.Array(dt, nd, "C")

    sig = (A(i32), A(f64), A(f64), A(f64), A(f64), i64, i64, i64, i64, f64, f64, f64,
           i64, f64, b, b, f64, f64, A(i64), A(f64), A(f64), A(i64), A(i32), A(f64, 2),
           A(T.float32), b, T.uint64, i64, i64, i64, i64, A(i64), A(i64), A(b), A(i64))
    try:
        ptx, _ = cuda.compile_ptx(KC.transport_streams.py_func, sig, cc=(8, 0), fastmath=True)
    except Exception as e:
        if "DynamicLibNotFound" in type(e).__name__ or "NVVM" in str(e).upper()[:2000]:
            print("SKIP", type(e).__name__)
            raise SystemExit(0)
        raise
    print("PTX", len(ptx))
""")


@pytest.mark.slow
def test_cuda_kernel_compiles_to_ptx():
    """The real CUDA target (not the simulator) compiles the kernel and the shared device
    functions, without a GPU; needs NVVM and NVRTC (numba-cuda[cu12]), else skipped. About a
    minute."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    out = subprocess.run([sys.executable, "-c", PTX], env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    if out.stdout.startswith("SKIP"):
        pytest.skip(f"no CUDA toolkit libraries to compile with ({out.stdout.strip()})")
    assert out.stdout.startswith("PTX")
