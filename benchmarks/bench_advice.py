"""The advice at each reading: is every step's advice out within 100 ms (issue 53)?

    python benchmarks/bench_advice.py [--scenario constant time-varying] [--repeat 3]

The shipped config ``examples/own_data.toml`` (N = 50, the drift bank: a still filter and
drifting ones) at body temperature (``HS.T_initial = 37``) with the laser at 1.1 W for
5 s, its medium given MCmatlab's Arrhenius law, and the ``[advice]`` table of
``docs/risk.md`` (target 0.1 cm below the beam, a temperature limit at 0.2 cm and on the
surface, the plan the config's laser). The readings: the paper's truth at the surface
sensor (its rise scaled from 0.5 W to 1.1 W, 150 readings at 10 Hz, noise 0.1 deg C).

An :class:`~enkf.tissue.OnlineIdentifier` takes the readings one by one and the advice
(:meth:`Advisor.online`) follows each update, as ``identify --follow`` does; both are
timed (the JIT and the solvers warmed first on 3 readings of another identifier). The
filters' members after each reading are kept, and the advice is then timed on them
alone, ``--repeat`` times from a fresh advisor each: each reading's best of the repeats
is its cost, their worst what a busy machine adds. Reported per scenario: median, 95th
percentile and max ms a reading; the readings by kind (the first; those with the plan
still heating ahead, where the drifting filters' optics are carried on piece by piece
over the longest horizons; the laser off for good; after the drifting filters'
restarts from the smoother, when they are forecast apart) and the slowest ones; and the
advisor's build (its stored rows). The machine's load (``os.getloadavg``) is printed
beside the times: the 2 cores are shared.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).parents[1]
T0, POWER = 37.0, 1.1  # deg C, W
ADVICE = {"target_depth": 0.1, "protected_depth": 0.2, "protected_T": 50.0,
          "surface_T": 100.0}


def config():
    """examples/own_data.toml at 37 deg C and 1.1 W, with MCmatlab's damage law and
    ``[advice]``."""
    from enkf.app.config import identify_config_from_dict
    from enkf.tissue.risk import MCMATLAB_A, MCMATLAB_E
    from mcmatlab_py.config import read_toml

    raw = read_toml(ROOT / "examples" / "own_data.toml")
    raw["HS"].update(P=POWER, T_initial=T0)
    raw["G"]["media"][0].update(E=MCMATLAB_E, A=MCMATLAB_A)
    raw["advice"] = dict(ADVICE)
    raw.pop("data", None)
    return identify_config_from_dict(raw)


class Readings:
    """The filters after one reading, as :meth:`Advisor.online` reads an identifier."""

    def __init__(self, time_s: float, ensembles: list):
        self.time, self._ens = time_s, ensembles

    def filter_ensembles(self) -> list:
        return self._ens


def follow(cfg, setup, scenario: str) -> tuple[list, list, np.ndarray]:
    """The filters' members after each of the 150 readings (copies), the readings after
    which a drifting filter restarted from the smoother, and ms of the advice and of the
    filter's update at each reading (columns) taken as ``identify --follow`` does: the
    advice after each update, the JIT warmed on 3 readings of another identifier first."""
    from enkf.paper import TruthConfig, generate_truth, noisy_sensor
    from enkf.tissue import OnlineIdentifier

    truth = generate_truth(TruthConfig(scenario=scenario), progress=False)
    data = T0 + POWER / 0.5 * noisy_sensor(truth, 0)  # the truth starts at 0 deg C
    out, ms = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ident, adv = OnlineIdentifier(setup, param_bounds=cfg.param_bounds), \
            cfg.advice.advisor(setup)
        for t, y in zip(truth.times[1:4], data[:3], strict=True):
            ident.update(t, [y])
            adv.online(ident)
        ident, adv = OnlineIdentifier(setup, param_bounds=cfg.param_bounds), \
            cfg.advice.advisor(setup)
        for t, y in zip(truth.times[1:], data, strict=True):
            tic = time.perf_counter()
            ident.update(t, [y])
            mid = time.perf_counter()
            adv.online(ident)
            ms.append((1e3 * (time.perf_counter() - mid), 1e3 * (mid - tic)))
            out.append(Readings(ident.time, [(n, w, X.copy(), th.copy()) for n, w, X, th
                                             in ident.filter_ensembles()]))
    return out, list(ident.restart_times), np.array(ms)


def what(adv, r: Readings) -> dict:
    """What the advice at reading ``r`` forecast: the filters apart (identical drifting
    filters once, those below ``min_weight`` not at all), the steps of its horizon, and
    how many of them carry drifting optics (while the plan still heats)."""
    import math

    kept = [(n, X, th) for n, w, X, th in r.filter_ensembles() if w >= adv.min_weight]
    apart = []
    for n, X, th in kept:
        if not any(np.array_equal(X, X0) and np.array_equal(th, th0) for _, X0, th0 in apart):
            apart.append((n, X, th))
    end = min(max(adv.plan.end, r.time) + adv.tail, r.time + adv.max_horizon)
    K = int(min(adv.K, max(1, math.ceil((end - r.time) / adv.step - 1e-9))))
    drifting = [n for n, _, _ in apart if r.time < adv.plan.end  # the optics drift heated
                and adv.walks.get(n, (np.zeros(1),))[0].max() >= adv.hold_below]
    return {"filters": len(apart), "K": K, "drifting": len(drifting)}


def time_advice(cfg, setup, readings: list) -> tuple:
    """ms of :meth:`Advisor.online` at each reading from a fresh advisor, s to build it,
    and the advisor."""
    tic = time.perf_counter()
    adv = cfg.advice.advisor(setup)
    build = time.perf_counter() - tic
    ms = []
    for r in readings:
        tic = time.perf_counter()
        adv.online(r)
        ms.append(1e3 * (time.perf_counter() - tic))
    return np.array(ms), build, adv


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", nargs="+", default=["constant", "time-varying"],
                    choices=["constant", "time-varying"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--slowest", type=int, default=5, help="readings listed per scenario")
    args = ap.parse_args(argv)
    cfg = config()
    setup = cfg.setup(cfg.emulator(progress=False), seed=0)
    for sc in args.scenario:
        load = os.getloadavg()[0]
        readings, restarts, live = follow(cfg, setup, sc)
        runs = [time_advice(cfg, setup, readings) for _ in range(args.repeat)]
        ms = np.array([r[0] for r in runs])
        best, worst = ms.min(axis=0), ms.max(axis=0)
        adv = runs[-1][2]
        info = [what(adv, r) for r in readings]
        a, f = live[:, 0], live[:, 1]
        print(f"{sc} (load {load:.2f} to {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores): "
              f"the advice after each filter update (identify --follow): median "
              f"{np.median(a):.1f} ms, 95th percentile {np.percentile(a, 95):.1f} ms, max "
              f"{a.max():.1f} ms, within 100 ms at {np.mean(a < 100):.0%} of "
              f"{len(a)} readings (the filter's update median {np.median(f):.0f} ms); the "
              f"slowest, reading {a.argmax() + 1} (t = {readings[a.argmax()].time:.1f} s), "
              f"takes {best[a.argmax()]:.1f} ms on its kept members")
        print(f"  the advice alone on the kept members, each reading's best of {args.repeat}: "
              f"median {np.median(best):.1f} ms, 95th percentile "
              f"{np.percentile(best, 95):.1f} ms, max {best.max():.1f} ms; their worst: 95th "
              f"percentile {np.percentile(worst, 95):.1f} ms, max {worst.max():.1f} ms")
        print(f"  advisor built in {min(r[1] for r in runs):.2f} s (engine {adv.engine}, "
              f"{adv.K} steps of {adv.step:g} s, stored rows of rank "
              f"{adv.forecast.rank if adv.engine == 'adjoint' else '-'}); smoother restarts "
              f"after {', '.join(f'{t:g} s' for t in restarts) or 'none'}")
        groups = {"first reading": [0],
                  "the plan heating ahead":
                      [i for i, r in enumerate(readings) if i and r.time < adv.plan.end],
                  "the laser off for good, before the restarts":
                      [i for i, r in enumerate(readings) if r.time >= adv.plan.end
                       and not any(r.time >= t - 1e-9 for t in restarts)],
                  "after the restarts (the filters forecast apart)":
                      [i for i, r in enumerate(readings)
                       if any(r.time >= t - 1e-9 for t in restarts)]}
        for label, idx in groups.items():
            if idx:
                b = best[idx]
                print(f"  {label}: {len(idx)} readings, median {np.median(b):.1f} ms, max "
                      f"{b.max():.1f} ms (best of {args.repeat}); filters forecast "
                      f"{min(info[i]['filters'] for i in idx)}-"
                      f"{max(info[i]['filters'] for i in idx)} (with drifting optics "
                      f"{min(info[i]['drifting'] for i in idx)}-"
                      f"{max(info[i]['drifting'] for i in idx)}), steps "
                      f"{min(info[i]['K'] for i in idx)}-{max(info[i]['K'] for i in idx)}")
        for i in np.argsort(-best)[:args.slowest]:
            r, d = readings[i], info[i]
            after = any(0 <= r.time - t < 0.35 for t in restarts)
            print(f"  reading {i + 1} (t = {r.time:.1f} s): {best[i]:.1f} ms (worst "
                  f"{worst[i]:.1f}, after the filter's update {a[i]:.1f}); {d['filters']} "
                  f"filter(s) forecast, {d['drifting']} with drifting optics, {d['K']} steps"
                  + ("; just after a smoother restart" if after else ""))


if __name__ == "__main__":
    main()
