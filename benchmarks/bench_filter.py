"""The filter alone: 150 steps, N = 50, on the 20 x 20 x 10 model, emulator cached.

    python benchmarks/bench_filter.py [--scenario constant|time-varying|all-params]

Reports the wall time and the per-step latency (median, max); the truth and the emulator
come from the cache (built on first use).
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from enkf.paper import SCENARIOS, TruthConfig, emulator_for, filter_setup, generate_truth, noisy_sensor
from enkf.tissue import identify


def heat_step_ms(operator: str, new_scales: bool, N: int = 50, repeat: int = 60,
                 mass: str = "lumped") -> float:
    """Median ms of one heat step of N members on the filter's 20 x 20 x 10 mesh."""
    import time

    import fem

    mesh = fem.BoxGrid(20, 20, 10, 0.5, 0.5, 0.25).mesh()
    rng = np.random.default_rng(0)
    stepper = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, operator=operator, mass=mass)
    T = rng.random((N, mesh.p.shape[1]))
    f = 1e-3 * rng.random(T.shape)
    times = []
    for _ in range(repeat):
        kw = dict(vhc_scale=rng.uniform(0.5, 2, N), tc_scale=rng.uniform(0.5, 2, N)) \
            if new_scales else {}
        t0 = time.perf_counter()
        T = stepper.step(T, f, **kw)
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times[5:]))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", choices=SCENARIOS, default=None)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    avg = dict(mass="averaged")
    print(f"heat step, 50 members, kronecker operator with the filter's averaged mass: "
          f"{heat_step_ms('kronecker', False, **avg):.2f} ms (fixed VHC, TC), "
          f"{heat_step_ms('kronecker', True, **avg):.2f} ms (new member scales every step); "
          f"lumped mass {heat_step_ms('kronecker', False):.2f} ms; exact P1 "
          f"{heat_step_ms('p1', False):.2f} ms")
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
        warnings.simplefilter("ignore", RuntimeWarning)  # emulator clamps, reported elsewhere
        print(f"{sc}: filter {min(walls):.2f} s for {len(truth.times) - 1} steps (best of "
              f"{args.repeat}), median step {1e3 * min(med):.1f} ms, max step "
              f"{1e3 * min(mx):.1f} ms")


if __name__ == "__main__":
    main()
