"""Memory of an MCmatlab-style heat run on a large heterogeneous block (issue #20).

Two media (a layer boundary at z = 0.2 cm, different VHC and TC), n x n x n/2 voxels,
a short Monte Carlo (2 x 10^4 photons), then two heat steps: the peak resident memory and
the bytes per FEM node over what the process held before the heat run.

    python benchmarks/bench_heat_memory.py [--n 100]     # 200: 4 M nodes, ~5 GB
"""

from __future__ import annotations

import argparse
import resource
import time

from mcmatlab_py import Medium, Model


def rss_mb() -> float:
    """Peak resident set size of this process so far, MB (Linux: ru_maxrss in KB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100, help="voxels along x and y (z: n / 2)")
    args = ap.parse_args(argv)
    n = args.n
    m = Model()
    m.G.nx, m.G.ny, m.G.nz = n, n, n // 2
    m.G.Lx = m.G.Ly = 1.0
    m.G.Lz = 0.5
    m.G.media = [Medium("upper", mua=1, mus=100, g=0.9, VHC=3.76, TC=0.0037),
                 Medium("lower", mua=5, mus=50, g=0.9, VHC=3.9, TC=0.005)]
    m.G.geom_func = lambda X, Y, Z: (Z > 0.2).astype(int)
    m.MC.n_photons_requested, m.MC.progress, m.MC.seed = 20_000, False, 1
    m.run_monte_carlo()
    before = rss_mb()
    m.HS.P, m.HS.duration_on, m.HS.duration_off, m.HS.dt = 1.0, 0.2, 0.0, 0.1
    m.HS.progress = False
    t0 = time.perf_counter()
    m.simulate_heat_distribution()
    nodes = (n + 1) ** 2 * (n // 2 + 1)
    peak = rss_mb()
    print(f"{n} x {n} x {n // 2} voxels, {nodes} nodes: heat run {time.perf_counter() - t0:.1f} s, "
          f"peak {peak:.0f} MB ({1e6 * (peak - before) / nodes:.0f} bytes per node over the "
          f"{before:.0f} MB before it)")


if __name__ == "__main__":
    main()
