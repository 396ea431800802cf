"""Dask: emulator table build on 1 and 2 workers, and the overhead of one task.

    python benchmarks/bench_dask.py [--table 6] [--photons 100000]

The table is the filter's voxel emulator of the paper's block on 20 x 20 x 10 (a
``--table`` x ``--table`` grid of Monte Carlo points, ``--photons`` at mus = 100), built
three times from scratch in a temporary cache: on this machine's threads (no Dask), on
a local cluster of 1 single-threaded worker, and on 2. The overhead is the time per
task of a batch of empty tasks, and of the smallest sensible Monte Carlo task (one
range of 1000-photon batches on the same grid).
"""

from __future__ import annotations

import argparse
import functools
import tempfile
import time

from enkf.paper import paper_model
from mcmatlab_py.distributed import connect, run_tasks
from mcmatlab_py.emulator import AbsorptionEmulator, EmulatorSpec


def _identity(x):
    return x


def build_seconds(spec: EmulatorSpec, client) -> float:
    with tempfile.TemporaryDirectory() as cache:
        t0 = time.perf_counter()
        AbsorptionEmulator.build(spec, cache_dir=cache, progress=False, client=client)
        return time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--table", type=int, default=6)
    ap.add_argument("--photons", type=int, default=100_000)
    args = ap.parse_args(argv)
    spec = EmulatorSpec.from_model(paper_model((20, 20, 10), progress=False),
                                   n_photons=args.photons, n_mua=args.table, n_mus=args.table)
    print(f"emulator table {args.table} x {args.table}, {args.photons} photons at mus = 100:")
    print(f"  this machine, numba threads: {build_seconds(spec, None):.1f} s")
    times = {}
    for n in (1, 2):
        client = connect(n_workers=n)
        try:
            build_seconds(spec, client)  # workers import and load the JIT cache once
            times[n] = build_seconds(spec, client)
            print(f"  local cluster, {n} worker(s) of 1 thread: {times[n]:.1f} s", flush=True)
            if n == 2:
                items = list(range(400))
                t0 = time.perf_counter()
                run_tasks(_identity, items, client=client)
                empty = (time.perf_counter() - t0) / len(items)
                print(f"task overhead: {1e3 * empty:.2f} ms per empty task (400 tasks, 2 workers)")
                from mcmatlab_py.monte_carlo import batch_range
                from mcmatlab_py.monte_carlo import host as mc

                m = paper_model((20, 20, 10), n_photons=8000, progress=False)
                a = mc.kernel_args(m.G, m.MC, m.G.medium_map(), *mc.optical_arrays(m.G.media),
                                   1, 8000)
                ranges = [(i, i + 1) for i in range(8)]
                task = functools.partial(batch_range, a)
                run_tasks(task, ranges, client=client)
                t0 = time.perf_counter()
                parts = run_tasks(task, ranges, client=client)
                wall = (time.perf_counter() - t0) / len(ranges)
                kernel = sum(p[1] for p in parts) / len(ranges)
                print(f"smallest Monte Carlo task (1000 photons on 20 x 20 x 10): "
                      f"{1e3 * wall:.1f} ms per task on 2 workers, of which kernel "
                      f"{1e3 * kernel:.1f} ms")
        finally:
            client.close()
            client.cluster.close()
    print(f"speed-up 2 workers / 1 worker: {times[1] / times[2]:.2f}x")


if __name__ == "__main__":
    main()
