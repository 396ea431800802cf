"""The paper's three experiments over several seeds, checked against the targets.

Targets: constant: mua within 5% and mus within 25 cm^-1 at t = 15 s; time-varying:
mua RMSE <= 0.3 cm^-1, mus within 10% at t = 15 s; all-params: each of the four within
10% at t = 15 s; temperature coverage of the +-2 sd band >= 0.9 at all three depths;
filter <= 15 s wall and no step above 100 ms. Writes validation/reports/paper_runs.md.

With ``--twin`` every experiment is run a second time on identical-twin data (the
filter's own coarse model at the true parameters, no model error): where a target is
met on the twin and missed on the fine truth, the coarse model is what misses it.

    python validation/paper_runs.py [--seeds 0 1 ... 19] [--scenarios constant ...] [--twin]
        [--drift auto]

``--drift auto`` runs identify's drift bank (a still and drifting filters weighed by the
data) in place of each scenario's own walk.

Twenty seeds by default: with five, a pass count moves by one or two seeds when only the
random numbers change (seeds 0-4 alone can meet a target that 20 seeds miss).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from enkf.paper import SCENARIOS, TruthConfig, run_experiment

DEFAULT_OUT = str(Path(__file__).parent / "reports" / "paper_runs.md")


def checks(s: dict) -> dict[str, bool]:
    p, sc = s["parameters"], s["scenario"]
    out = {}
    if sc == "constant":
        out["mua within 5%"] = p["mua"]["relative_error_final"] <= 0.05
        out["mus within 25/cm"] = abs(p["mus"]["estimate_final"] - p["mus"]["truth_final"]) <= 25
    elif sc in ("time-varying", "pulse-train"):
        out["mua rmse <= 0.3"] = p["mua"]["rmse"] <= 0.3
        out["mus within 10%"] = p["mus"]["relative_error_final"] <= 0.10
    else:
        for k in ("mua", "mus", "VHC", "TC"):
            out[f"{k} within 10%"] = p[k]["relative_error_final"] <= 0.10
    for k, v in p.items():
        out[f"{k} band holds the truth at 15 s"] = v["band_covers_truth_final"]
    for z, t in s["temperatures"].items():
        out[f"coverage {z} >= 0.9"] = t["coverage_2sd"] >= 0.9
    out["every coverage target"] = all(t["coverage_2sd"] >= 0.9 for t in s["temperatures"].values()) \
        and all(v["band_covers_truth_final"] for v in p.values())
    out["ran to t = 15 s"] = not s["stopped"]
    out["filter <= 15 s"] = s["timing"]["filter_wall_s"] <= 15
    out["max step <= 100 ms"] = s["timing"]["step_latency_max_s"] <= 0.1
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(20)))
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=SCENARIOS)
    ap.add_argument("--twin", action="store_true", help="also run identical-twin experiments")
    ap.add_argument("--theta", type=float, default=None,
                    help="the filter's (and the twin's) time scheme, TissueFilterSetup.theta "
                         "(default: its default, Crank-Nicolson; 1: backward Euler)")
    ap.add_argument("--truth-theta", type=float, default=None,
                    help="the fine truth's, TruthConfig.heat_theta (default: its default)")
    ap.add_argument("--drift", choices=("paper", "auto"), default="paper",
                    help="the scenarios' own walks (default) or the drift bank of identify")
    ap.add_argument("--out", default=DEFAULT_OUT)
    args = ap.parse_args(argv)
    lines = ["# The paper's experiments over several seeds", "",
             f"Command: `python validation/paper_runs.py --seeds {' '.join(map(str, args.seeds))}"
             f"{' --twin' if args.twin else ''}"
             + ("" if args.theta is None else f" --theta {args.theta:g}")
             + ("" if args.truth_theta is None else f" --truth-theta {args.truth_theta:g}")
             + ("" if args.drift == "paper" else f" --drift {args.drift}")
             + ("" if args.out == DEFAULT_OUT else f" --out {args.out}") + "`",
             "", "Fine-grid truth 100 x 100 x 50 (cached), filter N = 50 on 20 x 20 x 10 with the "
             "emulator. The seed sets the sensor noise and the filter's random numbers.", ""]
    kw = {} if args.theta is None else {"theta": args.theta}
    kw["drift"] = args.drift
    if args.truth_theta is not None:
        kw["truth_config"] = TruthConfig(heat_theta=args.truth_theta)
    runs = [(sc, False) for sc in args.scenarios]
    if args.twin:
        runs += [(sc, True) for sc in args.scenarios]
    all_passed = True
    for sc, twin in runs:
        note = " (identical twin: data from the coarse model, no model error)" if twin else ""
        lines += [f"## {sc}{note}", ""]
        rows, passed = [], {}
        for seed in args.seeds:
            s = run_experiment(sc, seed, progress=False, twin=twin, **kw).summary
            c = checks(s)
            for k, v in c.items():
                passed.setdefault(k, []).append(v)
            par = ", ".join(f"{k} {v['estimate_final']:.4g}+-{v['std_final']:.2g} "
                            f"({100 * v['relative_error_final']:.1f}%)"
                            for k, v in s["parameters"].items())
            if "drift" in s:
                par += f"; P(drift) {s['drift']['weight_final']:.3g}"
            temps = ", ".join(f"{z}: rmse {t['rmse']:.2f}, cov {t['coverage_2sd']:.2f}"
                              for z, t in s["temperatures"].items())
            tm = s["timing"]
            stop = f" **stopped: {s['stopped']}**" if s["stopped"] else ""
            rows.append(f"| {seed} | {par}{stop} | {temps} | {tm['filter_wall_s']:.1f} s, max step "
                        f"{1e3 * tm['step_latency_max_s']:.0f} ms |")
            print(sc, "twin" if twin else "fine", seed, par, temps, flush=True)
        lines += ["| seed | parameters at the end (rel. error) | temperatures | filter |",
                  "|---|---|---|---|", *rows, "", "| target | seeds passing |", "|---|---|"]
        lines += [f"| {k} | {sum(v)}/{len(v)} |" for k, v in passed.items()]
        lines.append("")
        if not twin:
            all_passed = all_passed and all(np.all(v) for v in passed.values())
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"report written to {args.out}")
    return 0 if all_passed else 1


if __name__ == "__main__":
    raise SystemExit(main())
