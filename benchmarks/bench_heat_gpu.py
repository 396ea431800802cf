"""GPU heat steps (:mod:`fem.gpu`, for ``HS.use_gpu``) against the CPU's, on a real GPU.

    python benchmarks/bench_heat_gpu.py [--grid 60,60,59] [--steps 100] [--dt 0.05] [--out DIR]

One heat problem, stepped twice from the same start: 60 x 60 x 59 voxels over
0.6 x 0.6 x 0.59 cm (the voxel-corner mesh has 61 x 61 x 60 = 223,260 nodes), the media of
``benchmarks/bench_fem.py``'s heterogeneous case (a 0.02 cm epidermis-like layer over dermis,
a vessel along y), a convective top, backward Euler, a Gaussian beam's heat load every step.

* CPU: :class:`fem.HeatStepper` as the heat front end makes it (``method="auto"``: on this
  mesh, batched PCG warm-started from the last step, preconditioned by the fast
  diagonalization of the averaged operator), with all of numba's threads;
* GPU: the same stepper with its solves on the GPU (``method="gpu"``, as ``HS.use_gpu``
  asks for it: Jacobi PCG on the device, the same relative tolerance).

Printed: the setup, the first step (the GPU's includes the kernels' JIT compile), the
median of the other steps' wall times (right-hand side, transfers and solve: what the front
end would see), the mean iterations per step, the CPU / GPU ratio of the step times, and
the largest difference of the final temperatures (the PCG tolerance's size). With ``--out``
a JSON report. Without a CUDA GPU it prints "no CUDA GPU: skipped" and exits 0; under
numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``) it runs, slowly: give a small ``--grid``.

Not yet run on a GPU: none was available when the script was written.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numba
import numpy as np

MEDIA = {"vhc": (3.7, 3.4, 3.617), "tc": (0.0052, 0.0037, 0.0052)}  # dermis, epidermis, blood
TOP = {"temperature": 20.0, "h": 0.001}  # convective top: ambient deg C, W cm^-2 K^-1


def problem(grid_shape, dt: float, method: str = "auto"):
    """The stepper (``method``: its solver), the nodal load (W) and the start temperatures
    (deg C)."""
    from fem import BoxGrid, FaceBC, HeatBoundary, HeatStepper, element_voxel_index, voxel_load_matrix

    nx, ny, nz = grid_shape
    grid = BoxGrid(nx, ny, nz, 0.01 * nx, 0.01 * ny, 0.01 * nz)
    mesh = grid.mesh()
    media = np.zeros(grid.shape, dtype=int)
    media[:, :, grid.z < 0.02] = 1
    xx, zz = np.meshgrid(grid.x, grid.z, indexing="ij")
    media[((xx**2 + (zz - 0.1) ** 2) < 0.03**2)[:, None, :].repeat(grid.ny, 1)] = 2
    vox = media.ravel()[element_voxel_index(mesh, grid)]
    stepper = HeatStepper(mesh, np.array(MEDIA["vhc"])[vox], np.array(MEDIA["tc"])[vox], dt,
                          boundary=HeatBoundary({"z-": FaceBC("convective", **TOP)}),
                          method=method)
    r2 = grid.x[:, None, None] ** 2 + grid.y[None, :, None] ** 2
    S = 100.0 * np.exp(-2 * r2 / 0.05**2) * np.exp(-10.0 * grid.z[None, None, :])  # W/cm^3
    load = voxel_load_matrix(mesh, grid) @ S.ravel()
    return stepper, load, np.full(mesh.p.shape[1], 37.0)


def timed_run(stepper, load, T0, n_steps: int) -> dict:
    T = stepper.step(T0, load)
    times, iters = [], []
    for _ in range(n_steps - 1):
        t0 = time.perf_counter()
        T = stepper.step(T, load)
        times.append(time.perf_counter() - t0)
        iters.append(getattr(stepper._solver, "last_iterations", 0))
    return {"method": stepper.method, "step_s_median": float(np.median(times)),
            "steps_s": float(np.sum(times)), "iterations_mean": float(np.mean(iters)),
            "T": T}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--grid", default="60,60,59", help="voxels nx,ny,nz (0.01 cm each)")
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--dt", type=float, default=0.05, help="s")
    p.add_argument("--out", type=Path, default=None, help="write heat_gpu_vs_cpu.json there")
    a = p.parse_args(argv)
    from fem.gpu import device_name, gpu_available

    if not gpu_available():
        print("no CUDA GPU: skipped (numba-cuda or a GPU missing: "
              "numba.cuda.is_available() is False)")
        return 0
    if a.steps < 2:
        p.error(f"--steps must be >= 2, got {a.steps}")
    shape = tuple(int(v) for v in a.grid.split(","))
    res = {"grid": shape, "steps": a.steps, "dt": a.dt, "device": device_name(),
           "cpu": platform.processor() or platform.machine(),
           "threads": numba.get_num_threads(), "cpu_count": os.cpu_count()}
    for side in ("cpu", "gpu"):
        t0 = time.perf_counter()
        stepper, load, T0 = problem(shape, a.dt, "gpu" if side == "gpu" else "auto")
        setup = time.perf_counter() - t0
        t0 = time.perf_counter()
        run = timed_run(stepper, load, T0, a.steps)
        res[side] = {"setup_s": setup, "total_s": time.perf_counter() - t0, **run}
        res["nodes"] = int(stepper.npoints)
        print(f"{side}: {run['method']}, setup {setup:.2f} s, step {1e3 * run['step_s_median']:.2f}"
              f" ms (median), {run['iterations_mean']:.1f} iterations per step", flush=True)
    T_cpu, T_gpu = res["cpu"].pop("T"), res["gpu"].pop("T")
    res["max_abs_diff_K"] = float(np.abs(T_gpu - T_cpu).max())
    res["T_max"] = float(T_cpu.max())
    res["ratio_cpu_over_gpu"] = res["cpu"]["step_s_median"] / res["gpu"]["step_s_median"]
    print(f"{res['nodes']} nodes, {a.steps} steps on {res['device']}: CPU / GPU step time "
          f"{res['ratio_cpu_over_gpu']:.2f}; max |T_gpu - T_cpu| {res['max_abs_diff_K']:.2e} K "
          f"(T max {res['T_max']:.2f} deg C)")
    if a.out is not None:
        a.out.mkdir(parents=True, exist_ok=True)
        (a.out / "heat_gpu_vs_cpu.json").write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
