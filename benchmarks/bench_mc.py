"""Monte Carlo speed: photons per second on the paper's standard tissue, 1 and 2 threads.

100 x 100 x 50 voxels over 0.5 x 0.5 x 0.25 cm, mua 1, mus 100, g 0.9, n 1.3, top-hat
radius 1 mm, matched interfaces, boundary type 1. Run::

    python benchmarks/bench_mc.py [--photons N] [--pairs K]

The JIT compile is done (or loaded from the cache) before timing; only the kernel is
timed. One-thread and two-thread runs alternate (``--pairs`` times), so that a slow
spell of the machine hits both; the speed-up is reported over all pairs (median,
worst and best). For each run the kernel's CPU time over its wall time
(``MC.cores_used``) is printed too: the threads claim batches dynamically, so it stays
near 2 even when one core of a shared virtual machine runs slower for a while.
"""

from __future__ import annotations

import argparse
import resource
import statistics

import numba

from enkf.paper import paper_model


def standard_model(n_photons: int, threads: int):
    """The paper's block (enkf.paper.paper_model) with a thread count."""
    model = paper_model((100, 100, 50), n_photons=n_photons, seed=1, progress=False)
    model.MC.n_threads = threads
    return model


def run(n_photons: int, threads: int):
    MC = standard_model(n_photons, threads).run_monte_carlo().MC
    return MC.photons_per_second, MC.cores_used


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photons", type=int, default=1_000_000)
    parser.add_argument("--pairs", type=int, default=5)
    args = parser.parse_args(argv)
    standard_model(2000, 1).run_monte_carlo()  # compile / load cache
    two = min(2, numba.config.NUMBA_NUM_THREADS)
    pairs = []
    for k in range(args.pairs):
        r1, c1 = run(args.photons, 1)
        r2, c2 = run(args.photons, two)
        pairs.append((r1, r2, c2))
        print(f"pair {k + 1}: 1 thread {r1:.3e} photons/s, {two} threads {r2:.3e} photons/s "
              f"on {c2:.2f} cores, speed-up {r2 / r1:.2f}x", flush=True)
    rate1 = max(p[0] for p in pairs)
    rate2 = max(p[1] for p in pairs)
    print(f"best rates ({args.photons} photons per run): 1 thread {rate1:.3e}, "
          f"{two} threads {rate2:.3e} photons/s")
    if two == 2:
        ups = [p[1] / p[0] for p in pairs]
        print(f"speed-up 2 threads / 1 thread: median {statistics.median(ups):.2f}x, "
              f"worst {min(ups):.2f}x, best {max(ups):.2f}x, over {len(ups)} pairs")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory: {peak:.0f} MiB")


if __name__ == "__main__":
    main()
