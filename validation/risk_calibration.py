"""Does the filter's risk of thermal injury mean what it says? Reliability against the truth.

Scenario: the paper's block at body temperature (T_initial = 37 deg C) under a 1 W
top-hat pulse of 5 s (then 10 s off), constant optics (mua 1, mus 100), MCmatlab's
damage parameters E = 422.5 kJ/mol, A = 7.6e66 1/s: the surface passes 70 deg C and a
lens of tissue under the beam is damaged. The fine-grid truth (100 x 100 x 50 voxels,
2e6 photons, FEM on 520,251 nodes, every step kept) is interpolated onto the filter's
20 x 20 x 10 nodes; its damage Omega is integrated there the same way as the filter's.
The filter (N = 50, the paper's defaults, one surface sensor) gives at every node the
probability P(Omega > 1) and P(T > 60 deg C so far). Over nodes, five record times and
the seeds, the forecasts are binned by probability and set against how often the
event happened in the truth (a reliability table), with the Brier score. Writes
validation/reports/risk_calibration.md and a depth-map figure.

    python validation/risk_calibration.py [--seeds 0 1 2 3 4] [--photons 2000000]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import fem
from enkf.paper import emulator_for, filter_setup, paper_model
from enkf.risk import RiskTracker, plot_depth_maps
from enkf.tissue import TissueForwardModel, identify

E, A = 422.5e3, 7.6e66  # J/mol, 1/s (MCmatlab's example tissue)
POWER, T0, THRESHOLD = 1.0, 37.0, 60.0
RECORD = (2.5, 5.0, 7.5, 10.0, 15.0)
BINS = np.array([0.0, 0.05, 0.2, 0.4, 0.6, 0.8, 0.95, 1.0001])


def truth_on_coarse_nodes(photons: int, coarse_mesh) -> tuple[np.ndarray, np.ndarray]:
    """(times (n,), T (n, n_coarse_nodes)) of the fine-grid truth."""
    model = paper_model((100, 100, 50), photons, 1, progress=True)
    model.HS.P, model.HS.T_initial = POWER, T0
    model.HS.n_snapshots = 150
    model.run_monte_carlo()
    model.simulate_heat_distribution()
    P = fem.probe_matrix(model.HS.mesh, coarse_mesh.p)
    times = np.array([t for t, _ in model.HS.snapshots])
    T = np.array([P @ T_nodes for _, T_nodes in model.HS.snapshots])
    return times, T


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--photons", type=int, default=2_000_000)
    ap.add_argument("--out", default=str(Path(__file__).parent / "reports" / "risk_calibration.md"))
    args = ap.parse_args(argv)
    emu = emulator_for(progress=False)
    base = filter_setup("constant", emu)
    grid = base.grid
    mesh = TissueForwardModel(base).mesh
    times, T_true = truth_on_coarse_nodes(args.photons, mesh)
    omega_true = np.zeros_like(T_true)
    for k in range(1, len(times)):
        omega_true[k] = omega_true[k - 1] + fem.arrhenius_increment(
            T_true[k - 1], T_true[k], times[k] - times[k - 1], E, A)
    hot_true = np.maximum.accumulate(T_true > THRESHOLD, axis=0)
    sensor = fem.probe_matrix(mesh, np.zeros((3, 1)))
    y_true = (sensor @ T_true.T)[0]
    pairs = {"damage": [], "T": []}
    last = None
    for seed in args.seeds:
        setup = filter_setup("constant", emu, seed=seed)
        hs = paper_model((2, 2, 2), progress=False).HS
        hs.P = POWER
        setup.power, setup.T_initial = hs.laser_power, T0
        rng = np.random.default_rng([seed, 20230103])
        data = y_true[1:] + 0.1 * rng.standard_normal(len(times) - 1)
        tracker = RiskTracker(E=E, A=A, T_threshold=THRESHOLD, record_times=list(RECORD))
        est = identify(setup, times[1:], data[:, None], callback=tracker)
        for s in tracker.snapshots:
            k = int(np.argmin(np.abs(times - s.time)))
            pairs["damage"].append((s.p_damage, omega_true[k] > 1.0))
            pairs["T"].append((s.p_T_ever, hot_true[k]))
        last = tracker
        print(f"seed {seed}: mua {est.param_mean[-1, 0]:.4g}, mus {est.param_mean[-1, 1]:.4g}; "
              f"truth damaged nodes at 15 s: {int(np.sum(omega_true[-1] > 1))}, filter "
              f"P(Omega > 1) >= 0.5 at {int(np.sum(tracker.snapshots[-1].p_damage >= 0.5))}",
              flush=True)
    out = Path(args.out)
    fig = out.with_name("risk_depth_maps.png")
    plot_depth_maps(fig, last.snapshots[-1], grid, THRESHOLD)
    lines = ["# Risk of thermal injury: reliability against the truth", "",
             f"Command: `python validation/risk_calibration.py --seeds "
             f"{' '.join(map(str, args.seeds))} --photons {args.photons}`", "",
             f"Paper block at T_initial = {T0:g} deg C, {POWER:g} W top-hat for 5 s, constant "
             f"optics; damage E = {E:g} J/mol, A = {A:g} 1/s. Forecasts at every node of the "
             f"20 x 20 x 10 mesh at t = {', '.join(map(str, RECORD))} s over seeds "
             f"{args.seeds}; truth from the fine grid at the same nodes.", ""]
    for name, label in (("damage", "P(Omega > 1)"), ("T", f"P(T > {THRESHOLD:g} C so far)")):
        p = np.concatenate([a for a, _ in pairs[name]])
        o = np.concatenate([b for _, b in pairs[name]]).astype(float)
        brier = float(np.mean((p - o) ** 2))
        clim = float(np.mean((o.mean() - o) ** 2))
        lines += [f"## {label}", "", f"Brier score {brier:.5f} (always forecasting the base "
                  f"rate {o.mean():.4f}: {clim:.5f}); {int(o.sum())} of {o.size} node-times "
                  "had the event in the truth.", "",
                  "| forecast probability | node-times | mean forecast | observed frequency |",
                  "|---|---|---|---|"]
        idx = np.digitize(p, BINS) - 1
        for b in range(len(BINS) - 1):
            m = idx == b
            if m.any():
                lines.append(f"| [{BINS[b]:.2f}, {min(BINS[b + 1], 1):.2f}) | {int(m.sum())} | "
                             f"{p[m].mean():.3f} | {o[m].mean():.3f} |")
        lines.append("")
    lines += [f"![depth maps]({fig.name})", ""]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    print(f"report written to {out}")


if __name__ == "__main__":
    main()
