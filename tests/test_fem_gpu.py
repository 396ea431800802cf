r"""The GPU heat solver (:mod:`fem.gpu`, for ``HS.use_gpu``) on numba's CUDA simulator.

No GPU is needed: the kernels run as Python threads in a subprocess that sets
``NUMBA_ENABLE_CUDASIM=1`` before ``numba.cuda`` is imported; the parent runs the CPU
references (:class:`fem.linsolve.DirectSolver`, the CPU stepper) and compares.

The tolerances come from the CG stopping test, ``||r|| <= rtol ||b||``: the error of a solve
is at most :math:`\|A^{-1}\|_2\,\|r\|_2 \le \mathrm{rtol}\,\|b\|_2/\lambda_{\min}(A)`, plus the
rounding of either solver (:math:`n\,\varepsilon\,\kappa(A)\,\|x\|`, a pessimistic bound for
LU, negligible beside it). Over steps, an error made at one step is carried by the step
map :math:`S = (M/\Delta t + \theta A)^{-1}(M/\Delta t - (1-\theta) A)`, whose norm in the
lumped mass's inner product is at most one for :math:`\theta \ge 1/2`; so after ``n`` steps
the 2-norm of the difference is at most :math:`\sqrt{m_{\max}/m_{\min}}` times the sum of the
steps' solve errors.
"""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from fem.gpu import DEFAULT_RTOL, gpu_available, make_solver
from fem.linsolve import DirectSolver

EPS = np.finfo(float).eps

# the same problems in both processes: on a 4 x 4 x 3 voxel box (80 nodes; the simulator
# runs a few thousand rows per second), two layers under Crank-Nicolson with a convective
# top and the bottom held (the CPU's sparse LU; free and fixed nodes), and one medium,
# insulated, under backward Euler (the CPU's fast diagonalization)
PROBLEM = textwrap.dedent("""
    import numpy as np
    from fem import (BoxGrid, FaceBC, HeatBoundary, HeatStepper, element_voxel_index,
                     voxel_load_matrix)

    GRID = BoxGrid(4, 4, 3, 0.4, 0.4, 0.3)
    DT = 1.0  # s; D dt / h^2 = 0.14 (layers), so the stiffness weighs in the solves
    N_STEPS = {"layers": 3, "fast": 3}

    def stepper(case, method="auto"):
        mesh = GRID.mesh()
        if case == "layers":
            deep = np.broadcast_to(np.arange(GRID.nz) >= 1, GRID.shape).ravel()
            deep = deep[element_voxel_index(mesh, GRID)]
            boundary = HeatBoundary({"z-": FaceBC("convective", temperature=20.0, h=0.01),
                                     "z+": FaceBC("fixed", temperature=37.0)})
            return HeatStepper(mesh, np.where(deep, 3.4, 3.9), np.where(deep, 0.0037, 0.0052),
                               DT, theta=0.5, boundary=boundary, method=method)
        return HeatStepper(mesh, 3.7, 0.0052, DT, method=method)

    def load():  # W per node: 50 W/cm^3 decaying with depth
        S = 50.0 * np.exp(-10.0 * GRID.z)[None, None, :] * np.ones(GRID.shape)
        return voxel_load_matrix(GRID.mesh(), GRID) @ S.ravel()

    def run(st, case):
        T = np.full(st.npoints, 37.0)
        out = []
        for _ in range(N_STEPS[case]):
            T = st.step(T, load())
            out.append(T)
        return np.array(out)

    def system(st):
        # the free-node matrices of the stepper's solves, with theta on R; A = a M + b K + R
        f = np.ix_(st.free, st.free)
        return st.M.tocsr()[f], st.K.tocsr()[f], st.theta * st.R.tocsr()[f]

    def rhs(n):  # two members: right-hand sides, and scales on the mass and the stiffness
        rng = np.random.default_rng(1)
        return (rng.uniform(30.0, 40.0, (2, n)), np.array([1.0, 1.3]) / DT,
                np.array([0.5, 0.4]))
""")

SIMULATED = PROBLEM + textwrap.dedent("""
    import json
    import sys

    import numba
    from fem.gpu import CudaPCG

    # the simulator's threads hand the GIL round at barriers: a short switch interval
    # makes each launch five times faster
    sys.setswitchinterval(1e-4)
    assert numba.config.ENABLE_CUDASIM
    res = {}
    M, K, R = system(stepper("layers"))
    r, a, b = rhs(M.shape[0])
    solver = CudaPCG(M, K, R, blocks=3)  # the rows over 3 blocks: the two-pass sums
    x = solver.solve(r, a, b)
    res["solve"] = {"x": x.tolist(), "iterations": solver.last_iterations}
    again = solver.solve(r, a, b, x0=np.zeros_like(r))
    res["repeat_identical"] = bool(np.array_equal(x, again))
    solver.solve(r, a, b)  # no x0: the last solution, still on the device
    res["warm_iterations"] = solver.last_iterations
    for case in N_STEPS:
        st = stepper(case, method="gpu")
        res[case] = {"method": st.method, "T": run(st, case).tolist(),
                     "iterations": st._solver.last_iterations}
    print(json.dumps(res))
""")


@pytest.fixture(scope="module")
def simulated():
    """All the simulator's runs, in one subprocess (about 10 s)."""
    pytest.importorskip("numba_cuda", reason="the gpu extra (numba-cuda) is not installed")
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    out = subprocess.run([sys.executable, "-c", SIMULATED], env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def _problem():
    ns = {}
    exec(PROBLEM, ns)
    return ns


def _system_matrix(M, K, R, a, b):
    return (a * M + b * K + R).toarray()


def _solve_bound(A: np.ndarray, b: np.ndarray, x: np.ndarray, rtol: float) -> float:
    """2-norm bound on the error of a solve stopped at ``||r|| <= rtol ||b||``, plus both
    solvers' rounding."""
    lam = np.linalg.eigvalsh(A)
    return (rtol * np.linalg.norm(b) / lam[0]
            + 2 * A.shape[0] * EPS * lam[-1] / lam[0] * np.linalg.norm(x))


def test_solve_agrees_with_direct_to_the_cg_tolerance(simulated):
    ns = _problem()
    M, K, R = ns["system"](ns["stepper"]("layers"))
    r, a, b = ns["rhs"](M.shape[0])
    x_direct = DirectSolver(M, K, R).solve(r, a, b)
    x_gpu = np.array(simulated["solve"]["x"])
    assert simulated["solve"]["iterations"] > 0
    for m in range(2):
        A = _system_matrix(M, K, R, a[m], b[m])
        bound = _solve_bound(A, r[m], x_direct[m], DEFAULT_RTOL)
        err = np.linalg.norm(x_gpu[m] - x_direct[m])
        assert err <= bound, (m, err, bound)
        assert bound < 1e-7 * np.linalg.norm(x_direct[m])  # the bound says something


def test_solve_repeats_to_the_bit_and_warm_starts_on_the_device(simulated):
    assert simulated["repeat_identical"]
    assert simulated["warm_iterations"] == 0  # the kept solution already meets the tolerance


@pytest.mark.parametrize("case", ["layers", "fast"])
def test_steps_agree_with_the_cpu_stepper(simulated, case):
    """Several implicit steps of ``HeatStepper(method="gpu")`` against the CPU stepper (sparse
    LU, fast diagonalization), within the accumulated bound of the solves' errors."""
    ns = _problem()
    st = ns["stepper"](case)
    assert st.method == {"layers": "direct", "fast": "fast"}[case]
    T_cpu = ns["run"](st, case)
    T_gpu = np.array(simulated[case]["T"])
    assert simulated[case]["method"] == "gpu"
    assert simulated[case]["iterations"] > 0
    M, K, R = ns["system"](st)
    A = _system_matrix(M, K, R, 1.0 / ns["DT"], st.theta)
    m = M.diagonal()
    total = 0.0
    for k, Tk in enumerate(T_cpu):
        x = Tk[st.free]
        # the step's right-hand side is A x (the CPU's solve is exact to rounding); the
        # GPU's differs by the earlier steps' errors, relative 1e-9
        total += _solve_bound(A, (1 + 1e-6) * (A @ x), x, DEFAULT_RTOL)
        bound = np.sqrt(m.max() / m.min()) * total
        err = np.linalg.norm(T_gpu[k] - Tk)
        assert err <= bound, (k, err, bound)
        assert bound < 1e-7 * np.linalg.norm(x)
    assert np.array_equal(T_gpu[:, st.fixed], T_cpu[:, st.fixed])  # held nodes stay held
    assert T_cpu[-1].max() > 37.5  # the load heats: the comparison is not of constants


LOWER = textwrap.dedent("""
    import types
    import numba.cuda.dispatcher as D
    # no GPU: the compiler asks the current device for its compute capability
    D.get_current_device = lambda: types.SimpleNamespace(compute_capability=(8, 0))
    from numba import types as T
    from numba.cuda.compiler import compile_cuda
    from fem import _cuda_kernels as KC

    f, i32, i64 = T.Array(T.float64, 1, "C"), T.Array(T.int32, 1, "C"), T.int64
    mat = (i32, i32, f, f, f)
    sigs = {"start": mat + (f,) * 5 + (i64,) + (f,) * 7,
            "spmv_dot": mat + (f, f, i64, f, f, f), "update": (i64,) + (f,) * 9,
            "direction": (i64,) + (f,) * 4, "reduce_partials": (f, i64, f)}
    for name, sig in sigs.items():
        compile_cuda(getattr(KC, name).py_func, T.void, sig, cc=(8, 0))
    print("LOWERED", KC.TPB)
""")


def test_kernels_type_and_lower_for_the_cuda_target():
    """The simulator runs the kernels as Python and checks no types: the real CUDA target
    types them and lowers them to LLVM IR, without a GPU or the CUDA libraries (PTX would
    need NVVM)."""
    pytest.importorskip("numba_cuda", reason="the gpu extra (numba-cuda) is not installed")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    out = subprocess.run([sys.executable, "-c", LOWER], env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.split() == ["LOWERED", "128"]


def test_import_fem_needs_no_cuda():
    code = ("import sys, fem, fem.gpu; fem.gpu.DEFAULT_RTOL; "
            "print('numba.cuda' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "False"


@pytest.mark.skipif(gpu_available(), reason="a CUDA GPU (or the simulator) is available here")
def test_gpu_missing_names_the_setting_and_the_alternative():
    ns = _problem()
    st = ns["stepper"]("layers")
    with pytest.raises(RuntimeError, match=r"HS.use_gpu = True needs numba-cuda .*"
                       r"numba.cuda.is_available\(\) is False.*Set HS.use_gpu = False"):
        make_solver(*ns["system"](st))
    with pytest.raises(RuntimeError, match="Set HS.use_gpu = False to run on the CPU"):
        ns["stepper"]("layers", method="gpu")
