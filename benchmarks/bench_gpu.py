"""GPU Monte Carlo (``MC.use_gpu``): agreement with the CPU kernel and speed, on a real GPU.

    python benchmarks/bench_gpu.py [--photons N] [--splits K] [--out DIR]

Two blocks of 100 x 100 x 50 voxels over 0.5 x 0.5 x 0.25 cm, lit by the paper's top-hat
beam (radius 1 mm):

* ``paper``: the paper's standard tissue (mua 1, mus 100 cm^-1, g 0.9, n 1.3), matched
  interfaces (the kernel's fast path);
* ``layers``: a 100 um skin-like top layer (mua 5, mus 200, g 0.8, n 1.4) over the same
  tissue under air, mismatched interfaces (Fresnel, refraction, the voxel walk).

Each run is split into ``K`` independent runs (seeds 1..K on the GPU, 101..100+K on the CPU
with all of its threads), so that every compared quantity has a standard error from the
scatter of its own runs, not from a formula: the absorbed, top and bottom fractions, and the
absorbed power summed over each of the 50 depth layers and over 10 radial rings. For each
the z-score of the difference GPU - CPU is reported; ``|z| < 4`` everywhere, and a
chi-square over the profile near its degrees of freedom, mean the GPU samples the CPU's
distribution. The energy balance is exact (fixed point) on both.

Speed: photons per second of the kernel (``MC.photons_per_second``), each device's first run
(the JIT compile) left out. A JSON and a Markdown report go to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from pathlib import Path

import numba
import numpy as np

from enkf.paper import paper_model
from mcmatlab_py import Medium

GRID = (100, 100, 50)


def build(case: str, gpu: bool, n_photons: int, seed: int):
    model = paper_model(GRID, n_photons=n_photons, seed=seed, progress=False)
    if case == "layers":
        tissue = model.G.media[0]
        model.G.media = [Medium("epidermis-like", mua=5.0, mus=200.0, g=0.8, n=1.4), tissue]
        top = model.G.z[0] - model.G.dz / 2 + 0.01  # 100 um below the surface
        model.G.geom_func = lambda X, Y, Z: np.where(Z < top, 0, 1)
        model.MC.matched_interfaces = False
    model.MC.use_gpu = gpu
    return model


def observables(model) -> dict:
    """Fractions and the absorbed power's depth and radial profiles (fractions of the launched
    power), of one run."""
    MC, G = model.MC, model.G
    dV = G.dx * G.dy * G.dz
    A = MC.NA * dV  # absorbed fraction per voxel
    X, Y = np.meshgrid(G.x, G.y, indexing="ij")
    ring = np.minimum((np.hypot(X, Y) / 0.025).astype(int), 9)  # rings of 250 um, last open
    radial = np.bincount(ring.ravel(), weights=A.sum(axis=2).ravel(), minlength=10)
    return {"absorbed": MC.absorbed_fraction, "top": MC.escaped["top"],
            "bottom": MC.escaped["bottom"], "balance": MC.energy_balance,
            "depth": A.sum(axis=(0, 1)), "radial": radial,
            "rate": MC.photons_per_second, "seconds": MC.simulation_time}


def compare(gpu_runs: list[dict], cpu_runs: list[dict]) -> dict:
    out = {}
    for key in ("absorbed", "top", "bottom", "depth", "radial"):
        g = np.array([r[key] for r in gpu_runs], dtype=float)
        c = np.array([r[key] for r in cpu_runs], dtype=float)
        se = np.sqrt(g.var(axis=0, ddof=1) / len(g) + c.var(axis=0, ddof=1) / len(c))
        diff = g.mean(axis=0) - c.mean(axis=0)
        ok = se > 0
        z = np.where(ok, diff / np.where(ok, se, 1.0), 0.0)
        out[key] = {"gpu": g.mean(axis=0).tolist(), "cpu": c.mean(axis=0).tolist(),
                    "z": np.atleast_1d(z).tolist(), "max_abs_z": float(np.max(np.abs(z))),
                    "chi2": float(np.sum(z[ok] ** 2)), "dof": int(np.sum(ok))}
    return out


def run_case(case: str, n_photons: int, splits: int) -> dict:
    per = n_photons // splits
    for gpu in (True, False):  # compile (or load) each kernel outside the timings
        build(case, gpu, min(2000, per), 999).run_monte_carlo()
    gpu_runs = [observables(build(case, True, per, 1 + k).run_monte_carlo()) for k in range(splits)]
    cpu_runs = [observables(build(case, False, per, 101 + k).run_monte_carlo())
                for k in range(splits)]
    res = compare(gpu_runs, cpu_runs)
    res["balance"] = {"gpu": [r["balance"] for r in gpu_runs], "cpu": [r["balance"] for r in cpu_runs]}
    res["rate"] = {"gpu": float(np.median([r["rate"] for r in gpu_runs])),
                   "cpu": float(np.median([r["rate"] for r in cpu_runs]))}
    res["photons"] = per * splits
    return res


def device_name() -> str:
    from numba import cuda

    if numba.config.ENABLE_CUDASIM:
        return "numba's CUDA simulator"
    d = cuda.get_current_device()
    name = d.name.decode() if isinstance(d.name, bytes) else str(d.name)
    return f"{name} (compute capability {d.compute_capability[0]}.{d.compute_capability[1]})"


def report(results: dict, meta: dict) -> str:
    lines = ["# GPU Monte Carlo against the CPU kernel", "",
             f"`python benchmarks/bench_gpu.py --photons {meta['photons']} --splits "
             f"{meta['splits']} --grid {meta['grid']}` on {meta['device']}; CPU: {meta['cpu']} with "
             f"{meta['threads']} numba threads.", "",
             "| block | photons each | quantity | GPU | CPU | max abs z | chi2 / dof |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for case, r in results.items():
        for key in ("absorbed", "top", "bottom", "depth", "radial"):
            q = r[key]
            scalar = key in ("absorbed", "top", "bottom")
            gpu = f"{q['gpu']:.5f}" if scalar else f"{len(q['gpu'])} bins"
            cpu = f"{q['cpu']:.5f}" if scalar else ""
            lines.append(f"| {case} | {r['photons']} | {key} | {gpu} | {cpu} | "
                         f"{q['max_abs_z']:.2f} | {q['chi2']:.1f} / {q['dof']} |")
    lines += ["", "| block | GPU photons/s | CPU photons/s | GPU / CPU | energy balance (GPU, CPU) |",
              "| --- | --- | --- | --- | --- |"]
    for case, r in results.items():
        bal = (f"{min(r['balance']['gpu']):.15f}-{max(r['balance']['gpu']):.15f}, "
               f"{min(r['balance']['cpu']):.15f}-{max(r['balance']['cpu']):.15f}")
        lines.append(f"| {case} | {r['rate']['gpu']:.3e} | {r['rate']['cpu']:.3e} | "
                     f"{r['rate']['gpu'] / r['rate']['cpu']:.1f} | {bal} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--photons", type=int, default=32_000_000, help="photons per device and block")
    p.add_argument("--splits", type=int, default=16, help="independent runs the photons are split in")
    p.add_argument("--cases", default="paper,layers")
    p.add_argument("--grid", default="100,100,50", help="voxels nx,ny,nz (small ones to try "
                   "the script on numba's CUDA simulator)")
    p.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    a = p.parse_args(argv)
    if a.splits < 2 or a.photons < a.splits:
        p.error(f"--splits must be >= 2 and --photons >= --splits (got {a.splits}, {a.photons})")
    global GRID
    GRID = tuple(int(v) for v in a.grid.split(","))
    from mcmatlab_py.monte_carlo import gpu_available

    if not gpu_available():
        print("no CUDA GPU (numba.cuda.is_available() is False); nothing to compare")
        return 2
    meta = {"photons": a.photons, "grid": a.grid, "splits": a.splits, "device": device_name(),
            "cpu": platform.processor() or platform.machine(), "threads": numba.get_num_threads(),
            "cpu_count": os.cpu_count()}
    results = {}
    t0 = time.perf_counter()
    for case in a.cases.split(","):
        results[case] = run_case(case, a.photons, a.splits)
        r = results[case]
        print(f"{case}: GPU {r['rate']['gpu']:.3e} photons/s, CPU {r['rate']['cpu']:.3e}; "
              + ", ".join(f"{k} max|z| {r[k]['max_abs_z']:.2f}"
                          for k in ("absorbed", "top", "bottom", "depth", "radial"))
              + f" ({time.perf_counter() - t0:.0f} s)", flush=True)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "gpu_vs_cpu.json").write_text(json.dumps({"meta": meta, "results": results}, indent=1))
    (a.out / "gpu_vs_cpu.md").write_text(report(results, meta))
    print(report(results, meta))
    worst = max(r[k]["max_abs_z"] for r in results.values()
                for k in ("absorbed", "top", "bottom", "depth", "radial"))
    return 0 if worst < 4.0 and math.isfinite(worst) else 1


if __name__ == "__main__":
    raise SystemExit(main())
