r"""Our heat solver against comet-lab/fem-heat-simulator on the peer's own problem.

The peer (github.com/comet-lab/fem-heat-simulator, C++/Eigen: trilinear hexahedra, consistent
mass, nodal fluence rate times ``mua`` through the consistent mass, Crank-Nicolson in single
precision with Jacobi-preconditioned CG) and ours run one after the other in one process run,
one thread each (``NUMBA_NUM_THREADS``, ``OMP_NUM_THREADS`` and the BLAS at 1; Eigen's
``setNbThreads(1)``), on the problem of issue 47:

* a 1 x 1 x 0.5 cm block, x, y in [-0.5, 0.5], z in [0, 0.5] (z into the tissue);
  TC 0.0062 W cm^-1 K^-1, VHC 4.3 J cm^-3 K^-1; the top face z = 0 convective
  (h = 0.001 W cm^-2 K^-1, ambient 20 deg C), the other five faces held at 20 deg C,
  20 deg C at the start;
* the source :math:`q = P \mu_a e^{-\mu_a z}\, \frac{2}{\pi w^2} e^{-2 r^2/w^2}` W cm^-3,
  P = 1 W, w = 0.1 cm, mua = 10 cm^-1, for 1 s in 100 Crank-Nicolson steps of 0.01 s;
* read at r = 0, z = 0 / 0.05 / 0.1 cm (nodes of every mesh below).

The reference is the modal series of the same problem (:func:`modal_reference`), converged
to 1e-6 K; issue 47's semi-analytic values (rises 77.30 / 60.36 / 38.37 K) agree with it to
0.014 K. Errors are in % of the reference's rise.

Our rows, all on :func:`fem.box_mesh` (nodes at the corners of a regular grid):

* ``averaged``: ``operator="kronecker", mass="averaged"`` (the filter's operator), the
  load integrated exactly against each node's tensor-product hat function (the source is
  separable: Gauss-Legendre per axis over the node's two intervals);
* ``q1``: ``mass="consistent"`` (the Galerkin trilinear scheme), the same load;
* ``q1-nodal``: ``mass="consistent"``, the nodal interpolant of q through the consistent P1
  mass: close to the peer's discretization (which weighs it with its Q1 mass);
* ``p1``: the default (``operator="p1"``, lumped mass), the same nodal load.

Each at the peer's 41 x 41 x 21 nodes and, for the averaged and the peer-like Q1 rows, at
the coarsest mesh tried that reaches 0.2 % of the rise at the three depths; ``--fine`` adds the
other two at theirs (4 million nodes for the default: several minutes and 8 GB) and the peer at
91 x 91 x 51, where it reaches 0.2 %.
Wall times are the best of ``--repeat`` interleaved rounds, for the steps and for the
set-up (mesh, matrices, load, probes; the peer's mesh, fluence rate, sensors and
``initializeModel``); ours after a warm-up on a small mesh, so that numba's compilation
is not counted. CPU times of both are given too: on a shared machine they move
less than the wall times.

The peer's driver is a small C++ program (:data:`DRIVER_CPP`) that this script can write
and build against a checkout of the peer (CMake >= 3.29 and Eigen 3.4; the peer's code is
not copied here)::

    python benchmarks/bench_heat_peer.py --build-peer /tmp/peer/src --peer-dir /tmp/peer/driver
    python benchmarks/bench_heat_peer.py --peer /tmp/peer/driver/build/peer_heat [--fine]

or ``PEER_HEAT=/tmp/peer/driver/build/peer_heat``. Without a driver the peer's row is
skipped (with a message) and ours still run.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

for _v in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# the problem (cm, s, W, J, K)
SIZE = (1.0, 1.0, 0.5)
TC, VHC, HTC, T0 = 0.0062, 4.3, 0.001, 20.0
P, W, MUA = 1.0, 0.1, 10.0
DT, STEPS = 0.01, 100
DEPTHS = (0.0, 0.05, 0.1)
ISSUE_RISE = (77.30, 60.36, 38.37)  # issue 47's semi-analytic reference, K
TARGET = 0.2  # % of the rise, at every depth
TIMES = ("steps_s", "setup_s", "cpu_steps_s", "cpu_setup_s")  # wall and CPU seconds

#: ours: (operator, mass, load) of each configuration, and its label
CONFIGS = {
    "averaged": (("kronecker", "averaged", "hat"), "ours, tensor product, averaged mass, exact load"),
    "q1": (("kronecker", "consistent", "hat"), "ours, Q1 (consistent mass), exact load"),
    "q1-nodal": (("kronecker", "consistent", "nodal"), "ours, Q1 (consistent mass), nodal load"),
    "p1": (("p1", "lumped", "nodal"), "ours, P1 lumped (default), nodal load"),
}
#: rows (config, voxels per axis); FINE only with --fine. The second mesh of a configuration
#: is the coarsest tried on which every error is within TARGET (the next coarser: averaged
#: 27 x 27 x 21 nodes -0.24 %, Q1 nodal 81 x 81 x 51 -0.25 %, Q1 exact 141 x 141 x 71 +0.21 %,
#: P1 161 x 161 x 81 -0.31 %, the peer 81 x 81 x 51 -0.25 %)
ROWS = [("averaged", (40, 40, 20)), ("q1", (40, 40, 20)), ("q1-nodal", (40, 40, 20)),
        ("p1", (40, 40, 20)), ("averaged", (28, 28, 20)), ("q1-nodal", (90, 90, 50))]
FINE = [("peer", (90, 90, 50)), ("q1", (160, 160, 80)), ("p1", (200, 200, 100))]

DRIVER_CPP = r"""
// comet-lab/fem-heat-simulator's CPU solver on benchmarks/bench_heat_peer.py's problem.
// usage: peer_heat NX NY NZ [DT] [DURATION] [THREADS]   (nodes per axis)
#include "FEM_Simulator.h"
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>

int main(int argc, char** argv)
{
    if (argc < 4) {
        std::fprintf(stderr, "usage: %s NX NY NZ [DT] [DURATION] [THREADS]\n", argv[0]);
        return 2;
    }
    std::array<long, 3> n = { std::atol(argv[1]), std::atol(argv[2]), std::atol(argv[3]) };
    float dt = argc > 4 ? std::atof(argv[4]) : 0.01f;
    float duration = argc > 5 ? std::atof(argv[5]) : 1.0f;
    Eigen::setNbThreads(argc > 6 ? std::atoi(argv[6]) : 1);
    using clock = std::chrono::steady_clock;
    auto t0 = clock::now();
    std::clock_t c0 = std::clock();
    std::array<float, 3> size = { 1.0f, 1.0f, 0.5f };  // x, y in [-0.5, 0.5], z in [0, 0.5]
    // faces: z = 0, z = max, y = min, y = max, x = min, x = max
    std::array<BoundaryType, 6> bc = { CONVECTION, HEATSINK, HEATSINK, HEATSINK, HEATSINK, HEATSINK };
    Mesh mesh = Mesh::buildCubeMesh(size, n, bc);
    FEM_Simulator sim(10.0f, 4.3f, 0.0062f, 0.001f);  // mua, VHC, TC, HTC
    sim.silentMode = true;
    sim.setMesh(mesh);
    Eigen::VectorXf T = Eigen::VectorXf::Constant(n[0] * n[1] * n[2], 20.0f);
    sim.setTemp(T);  // the HEATSINK faces hold these temperatures
    sim.setAmbientTemp(20.0f);
    sim.setHeatFlux(0.0f);
    sim.setAlpha(0.5f);
    sim.setDt(dt);
    std::array<float, 6> pose = { 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f };
    sim.setFluenceRate(pose, 1.0f, 0.1f, 0.0f);  // wavelength 0: the waist 0.1 cm at every depth
    std::vector<std::array<float, 3>> sensors = {
        {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.05f}, {0.0f, 0.0f, 0.1f} };
    sim.setSensorLocations(sensors);
    sim.initializeModel();
    auto t1 = clock::now();
    std::clock_t c1 = std::clock();
    int steps = (int)std::lround(duration / dt);
    for (int s = 0; s < steps; s++)
        sim.singleStep();  // multiStep keeps only the last step
    auto t2 = clock::now();
    std::clock_t c2 = std::clock();
    std::vector<float> temps = sim.sensorTemps();
    std::printf("{\"setup_s\": %.6f, \"steps_s\": %.6f, \"cpu_setup_s\": %.6f, \"cpu_steps_s\": %.6f, "
                "\"steps\": %d, \"threads\": %d, \"temps\": [%.6f, %.6f, %.6f]}\n",
                std::chrono::duration<double>(t1 - t0).count(),
                std::chrono::duration<double>(t2 - t1).count(),
                double(c1 - c0) / CLOCKS_PER_SEC, double(c2 - c1) / CLOCKS_PER_SEC,
                steps, Eigen::nbThreads(), temps[0], temps[1], temps[2]);
    return 0;
}
"""

DRIVER_CMAKE = """cmake_minimum_required(VERSION 3.29)
project(PeerHeatDriver LANGUAGES CXX)
set(BUILD_TESTING OFF CACHE BOOL "" FORCE)
set(BUILD_FEM_MEX OFF CACHE BOOL "" FORCE)
add_subdirectory("{src}" peer)
add_executable(peer_heat peer_heat.cpp)
target_link_libraries(peer_heat PRIVATE HeatSimulation::Static)
"""


def modal_reference(z, t: float = STEPS * DT, n_xy: int = 40, n_z: int = 1000) -> np.ndarray:
    r"""Temperature rise (K) at r = 0 and depths ``z`` (cm) after ``t`` s, by modal series.

    With the rise :math:`u` held at 0 on x, y = +-1/2 and z = L, and
    :math:`k\,\partial_z u = h u` at z = 0, the eigenfunctions are
    :math:`\cos(a_m x)\cos(a_n y)\sin(b_p (L - z))` with :math:`a_m = (2m-1)\pi` (the
    even ones: the source is symmetric) and :math:`k b_p \cos(b_p L) + h \sin(b_p L) = 0`,
    one root in each :math:`((p - 1/2)\pi/L, p\pi/L)`. With the source's coefficients
    :math:`q_{mnp}` (Gaussian: :math:`2\sqrt{\pi/2}\,w\,e^{-a^2 w^2/8}` per axis, its tails
    beyond the block below 1e-21; exponential: in closed form),

    .. math::

        u = \sum_{mnp} \frac{q_{mnp}}{k \lambda_{mnp}}
            \left(1 - e^{-k \lambda_{mnp} t / c}\right) \phi_{mnp},
        \qquad \lambda_{mnp} = a_m^2 + a_n^2 + b_p^2

    (Carslaw and Jaeger, Conduction of Heat in Solids, 2nd ed., sections 3.9 and 6.4).
    The defaults are converged to 1e-6 K (40 x 40 x 1000 modes against 60 x 60 x 6000).
    """
    from scipy.optimize import brentq

    L = SIZE[2]
    a = (2 * np.arange(1, n_xy + 1) - 1) * np.pi
    qa = 2 * np.sqrt(np.pi / 2) * W * np.exp(-(a**2) * W**2 / 8)  # int g cos / int cos^2

    def f(b):
        return TC * b * np.cos(b * L) + HTC * np.sin(b * L)

    eps = 1e-12
    b = np.array([brentq(f, (p - 0.5) * np.pi / L + eps, p * np.pi / L - eps)
                  for p in range(1, n_z + 1)])
    norm = L / 2 - np.sin(2 * b * L) / (4 * b)
    qb = (MUA * np.sin(b * L) - b * np.cos(b * L) + b * np.exp(-MUA * L)) / (MUA**2 + b**2) / norm
    lam = a[:, None, None] ** 2 + a[None, :, None] ** 2 + b[None, None, :] ** 2
    amp = (P * MUA * 2 / (np.pi * W**2) * qa[:, None, None] * qa[None, :, None] * qb
           / (TC * lam) * -np.expm1(-TC * lam * t / VHC))
    return np.einsum("mnp,pz->z", amp, np.sin(np.outer(b, L - np.asarray(z, float))))


def _gauss(x):
    return np.exp(-2 * x**2 / W**2)


def _decay(z):
    return np.exp(-MUA * z)


def hat_integrals(nodes: np.ndarray, f, order: int = 10) -> np.ndarray:
    """``int f(x) hat_i(x) dx`` for each node of a 1-D grid; Gauss-Legendre per interval."""
    s, w = np.polynomial.legendre.leggauss(order)
    lo, hi = nodes[:-1, None], nodes[1:, None]
    x = 0.5 * (lo + hi) + 0.5 * (hi - lo) * s  # (intervals, order)
    fw = 0.5 * (hi - lo) * w * f(x)
    t = (x - lo) / (hi - lo)
    g = np.zeros(nodes.size)
    g[:-1] += (fw * (1 - t)).sum(axis=1)
    g[1:] += (fw * t).sum(axis=1)
    return g


def ours(config: str, voxels: tuple[int, int, int]) -> dict:
    """One run of ours: set-up, 100 steps, the rises at DEPTHS, and the times."""
    import fem

    operator, mass, load = CONFIGS[config][0]
    w0, c0 = time.perf_counter(), time.process_time()
    mesh = fem.box_mesh(*voxels, *SIZE)
    fixed = fem.FaceBC("fixed", temperature=T0)
    boundary = fem.HeatBoundary({"z-": fem.FaceBC("convective", temperature=T0, h=HTC),
                                 "z+": fixed, "x-": fixed, "x+": fixed, "y-": fixed, "y+": fixed})
    stepper = fem.HeatStepper(mesh, VHC, TC, DT, theta=0.5, boundary=boundary,
                              operator=operator, mass=mass)
    amplitude = P * MUA * 2 / (np.pi * W**2)
    if load == "hat":
        axes = [np.linspace(lo, lo + L, n + 1)
                for lo, L, n in zip((-SIZE[0] / 2, -SIZE[1] / 2, 0.0), SIZE, voxels, strict=True)]
        f = amplitude * np.einsum("i,j,k->ijk", hat_integrals(axes[0], _gauss),
                                  hat_integrals(axes[1], _gauss),
                                  hat_integrals(axes[2], _decay)).ravel()
    else:
        x, y, z = mesh.p
        f = fem.mass_matrix(mesh, 1.0, lumped=False) @ (amplitude * _gauss(x) * _gauss(y) * _decay(z))
    probes = fem.probe_matrix(mesh, np.array([[0.0, 0.0, d] for d in DEPTHS]).T)
    T = np.full(mesh.p.shape[1], T0)
    w1, c1 = time.perf_counter(), time.process_time()
    for _ in range(STEPS):
        T = stepper.step(T, f)
    w2, c2 = time.perf_counter(), time.process_time()
    return {"setup_s": w1 - w0, "steps_s": w2 - w1, "cpu_setup_s": c1 - c0, "cpu_steps_s": c2 - c1,
            "rise": (probes @ T - T0).tolist(), "solver": stepper.method}


def peer(exe: str, voxels: tuple[int, int, int]) -> dict:
    """One run of the peer's driver."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    out = subprocess.run([exe, *(str(n + 1) for n in voxels), str(DT), str(STEPS * DT), "1"],
                         env=env, check=True, capture_output=True, text=True).stdout
    r = json.loads(out.strip().splitlines()[-1])
    if r["threads"] != 1 or r["steps"] != STEPS:
        raise RuntimeError(f"the peer ran {r['steps']} steps on {r['threads']} threads")
    return {k: r[k] for k in TIMES} | {"rise": [t - T0 for t in r["temps"]],
                                       "solver": "CG (float)"}


def build_peer(src: Path, dest: Path, cmake: str) -> Path:
    """Write the driver next to a checkout of the peer and build it; returns the program."""
    dest.mkdir(parents=True, exist_ok=True)
    (dest / "peer_heat.cpp").write_text(DRIVER_CPP.lstrip())
    (dest / "CMakeLists.txt").write_text(DRIVER_CMAKE.format(src=src.resolve().as_posix()))
    build = dest / "build"
    subprocess.run([cmake, "-S", str(dest), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release",
                    "-DBUILD_TESTING=OFF", "-DBUILD_FEM_MEX=OFF"], check=True)
    subprocess.run([cmake, "--build", str(build), "--target", "peer_heat", "-j2"], check=True)
    return build / "peer_heat"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--peer", default=os.environ.get("PEER_HEAT"),
                   help="the peer's driver (default: $PEER_HEAT)")
    p.add_argument("--build-peer", type=Path, metavar="SRC",
                   help="build the driver first, against the peer's checkout SRC")
    p.add_argument("--peer-dir", type=Path, default=Path("/tmp/peer_heat_driver"),
                   help="where --build-peer writes and builds the driver")
    p.add_argument("--cmake", default=shutil.which("cmake") or "cmake", help="CMake >= 3.29")
    p.add_argument("--repeat", type=int, default=3, help="interleaved rounds (best time)")
    p.add_argument("--fine", action="store_true",
                   help="also the fine meshes of the Q1 exact-load and the default rows")
    p.add_argument("--json", help="write the rows here")
    a = p.parse_args(argv)
    if a.build_peer is not None:
        a.peer = str(build_peer(a.build_peer, a.peer_dir, a.cmake))
    if a.peer is not None and not os.access(a.peer, os.X_OK):
        p.error(f"--peer {a.peer!r} is not an executable")

    ref = modal_reference(DEPTHS)
    print(f"reference (modal series): rises {', '.join(f'{r:.4f}' for r in ref)} K at z = "
          f"{', '.join(map(str, DEPTHS))} cm; issue 47: {', '.join(map(str, ISSUE_RISE))} K")

    rows = [("peer", (40, 40, 20))] if a.peer else []
    if not a.peer:
        print("the peer's row is skipped: no driver (give --peer, PEER_HEAT or --build-peer)")
    rows += ROWS
    for config in CONFIGS:  # numba compiles (or loads its cache) outside the timings
        ours(config, (4, 4, 2))

    def run(name, voxels):
        return peer(a.peer, voxels) if name == "peer" else ours(name, voxels)

    best: dict = {}
    fine = [r for r in FINE if a.peer or r[0] != "peer"] if a.fine else []
    schedule = [rows] * a.repeat + [fine]
    for round_rows in schedule:
        for name, voxels in round_rows:
            r = run(name, voxels)
            b = best.setdefault((name, voxels), r)
            for k in TIMES:
                b[k] = min(b[k], r[k])

    label = {k: v[1] for k, v in CONFIGS.items()} | {"peer": "comet-lab/fem-heat-simulator (Q1)"}
    print("| method | nodes | steps, s | set-up, s | CPU steps, s | CPU set-up, s | "
          "error % at z = 0 / 0.05 / 0.1 cm |")
    print("|---|---|---|---|---|---|---|")
    table = []
    for (name, voxels), r in best.items():
        err = 100 * (np.asarray(r["rise"]) - ref) / ref
        nodes = " x ".join(str(n + 1) for n in voxels)
        print(f"| {label[name]} | {nodes} | "
              + " | ".join(f"{r[k]:.3f}" for k in TIMES)
              + f" | {' / '.join(f'{e:+.2f}' for e in err)} |")
        table.append({"method": label[name], "config": name, "nodes": [n + 1 for n in voxels],
                      **{k: r[k] for k in (*TIMES, "rise", "solver")},
                      "error_percent": err.tolist()})

    if a.peer:
        pr = table[0]
        print(f"target: every error within {TARGET} % (the peer at 41 x 41 x 21: "
              f"{max(abs(e) for e in pr['error_percent']):.2f} % at worst) in at most half of "
              f"the peer's time (steps + set-up, wall and CPU)")
        for r in table[1:]:
            if r["config"] == "peer" or max(abs(e) for e in r["error_percent"]) > TARGET:
                continue
            wall = (r["steps_s"] + r["setup_s"]) / (pr["steps_s"] + pr["setup_s"])
            cpu = ((r["cpu_steps_s"] + r["cpu_setup_s"])
                   / (pr["cpu_steps_s"] + pr["cpu_setup_s"]))
            print(f"  {r['method']}, {' x '.join(map(str, r['nodes']))}: of the peer's time "
                  f"{wall:.2f} wall ({r['steps_s'] / pr['steps_s']:.2f} of its steps), {cpu:.2f} "
                  f"CPU ({r['cpu_steps_s'] / pr['cpu_steps_s']:.2f}): "
                  f"{'met' if max(wall, cpu) <= 0.5 else 'not met'}")
    if a.json:
        Path(a.json).write_text(json.dumps({"reference_rise": ref.tolist(), "rows": table}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
