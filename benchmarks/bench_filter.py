"""The filter alone: 150 steps, N = 50, on the 20 x 20 x 10 model, emulator cached.

    python benchmarks/bench_filter.py [--scenario constant|time-varying|all-params]

Reports the wall time and the per-step latency (median, max); the truth and the emulator
come from the cache (built on first use).
"""

from __future__ import annotations

import argparse

import numpy as np

from enkf.paper import SCENARIOS, TruthConfig, emulator_for, filter_setup, generate_truth, noisy_sensor
from enkf.tissue import identify


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", choices=SCENARIOS, default=None)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    emu = emulator_for(progress=False)
    for sc in [args.scenario] if args.scenario else SCENARIOS:
        truth = generate_truth(TruthConfig(scenario=sc), progress=False)
        data = noisy_sensor(truth, 0)[:, None]
        setup = filter_setup(sc, emu)
        identify(setup, truth.times[1:4], data[:3])  # warm up the JIT and the solvers
        walls, med, mx = [], [], []
        for _ in range(args.repeat):
            est = identify(setup, truth.times[1:], data)
            walls.append(est.filter_wall_s)
            med.append(np.median(est.step_latency_s))
            mx.append(est.step_latency_s.max())
        print(f"{sc}: filter {min(walls):.2f} s for {len(truth.times) - 1} steps (best of "
              f"{args.repeat}), median step {1e3 * min(med):.1f} ms, max step "
              f"{1e3 * min(mx):.1f} ms")


if __name__ == "__main__":
    main()
