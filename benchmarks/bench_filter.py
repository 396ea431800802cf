"""The filter alone: 150 steps, N = 50, on the 20 x 20 x 10 model, emulator cached.

    python benchmarks/bench_filter.py [--scenario constant|time-varying|all-params]

Reports the wall time and the per-step latency (median, max); the truth and the emulator
come from the cache (built on first use). The machine's speed drifts by up to 2x from one
minute to the next on a shared VM, so each filter run is bracketed by a yardstick (a fixed
numpy workload: 150 draws of 50 x 4851 normals and a pass over them) and the ratio is
printed with the times. ``--members 50 100 200 400`` times the constant scenario's steps
for several ensemble sizes (per-step cost against N). ``--bank`` runs each scenario with
the drift bank of the command line's default (``enkf.tissue.drift.DriftBank``: a still and
a drifting filter) and reports the two filters' steps and the drifting filter's restarts
from the smoother apart (a restart runs once per pulse, after it). ``--bank --ab-rhs``
times, in one process and interleaved, the heat steps' right-hand side in one
axis-by-axis pass (``fem._kernels.tridiag3_theta_rhs``, the default) against the mass
pass plus the stiffness's sparse product. ``--smoother`` times the smoother through the
sensors' responses (``enkf.tissue.response``) against running the members, interleaved.
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


def yardstick() -> float:
    """s for a fixed numpy workload of the filter's size (normals, one pass over them)."""
    import time

    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for _ in range(150):
        x = rng.standard_normal((50, 4851))
        x += 1.0
    return time.perf_counter() - t0


def members_scaling(emu, sizes) -> None:
    truth = generate_truth(TruthConfig(scenario="constant"), progress=False)
    data = noisy_sensor(truth, 0)[:, None]
    for N in sizes:
        setup = filter_setup("constant", emu, n_members=N)
        identify(setup, truth.times[1:4], data[:3])
        est = identify(setup, truth.times[1:], data)
        lat = est.step_latency_s
        print(f"N = {N}: 150 steps {est.filter_wall_s:.2f} s, median step "
              f"{1e3 * np.median(lat):.1f} ms ({1e3 * np.median(lat) / N:.3f} ms per member), "
              f"max step {1e3 * lat.max():.1f} ms")


def ab_rhs(setup, truth, data, rounds: int = 4) -> None:
    """The bank's 150 steps with the one-pass right-hand side and with the sparse stiffness
    product (``_theta_tridiag`` dropped from every stepper), ``rounds`` interleaved."""
    import fem.stepper as stepper_module

    built = stepper_module.kronecker_operators
    use = {"fused": True}

    def operators(st):
        built(st)
        if not use["fused"]:
            st._theta_tridiag = None

    stepper_module.kronecker_operators = operators
    try:
        res = {True: [], False: []}
        for _ in range(rounds):
            for fused in (True, False):
                use["fused"] = fused
                est = identify(setup, truth.times[1:], data)
                rest = sum(r["wall_s"] for r in est.restarts)
                res[fused].append((est.filter_wall_s - rest, rest, est.param_mean[-1]))
    finally:
        stepper_module.kronecker_operators = built
    for fused in (True, False):
        w, r = [x[0] for x in res[fused]], [x[1] for x in res[fused]]
        print(f"  {'one pass' if fused else 'sparse K'}: steps best {min(w):.2f} s (median "
              f"{np.median(w):.2f}), restarts best {min(r):.2f} s")
    d = np.abs(res[True][0][2] - res[False][0][2]) / np.abs(res[False][0][2])
    print(f"  final estimates' largest relative difference {d.max():.1e}")


def smoother_ab(emu, rounds: int = 3) -> None:
    """The smoother through the sensors' responses (``enkf.tissue.response``) against
    running the members, in one process and interleaved: one window of 50 members over the
    paper's 150 ramp readings, then each restart form over the first 60 readings."""
    import time

    import enkf.tissue.smooth as smooth
    from enkf.tissue.pieces import assemble
    from enkf.tissue.response import sensor_response
    from fem.threads import blas_threads

    truth = generate_truth(TruthConfig(scenario="time-varying"), progress=False)
    data = noisy_sensor(truth, 0)[:, None]
    setup = filter_setup("time-varying", emu)
    times = truth.times[1:]
    pieces = assemble(setup, warm_dt=float(times[0]))
    model, P = pieces.model, pieces.P_obs
    X0, th0 = pieces.prior(np.random.default_rng(0), setup.n_members)
    drift = np.exp(np.linspace(0.0, 1.0, times.size))[:, None, None]
    theta = th0[None] * drift  # every member's optics rising over the window
    edges = np.r_[0.0, times]

    def members():
        T = np.tile(X0[0], (theta.shape[1], 1))
        out = np.empty((theta.shape[1], times.size, P.shape[0]))
        for k in range(times.size):
            T = model(T, np.ascontiguousarray(theta[k]), edges[k], edges[k + 1])
            out[:, k] = (P @ T.T).T
        return out

    tic = time.perf_counter()
    response = sensor_response(model, P, times, X0[0])
    built = time.perf_counter() - tic
    ref = members()
    best = {"response": np.inf, "members": np.inf}
    for _ in range(rounds):
        for name, fn in (("response", lambda: response.readings(theta)), ("members", members)):
            with blas_threads(1):  # as the smoother runs them
                tic = time.perf_counter()
                fn()
                best[name] = min(best[name], time.perf_counter() - tic)
    diff = np.abs(response.readings(theta) - ref).max()
    print(f"one window, 50 members x 150 readings: response {1e3 * best['response']:.1f} ms "
          f"(built once in {1e3 * built:.0f} ms, rank {response.rank}), members "
          f"{1e3 * best['members']:.0f} ms; largest difference {diff:.1e} K")
    real = smooth.sensor_response
    for form in (2, 9, "logistic"):
        walls, means = {}, {}
        for _ in range(rounds):
            for use in (True, False):
                smooth.sensor_response = real if use else (lambda *a: None)
                try:
                    tic = time.perf_counter()
                    est = smooth.smooth_drifting(setup, times[:60], data[:60], knots=form,
                                                 n_iter=8, discrepancy=0.01)
                finally:
                    smooth.sensor_response = real
                walls.setdefault(use, []).append(time.perf_counter() - tic)
                means[use] = est.mean
        d = np.max(np.abs(means[True] - means[False]) / np.abs(means[False]))
        print(f"restart form {form}, 60 readings: response {min(walls[True]):.2f} s, members "
              f"{min(walls[False]):.2f} s (best of {rounds}); estimates' largest relative "
              f"difference {d:.1e}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", choices=SCENARIOS, default=None)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--members", type=int, nargs="+", default=None,
                    help="time the constant scenario for these ensemble sizes and stop")
    ap.add_argument("--bank", action="store_true",
                    help="the drift bank (identify's default) on each scenario")
    ap.add_argument("--smoother", action="store_true",
                    help="the smoother through the sensors' responses against running the "
                         "members, interleaved in one process, and stop")
    ap.add_argument("--ab-rhs", action="store_true",
                    help="with --bank: the one-pass right-hand side against the sparse "
                         "stiffness product, interleaved in one process")
    args = ap.parse_args(argv)
    if args.members:
        members_scaling(emulator_for(progress=False), args.members)
        return
    if args.smoother:
        smoother_ab(emulator_for(progress=False), args.repeat)
        return
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
        if args.bank:  # the still filter: the paper's walk of the constant scenario
            from enkf.tissue.drift import DriftBank

            setup = setup.with_(random_walk_std=0.002, rtps=0.0, drift=DriftBank())
        identify(setup, truth.times[1:4], data[:3])  # warm up the JIT and the solvers
        if args.bank and args.ab_rhs:
            print(f"{sc}, drift bank:")
            ab_rhs(setup, truth, data)
            continue
        walls, med, mx, ratios, rest = [], [], [], [], []
        for _ in range(args.repeat):
            y0 = yardstick()
            est = identify(setup, truth.times[1:], data)
            y1 = yardstick()
            restarts = sum(r["wall_s"] for r in est.restarts)
            rest.append(restarts)
            walls.append(est.filter_wall_s - restarts)
            ratios.append(est.filter_wall_s / (0.5 * (y0 + y1)))
            med.append(np.median(est.step_latency_s))
            mx.append(est.step_latency_s.max())
        warnings.simplefilter("ignore", RuntimeWarning)  # emulator clamps, reported elsewhere
        print(f"{sc}: filter {min(walls):.2f} s for {len(truth.times) - 1} steps (best of "
              f"{args.repeat}; median {np.median(walls):.2f} s), median step "
              f"{1e3 * min(med):.1f} ms, max step {1e3 * min(mx):.1f} ms; filter / yardstick "
              f"{min(ratios):.2f}-{max(ratios):.2f}"
              + (f"; drift bank: P(drift) {est.drift_weight[-1]:.3g}, restarts "
                 f"{len(est.restarts)} taking {min(rest):.2f} s" if args.bank else ""))


if __name__ == "__main__":
    main()
