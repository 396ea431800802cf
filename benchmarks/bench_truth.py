"""The fine-grid truth of the time-varying scenario, timed from scratch (minutes).

Direct Monte Carlo at every change of the optical properties (50 runs of 5 x 10^5
photons on 100 x 100 x 50 voxels) and FEM heat on 520,251 nodes, 150 steps::

    python benchmarks/bench_truth.py [--scenario time-varying|constant]
"""

from __future__ import annotations

import argparse
import tempfile
import time

from enkf.paper import TruthConfig, generate_truth


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="time-varying", choices=("time-varying", "constant"))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as cache:
        t0 = time.perf_counter()
        generate_truth(TruthConfig(scenario=args.scenario), cache_dir=cache, progress=False)
        print(f"{args.scenario} truth from scratch: {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
