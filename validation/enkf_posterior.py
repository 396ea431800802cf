"""Is the EnKF's uncertainty honest? The exact grid posterior of (mua, mus), constant case.

The exact Bayesian posterior of constant (mua, mus) given the sensor series, with the
filter's own coarse forward model (emulator + 20 x 20 x 10 FEM, no model noise), the
paper's uniform prior on [0.5, 2] x nominal and Gaussian noise of variance 0.01, is
computed on a parameter grid. It is set against the EnKF's mean and spread at t = 15 s,
for several seeds; and the EnKF's spread is set against its error over the seeds.
Writes validation/reports/enkf_posterior.md.

    python validation/enkf_posterior.py [--seeds 0 1 2 3 4] [--grid 41]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import fem
from enkf.paper import (
    TABLE,
    TruthConfig,
    emulator_for,
    filter_setup,
    generate_truth,
    noisy_sensor,
    run_experiment,
)
from enkf.tissue import TissueForwardModel


def predicted_sensor(setup, thetas: np.ndarray, times: np.ndarray, batch: int = 400):
    """Noise-free sensor series (n_theta, M) of the filter's model for constant parameters."""
    model = TissueForwardModel(setup)
    P = fem.probe_matrix(model.mesh, setup.sensors.positions.T)
    out = np.empty((len(thetas), len(times)))
    npts = model.mesh.p.shape[1]
    for b in range(0, len(thetas), batch):
        th = thetas[b:b + batch]
        T = np.full((len(th), npts), setup.T_initial)
        t0 = 0.0
        for k, t1 in enumerate(times):
            T = model(T, th, t0, t1)
            out[b:b + batch, k] = (P @ T.T)[0]
            t0 = t1
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--grid", type=int, default=41)
    ap.add_argument("--out", default=str(Path(__file__).parent / "reports" / "enkf_posterior.md"))
    args = ap.parse_args(argv)
    truth = generate_truth(TruthConfig(scenario="constant"), progress=False)
    emu = emulator_for(progress=False)
    setup = filter_setup("constant", emu)
    times = truth.times[1:]

    def grid_posterior(data, lo, hi):
        """Posterior mean and sd on a grid over [lo, hi], refined until it resolves the peak."""
        for _ in range(6):
            mua = np.linspace(lo[0], hi[0], args.grid)
            mus = np.linspace(lo[1], hi[1], args.grid)
            A, S = np.meshgrid(mua, mus, indexing="ij")
            thetas = np.column_stack([A.ravel(), S.ravel()])
            pred = predicted_sensor(setup, thetas, times)
            loglik = -0.5 * np.sum((pred - data[None, :]) ** 2, axis=1) / 0.01
            w = np.exp(loglik - loglik.max())
            w /= w.sum()
            pm = w @ thetas
            psd = np.sqrt(w @ (thetas - pm) ** 2)
            step = np.array([mua[1] - mua[0], mus[1] - mus[0]])
            if np.all(psd > 2 * step):
                return pm, psd
            # zoom on +-8 sd (at least +-4 grid steps), inside the prior's support
            half = np.maximum(8 * psd, 4 * step)
            lo = np.maximum(pm - half, [0.5 * TABLE["mua"], 0.5 * TABLE["mus"]])
            hi = np.minimum(pm + half, [2.0 * TABLE["mua"], 2.0 * TABLE["mus"]])
        return pm, psd
    lines = ["# EnKF spread against the exact grid posterior (constant scenario)", "",
             f"Command: `python validation/enkf_posterior.py --seeds "
             f"{' '.join(map(str, args.seeds))} --grid {args.grid}`", "",
             "Exact posterior: the filter's coarse model without model noise, constant "
             "parameters, uniform prior on [0.5, 2] x (1, 100), noise variance 0.01, on a "
             f"{args.grid} x {args.grid} grid refined around the peak until it resolves it. "
             "Filter: the paper defaults of `tissue-enkf paper constant` (N = 50), at t = 15 s.",
             "",
             "| seed | posterior mua | EnKF mua | posterior mus | EnKF mus |",
             "|---|---|---|---|---|"]
    errs, sds = [], []
    for seed in args.seeds:
        data = noisy_sensor(truth, seed)
        pm, psd = grid_posterior(data, np.array([0.5, 50.0]), np.array([2.0, 200.0]))
        s = run_experiment("constant", seed, progress=False).summary["parameters"]
        errs.append([s[k]["estimate_final"] - s[k]["truth_final"] for k in ("mua", "mus")])
        sds.append([s[k]["std_final"] for k in ("mua", "mus")])
        lines.append(f"| {seed} | {pm[0]:.4f} +- {psd[0]:.4f} | {s['mua']['estimate_final']:.4f} "
                     f"+- {s['mua']['std_final']:.4f} | {pm[1]:.2f} +- {psd[1]:.2f} | "
                     f"{s['mus']['estimate_final']:.2f} +- {s['mus']['std_final']:.2f} |")
        print(seed, pm, psd, flush=True)
    errs, sds = np.array(errs), np.array(sds)
    lines += ["", "Spread against error over the seeds (a calibrated filter has RMS error close "
              "to RMS spread):", "",
              "| parameter | RMS error | RMS spread |", "|---|---|---|"]
    for i, k in enumerate(("mua", "mus")):
        lines.append(f"| {k} | {np.sqrt(np.mean(errs[:, i] ** 2)):.4g} | "
                     f"{np.sqrt(np.mean(sds[:, i] ** 2)):.4g} |")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"report written to {args.out}")


if __name__ == "__main__":
    main()
