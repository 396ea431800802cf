"""Speed and memory of the FEM heat core (prints numbers; no assertions).

Targets (docs/fem.md):

(a) coarse filter model: box_mesh 20x20x10 voxels over 0.5 x 0.5 x 0.25 cm
    (4,851 nodes), one implicit step of 50 members with per-member VHC/TC
    scales and per-member loads: <= 5 ms on 2 cores;
(b) fine model: 100x100x50 voxels (520,251 nodes), assembly plus 150 implicit
    steps of dt = 0.1 s: <= 60 s and <= 4 GiB.

Usage::

    python benchmarks/bench_fem.py            # all cases, each in its own process
    python benchmarks/bench_fem.py --case coarse
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

LX, LY, LZ = 0.5, 0.5, 0.25  # cm
VHC, TC = 3.7, 0.0052  # J cm^-3 K^-1, W cm^-1 K^-1
TOP = dict(temperature=20.0, h=0.001)  # convective top: ambient deg C, W cm^-2 K^-1


def _beam(grid, S0=100.0, w=0.05, mua=10.0):
    r2 = grid.x[:, None, None] ** 2 + grid.y[None, :, None] ** 2
    return S0 * np.exp(-2 * r2 / w**2) * np.exp(-mua * grid.z[None, None, :])


def _boundary(kind):
    from fem import FaceBC, HeatBoundary

    if kind == "insulating":
        return HeatBoundary()
    return HeatBoundary({"z-": FaceBC("convective", **TOP)})


def coarse(boundary="convective-top", N=50, reps=300, seed=0):
    from fem import BoxGrid, HeatStepper, voxel_load_matrix

    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    grid = BoxGrid(20, 20, 10, LX, LY, LZ)
    mesh = grid.mesh()
    stepper = HeatStepper(mesh, VHC, TC, 0.1, boundary=_boundary(boundary))
    L = voxel_load_matrix(mesh, grid)
    setup = time.perf_counter() - t0
    S = _beam(grid)[None] * rng.uniform(0.5, 1.5, (N, 1, 1, 1))
    loads = S.reshape(N, -1) @ L.T  # per-member loads (W per node)
    vs, ts = rng.uniform(0.8, 1.2, N), rng.uniform(0.8, 1.2, N)
    T = np.full((N, mesh.p.shape[1]), 37.0)
    t0 = time.perf_counter()
    T = stepper.step(T, loads, vs, ts)
    first = time.perf_counter() - t0
    times, cpu = np.empty(reps), np.empty(reps)
    for r in range(reps):
        t0, c0 = time.perf_counter(), time.process_time()
        T = stepper.step(T, loads, vs, ts)
        times[r], cpu[r] = time.perf_counter() - t0, time.process_time() - c0
    return dict(case=f"coarse N={N} ({boundary})", method=stepper.method,
                nodes=mesh.p.shape[1], setup_s=setup, first_step_s=first,
                step_ms_median=1e3 * np.median(times), step_ms_min=1e3 * times.min(),
                step_ms_p90=1e3 * np.percentile(times, 90),
                step_cpu_ms_median=1e3 * np.median(cpu))


def fine(heterogeneous=False, n_steps=150, dt=0.1):
    from fem import BoxGrid, HeatStepper, element_voxel_index, voxel_load_matrix

    t0 = time.perf_counter()
    grid = BoxGrid(100, 100, 50, LX, LY, LZ)
    mesh = grid.mesh()
    if heterogeneous:
        # epidermis (top 0.025 cm), dermis, a blood vessel along y
        media = np.zeros(grid.shape, dtype=int)
        media[:, :, :5] = 1
        xx, zz = np.meshgrid(grid.x, grid.z, indexing="ij")
        media[((xx**2 + (zz - 0.1) ** 2) < 0.03**2)[:, None, :].repeat(grid.ny, 1)] = 2
        vox = media.ravel()[element_voxel_index(mesh, grid)]
        vhc = np.array([3.7, 3.4, 3.617])[vox]
        tc = np.array([0.0052, 0.0037, 0.0052])[vox]
    else:
        vhc, tc = VHC, TC
    stepper = HeatStepper(mesh, vhc, tc, dt, boundary=_boundary("convective-top"))
    load = voxel_load_matrix(mesh, grid) @ _beam(grid).ravel()
    setup = time.perf_counter() - t0
    T = np.full(mesh.p.shape[1], 37.0)
    t0, c0 = time.perf_counter(), time.process_time()
    iters = []
    for _ in range(n_steps):
        T = stepper.step(T, load)
        iters.append(getattr(stepper._solver, "last_iterations", 0))
    steps, steps_cpu = time.perf_counter() - t0, time.process_time() - c0
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # KiB -> GiB
    return dict(case=f"fine {'heterogeneous' if heterogeneous else 'homogeneous'}",
                method=stepper.method, nodes=mesh.p.shape[1], setup_s=setup,
                steps_s=steps, steps_cpu_s=steps_cpu, total_s=setup + steps, peak_rss_GiB=rss,
                pcg_iterations_mean=float(np.mean(iters)), T_max=float(T.max()))


CASES = {
    "coarse": lambda: coarse("convective-top"),
    "coarse-insulating": lambda: coarse("insulating"),
    "fine-homogeneous": lambda: fine(False),
    "fine-heterogeneous": lambda: fine(True),
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=[*CASES, "all"], default="all")
    ap.add_argument("--json", action="store_true", help="print one JSON line (internal)")
    args = ap.parse_args()
    if args.case != "all":
        res = CASES[args.case]()
        print(json.dumps(res) if args.json else res)
        return
    print(f"# {os.cpu_count()} CPUs, load average at start {os.getloadavg()}")
    for name in CASES:
        out = subprocess.run([sys.executable, __file__, "--case", name, "--json"],
                             capture_output=True, text=True, check=True)
        res = json.loads(out.stdout.strip().splitlines()[-1])
        print(" | ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                         for k, v in res.items()))
    print(f"# load average at end {os.getloadavg()}")


if __name__ == "__main__":
    main()
