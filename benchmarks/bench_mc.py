"""Monte Carlo speed: photons per second on the paper's standard tissue, 1 and 2 threads.

100 x 100 x 50 voxels over 0.5 x 0.5 x 0.25 cm, mua 1, mus 100, g 0.9, n 1.3, top-hat
radius 1 mm, matched interfaces, boundary type 1. Run::

    python benchmarks/bench_mc.py [--photons N] [--pairs K] [--ratio-photons N] [--ratio-only]
                                  [--control]

The JIT compile is done (or loaded from the cache) before timing; only the kernel is
timed. One-thread and two-thread runs alternate (``--pairs`` times, the order swapped
from pair to pair), so that a slow spell of the machine hits both; the speed-up is
reported over all pairs (median, worst and best). For each run the kernel's CPU time over its wall time
(``MC.cores_used``) is printed too: the threads claim batches dynamically, so it stays
near 2 even when one core of a shared virtual machine runs slower for a while.

``--control`` adds, to each pair, two one-thread runs in two processes at the same time:
their summed rate is what the machine gives two independent copies of the kernel, the
ceiling for two threads sharing its caches and memory (on a shared virtual machine that
is often well below twice one thread).

Then the yardstick: our kernel's photons per CPU-second over those of a plain numba
kernel (``benchmarks/plain_kernel.py``: absorbs at the interaction points, recomputes
the voxel index from the position, one thread) on the same tissue, 40 x 40 x 20 and
100 x 100 x 50 voxels, one thread each, the two kernels' runs interleaved (``--pairs``
times); the ratio of the best rates of each is printed, with the median of the pairs'
ratios. A ratio within one process does not depend on how loaded the machine is.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import time
from pathlib import Path

import numba
import numpy as np

from enkf.paper import paper_model


def standard_model(n_photons: int, threads: int):
    """The paper's block (enkf.paper.paper_model) with a thread count."""
    model = paper_model((100, 100, 50), n_photons=n_photons, seed=1, progress=False)
    model.MC.n_threads = threads
    return model


def run(n_photons: int, threads: int):
    MC = standard_model(n_photons, threads).run_monte_carlo().MC
    return MC.photons_per_second, MC.cores_used


def _one_thread_rate(n_photons: int) -> float:
    return run(n_photons, 1)[0]


def two_processes(n_photons: int) -> float:
    """Summed photons/s of two one-thread runs in two processes side by side."""
    import multiprocessing as mp

    with mp.get_context("spawn").Pool(2) as pool:
        pool.map(_one_thread_rate, [2000, 2000])  # compile / load cache in each
        return float(sum(pool.map(_one_thread_rate, [n_photons, n_photons])))


def our_cpu_rate(grid, n_photons: int) -> float:
    """Photons per CPU-second of our kernel on one thread."""
    model = paper_model(grid, n_photons=n_photons, seed=1, progress=False)
    model.MC.n_threads = 1
    MC = model.run_monte_carlo().MC
    return MC.n_photons / (MC.simulation_time * MC.cores_used)


def plain_cpu_rate(grid, n_photons: int, seed: int = 1) -> float:
    """Photons per CPU-second of the yardstick kernel, same tissue and beam."""
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from plain_kernel import plain_run

    model = paper_model(grid, n_photons=1, progress=False)
    G, med = model.G, model.G.media[0]
    M = np.zeros(grid, dtype=np.int32)
    args = (M, np.array([med.mua]), np.array([med.mus]), np.array([med.g]), *grid, G.dx,
            model.MC.light_source.radius)
    plain_run(*args, 100, seed)  # compile / load cache
    c0 = time.process_time()
    plain_run(*args, n_photons, seed)
    return n_photons / (time.process_time() - c0)


def yardstick(n_photons: int, pairs: int) -> None:
    """Our kernel over the plain one, photons per CPU-second, one thread, interleaved runs."""
    for grid in ((40, 40, 20), (100, 100, 50)):
        our_cpu_rate(grid, 2000)  # compile / load cache
        plain_cpu_rate(grid, 100)
        rows = []
        for k in range(pairs):
            ours = our_cpu_rate(grid, n_photons)
            plain = plain_cpu_rate(grid, n_photons, seed=k + 1)
            rows.append((ours, plain))
            print(f"{grid}: pair {k + 1}: ours {ours:.3e}, plain {plain:.3e} photons/CPU-s, "
                  f"ratio {ours / plain:.2f}", flush=True)
        best = max(r[0] for r in rows) / max(r[1] for r in rows)
        med = statistics.median(r[0] / r[1] for r in rows)
        print(f"{grid}: ours / plain kernel, photons per CPU-second, one thread: best rates "
              f"{best:.2f}x, median of pairs {med:.2f}x ({pairs} pairs of {n_photons} photons)")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photons", type=int, default=1_000_000)
    parser.add_argument("--pairs", type=int, default=5)
    parser.add_argument("--ratio-photons", type=int, default=200_000,
                        help="photons per run of the yardstick comparison")
    parser.add_argument("--ratio-only", action="store_true",
                        help="only the comparison with the plain kernel")
    parser.add_argument("--control", action="store_true",
                        help="also two one-thread processes side by side, in each pair")
    args = parser.parse_args(argv)
    if args.ratio_only:
        yardstick(args.ratio_photons, args.pairs)
        return
    standard_model(2000, 1).run_monte_carlo()  # compile / load cache
    two = min(2, numba.config.NUMBA_NUM_THREADS)
    pairs, controls = [], []
    for k in range(args.pairs):
        if k % 2:  # the order alternates, so that a drift of the machine's speed cancels
            r2, c2 = run(args.photons, two)
            r1, c1 = run(args.photons, 1)
        else:
            r1, c1 = run(args.photons, 1)
            r2, c2 = run(args.photons, two)
        pairs.append((r1, r2, c2))
        extra = ""
        if args.control:
            r_pp = two_processes(args.photons)
            controls.append(r_pp)
            extra = (f"; two one-thread processes together {r_pp:.3e} photons/s, "
                     f"{r_pp / r1:.2f}x ({r2 / r_pp:.2f} of it with threads)")
        print(f"pair {k + 1}: 1 thread {r1:.3e} photons/s, {two} threads {r2:.3e} photons/s "
              f"on {c2:.2f} cores, speed-up {r2 / r1:.2f}x{extra}", flush=True)
    rate1 = max(p[0] for p in pairs)
    rate2 = max(p[1] for p in pairs)
    print(f"best rates ({args.photons} photons per run): 1 thread {rate1:.3e}, "
          f"{two} threads {rate2:.3e} photons/s; medians "
          f"{statistics.median(p[0] for p in pairs):.3e}, "
          f"{statistics.median(p[1] for p in pairs):.3e}")
    if two == 2:
        ups = [p[1] / p[0] for p in pairs]
        print(f"speed-up 2 threads / 1 thread: median {statistics.median(ups):.2f}x, "
              f"worst {min(ups):.2f}x, best {max(ups):.2f}x, over {len(ups)} pairs")
    if controls:
        th = [p[1] / c for p, c in zip(pairs, controls, strict=True)]
        print(f"two threads / two processes: median {statistics.median(th):.2f} (the "
              f"processes' own speed-up over one thread: median "
              f"{statistics.median(c / p[0] for p, c in zip(pairs, controls, strict=True)):.2f}x)")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory: {peak:.0f} MiB")
    yardstick(args.ratio_photons, args.pairs)


if __name__ == "__main__":
    main()
