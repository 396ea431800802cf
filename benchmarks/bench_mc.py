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

from enkf.paper import paper_model


def standard_model(n_photons: int, threads: int):
    """The paper's block (enkf.paper.paper_model) with a thread count."""
    model = paper_model((100, 100, 50), n_photons=n_photons, seed=1, progress=False)
    model.MC.n_threads = threads
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
