"""Absorption emulator: evaluation for 50 members, and the table build.

    python benchmarks/bench_emulator.py            # evaluation (builds/loads the cached table)
    python benchmarks/bench_emulator.py --rebuild  # also time a build from scratch (minutes)
    python benchmarks/bench_emulator.py --builds [--photons 250000]
        # the direct ("table") and perturbation ("white") builds from scratch, side by side
        # in this process, and their ratio
    python benchmarks/bench_emulator.py --cold [--repeat 2]
        # `tissue-enkf identify examples/own_data.toml` from an empty cache, against a plain
        # one-thread Monte Carlo kernel pushing 5 million photons through the same block
        # (benchmarks/plain_kernel.py), run before and after each identify

The filter's emulator: Monte Carlo on the paper's 100 x 100 x 50 voxels, nodal loads on the
20 x 20 x 10 mesh; and the plain voxel emulator on 20 x 20 x 10.
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from enkf.paper import emulator_for, paper_model
from mcmatlab_py.emulator import AbsorptionEmulator, EmulatorSpec, table_point, table_row


def time_eval(emu, repeat=2000):
    rng = np.random.default_rng(0)
    mua = rng.uniform(0.5, 2.0, 50)
    mus = rng.uniform(50, 200, 50)
    emu.unique(mua, mus)  # compile / warm up
    best = []
    for f in (emu.unique, emu):
        t = []
        for _ in range(repeat // 10):
            t0 = time.perf_counter()
            for _ in range(10):
                f(mua, mus)
            t.append((time.perf_counter() - t0) / 10)
        best.append(np.median(t))
    return best


def time_builds(n_photons: int) -> None:
    """Both build methods from scratch (temporary caches), alternating, in this process."""
    from mcmatlab_py.emulator.white import white_column

    # compile (or load) both kernels outside the timings
    tiny = EmulatorSpec.from_model(paper_model((4, 4, 2), progress=False), n_photons=100)
    table_point(tiny, (0, 0))
    white_column(tiny, 0)
    for label, spec in [
        ("voxel NA, 20x20x10", EmulatorSpec.from_model(paper_model((20, 20, 10), progress=False),
                                                      n_photons=n_photons)),
        ("nodal loads, MC 100x100x50 -> mesh 20x20x10", EmulatorSpec.from_model(
            paper_model((100, 100, 50), progress=False), n_photons=n_photons,
            mesh_divisions=(20, 20, 10))),
    ]:
        if spec.mesh_divisions is not None:
            # the voxel -> node operator, built once per process, outside the timings
            table_row(spec, np.zeros((spec.nx, spec.ny, spec.nz)))
        seconds = {}
        for method in ("table", "white"):
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                AbsorptionEmulator.build(spec, cache_dir=tmp, progress=False, method=method)
                seconds[method] = time.perf_counter() - t0
        print(f"{label}, {spec.n_mua} x {spec.n_mus} table, {n_photons} photons at mus = 100: "
              f"table {seconds['table']:.1f} s ({spec.n_mua * spec.n_mus} runs), white "
              f"{seconds['white']:.1f} s ({spec.n_mus} runs): "
              f"{seconds['table'] / seconds['white']:.2f}x", flush=True)


def plain_seconds(n_photons: int = 5_000_000, seed: int = 1) -> float:
    """Seconds of the plain one-thread kernel for ``n_photons`` on examples/own_data.toml's
    block (the paper's tissue, 100 x 100 x 50, top hat of radius 1 mm): its CPU time, as
    ``benchmarks/bench_mc.py`` measures it."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from bench_mc import plain_cpu_rate

    plain_cpu_rate((100, 100, 50), 100)  # compile / load the cache
    return n_photons / plain_cpu_rate((100, 100, 50), n_photons, seed)


def time_cold(repeat: int) -> None:
    """The cold identify against the plain kernel, alternating, in fresh processes; and the
    table points its on-demand emulator built against the whole table built here."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).parents[1]
    exe = Path(sys.executable).with_name("tissue-enkf")
    cmd = [str(exe), "identify", str(root / "examples" / "own_data.toml"), "--data",
           str(root / "examples" / "own_data.csv"), "--force"]
    plain = [plain_seconds()]
    ratios, build_ratios = [], []
    for k in range(repeat):
        with tempfile.TemporaryDirectory() as tmp:
            env = dict(os.environ, TISSUE_ENKF_CACHE=str(Path(tmp) / "cache"))
            t0 = time.perf_counter()
            subprocess.run(cmd + ["--out", str(Path(tmp) / "out")], env=env, check=True,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            cold = time.perf_counter() - t0
            npz = next((Path(tmp) / "cache").glob("emulator-*.npz"))
            method = "white" if npz.name.startswith("emulator-white-") else "table"
            with np.load(npz) as f:
                have, built = f["have"], float(f["build_seconds"])
        plain.append(plain_seconds(seed=k + 2))
        ratio = cold / (0.5 * (plain[-2] + plain[-1]))
        ratios.append(ratio)
        print(f"run {k + 1}: cold identify {cold:.1f} s (empty TISSUE_ENKF_CACHE, numba's cache "
              f"as it is), plain kernel 5e6 photons {plain[-2]:.1f} s before, {plain[-1]:.1f} s "
              f"after: {ratio:.2f}x", flush=True)
        # the whole direct table (the build before on-demand points and the white build),
        # and the same points by direct runs, in this process (the load operator outside)
        with tempfile.TemporaryDirectory() as tmp:
            emu = emulator_for(cache_dir=tmp, progress=False, on_demand=True, method="table")
            table_row(emu.spec, np.zeros((emu.spec.nx, emu.spec.ny, emu.spec.nz)))
            t0 = time.perf_counter()
            emu.fill(have)
            same = time.perf_counter() - t0
            emu.fill(np.ones_like(emu.have))
            whole = time.perf_counter() - t0
        build_ratios.append(whole / built)
        print(f"  its emulator ({method}) built {int(have.sum())} of {have.size} table points on "
              f"demand in {built:.1f} s (load operator included); here the whole direct table "
              f"{whole:.1f} s: {whole / built:.2f}x; the same points by direct runs {same:.1f} s",
              flush=True)
    print(f"cold identify / plain kernel: median {np.median(ratios):.2f}x over {repeat} runs "
          f"(target <= 2); whole table / on-demand build: median "
          f"{np.median(build_ratios):.2f}x (target >= 5)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rebuild", action="store_true")
    ap.add_argument("--builds", action="store_true",
                    help="time the table and white builds side by side (minutes)")
    ap.add_argument("--photons", type=int, default=250_000,
                    help="photons per table point at mus = 100 for --builds")
    ap.add_argument("--cold", action="store_true",
                    help="time a cold identify against the plain kernel (minutes)")
    ap.add_argument("--repeat", type=int, default=2, help="cold identifies for --cold")
    args = ap.parse_args(argv)
    if args.cold:
        time_cold(args.repeat)
        return
    if args.builds:
        time_builds(args.photons)
        return
    for label, make in [
        ("nodal loads, MC 100x100x50 -> mesh 20x20x10", lambda cache: emulator_for(
            cache_dir=cache, progress=False, on_demand=False)),
        ("voxel NA, 20x20x10", lambda cache: AbsorptionEmulator.build(
            EmulatorSpec.from_model(paper_model((20, 20, 10), progress=False)),
            cache_dir=cache, progress=False)),
    ]:
        emu = make(None)
        u, full = time_eval(emu)
        print(f"{label}: evaluation of 50 members {1e3 * u:.3f} ms (orbit values, "
              f"{emu.log_na.shape[2]} per member), {1e3 * full:.3f} ms (full field "
              f"{np.prod(emu.shape)}); recorded build {emu.build_seconds:.0f} s")
        if args.rebuild:
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                make(tmp)
                print(f"  build from scratch: {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
