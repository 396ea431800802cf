"""Monte Carlo speed: photons per second on the paper's standard tissue, 1 and 2 threads.

100 x 100 x 50 voxels over 0.5 x 0.5 x 0.25 cm, mua 1, mus 100, g 0.9, n 1.3, top-hat
radius 1 mm, matched interfaces, boundary type 1. Run::

    python benchmarks/bench_mc.py [--photons N]

The JIT compile is done (or loaded from the cache) before timing; only the kernel is timed.
"""

from __future__ import annotations

import argparse
import resource

import numba

from mcmatlab_py import Medium, Model


def standard_model(n_photons: int, threads: int) -> Model:
    model = Model()
    model.G.nx, model.G.ny, model.G.nz = 100, 100, 50
    model.G.Lx, model.G.Ly, model.G.Lz = 0.5, 0.5, 0.25
    model.G.media = [Medium("standard tissue", mua=1.0, mus=100.0, g=0.9, n=1.3)]
    model.MC.n_photons_requested = n_photons
    model.MC.seed = 1
    model.MC.matched_interfaces = True
    model.MC.boundary_type = 1
    model.MC.light_source.source_type = "tophat"
    model.MC.light_source.radius = 0.1
    model.MC.n_threads = threads
    model.MC.progress = False
    return model


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photons", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    standard_model(2000, 1).run_monte_carlo()  # compile / load cache
    rates = {}
    for threads in sorted({1, min(2, numba.config.NUMBA_NUM_THREADS)}):
        best = 0.0
        for _ in range(args.repeat):
            MC = standard_model(args.photons, threads).run_monte_carlo().MC
            best = max(best, MC.photons_per_second)
        rates[threads] = best
        print(f"{threads} thread(s): {best:.3e} photons/s ({args.photons} photons, best of "
              f"{args.repeat})")
    if 2 in rates:
        print(f"speed-up 2 threads / 1 thread: {rates[2] / rates[1]:.2f}x")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory: {peak:.0f} MiB")


if __name__ == "__main__":
    main()
