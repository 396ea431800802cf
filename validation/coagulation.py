"""Damage-driven optics against the random walk, on the same data.

Two filters read the same noisy surface sensor (10 Hz, variance 0.01 deg C^2):

* ``coagulation``: ``parameter_model = "coagulation"`` (enkf.tissue.coagulation): each
  member's optics move from native to coagulated values with its own Arrhenius damage;
  the native and coagulated mua, mus are estimated, with a walk of 0.005 per step;
* ``random_walk``: the project's filter for drifting optics (walk [0.03, 0.10] per step
  with the laser on, held still with it off), as ``enkf.paper.filter_setup("time-varying")``.

Both: N = 50, ETKF, the paper's coarse 20 x 20 x 10 model and priors, the structured
model error of ``identify`` (``--model-error white``: the paper's white noise), whose
relative sd grows for the damage-driven filter with each member's coagulated fraction F
(``Coagulation.mean_field_rel_std``, ``--mean-field-rel-std``); T_initial and the laser
of the case (enkf.paper.coagulation). The report opens with the damage-driven model at
the true optics against the fine truths (the mean field's error).

Cases (truths, enkf.paper.coagulation):

* ``damage, single pulse``: fine-grid truth whose voxels' optics follow their damage
  (MCmatlab's FD-dependent media re-run every 0.5 s); 37 deg C, 1.0 W for 5 s, 10 s off;
* ``damage, pulse train``: the same tissue, three 2 s pulses 3 s apart;
* ``damage, identical twin``: the damage-driven coarse model itself (no model error);
* ``ramp, paper``: the paper's prescribed ramp (0 deg C, 0.5 W, mua 1 -> 4, mus 100 ->
  500 over 5 s; no damage at all), identical twin;
* ``ramp, hot``: the single-pulse laser at 37 deg C with mua 1 -> 1.5, mus 100 -> 300
  linear over the pulse (the coagulated values on a schedule the damage does not set),
  identical twin.

Per run: RMSE of the (effective) mua and mus against the truth's over the run and while
the laser is on; the lag of mus while heating (the shift tau in [-2, 4] s that brings
the truth closest to the estimate, est(t) ~ truth(t - tau), RMS over the heating
steps; positive: the estimate lags); RMSE and +-2 sd coverage of the temperature at
z = 0.1 and 0.2 cm; the Brier score of the damage-risk map P(Omega > 1) at the 4,851
coarse nodes and 10 record times against the truth's damage there (as
validation/risk_calibration.py); and the summed innovation log-likelihood (the log
evidence of each model under the filter's Gaussian approximation), whose difference
decides which model the data prefer.

    python validation/coagulation.py [--seeds 0 1 ... 19] [--cases ...] [--n-members 50]
        [--model-error structured|white] [--mean-field-rel-std 0.25]

Writes validation/reports/coagulation.md (``--out``), its numbers as
validation/results/coagulation.json and, named after it, the figure of seed 0,
``*_seed0.png``: the optics of the single pulse and of the paper's ramp,
the temperatures beneath the sensor of the single pulse and of the pulse train.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from enkf.paper import emulator_for
from enkf.paper.coagulation import (
    A_TRUE,
    COAG_PULSES,
    E_TRUE,
    CoagulationTruthConfig,
    coagulation_setup,
    damage_truth,
    ramp_twin_truth,
    twin_damage_truth,
)
from enkf.tissue import Coagulation, TissueFilterSetup, identify
from enkf.tissue.risk import MCMATLAB_A, MCMATLAB_E, RiskTracker

sys.path.insert(0, str(Path(__file__).parent))
from risk_calibration import RECORD, THRESHOLD, reliability, truth_events  # noqa: E402

REPORTS = Path(__file__).parent / "reports"
CASES = ("damage, single pulse", "damage, pulse train", "damage, identical twin",
         "ramp, paper", "ramp, hot")
MODELS = ("coagulation", "random_walk")
SCENARIO = {"damage, single pulse": "coagulation", "damage, pulse train": "coagulation-train",
            "damage, identical twin": "coagulation", "ramp, paper": "time-varying",
            "ramp, hot": "hot-ramp"}
NOISE_VAR = 0.01
#: the structured model error's relative sd of a step's tendency (the setup's default)
BASE_REL = TissueFilterSetup.__dataclass_fields__["model_error_rel_std"].default


def make_truth(case: str, emu):
    sc = SCENARIO[case]
    if case.startswith("damage") and "twin" not in case:
        return damage_truth(CoagulationTruthConfig(scenario=sc), emu, progress=False)
    if "twin" in case:
        return twin_damage_truth(sc, emu)
    return ramp_twin_truth(sc, emu)


def heating(scenario: str, times: np.ndarray) -> np.ndarray:
    """(n,) bool: the laser is on during the step that ends at ``times``."""
    from enkf.paper.coagulation import laser

    p = laser(scenario).laser_power
    return np.array([p(t - 0.05) > 0 for t in times])


def lag(est: np.ndarray, tru: np.ndarray, times: np.ndarray, on: np.ndarray) -> float:
    """s: the shift tau minimizing the RMS of est(t) - truth(t - tau) over the heating."""
    taus = np.round(np.arange(-2.0, 4.0 + 1e-9, 0.1), 10)
    best, best_tau = np.inf, np.nan
    for tau in taus:
        shifted = np.interp(times[on] - tau, times, tru)
        r = np.sqrt(np.mean((est[on] - shifted) ** 2))
        if r < best - 1e-12:
            best, best_tau = r, tau
    return float(best_tau)


def run_one(case, truth, model, seed, emu, n_members, events, model_error="structured",
            mean_field_rel_std=None):
    sc = SCENARIO[case]
    rng = np.random.default_rng([seed, 20230101])
    data = truth.temps[1:, 0] + np.sqrt(NOISE_VAR) * rng.standard_normal(len(truth.times) - 1)
    kw = {}
    if model == "coagulation" and mean_field_rel_std is not None:
        kw["coagulation"] = Coagulation(E=E_TRUE, A=A_TRUE, mean_field_rel_std=mean_field_rel_std)
    setup = coagulation_setup(sc, emu, model, seed=seed, n_members=n_members,
                              model_error=model_error, **kw)
    tracker = RiskTracker(E=MCMATLAB_E, A=MCMATLAB_A, T_threshold=THRESHOLD,
                          record_times=list(RECORD))
    tic = time.perf_counter()
    est = identify(setup, truth.times[1:], data[:, None], callback=tracker)
    wall = time.perf_counter() - tic
    # a run stopped by the health check has NaN statistics at the failing step: the
    # metrics cover the steps before it (as enkf.paper.summarize)
    ok = np.all(np.isfinite(est.param_mean), axis=1) & np.all(np.isfinite(est.tracked_mean),
                                                               axis=1)
    k = int(np.argmin(ok)) if not ok.all() else len(est.times)
    optics = (est.effective_mean if est.effective_mean is not None else est.param_mean)[:k, :2]
    tru = truth.optics[:k]
    times = truth.times[:k]
    on = heating(sc, times)
    on[0] = False
    out = {"seed": seed, "wall_s": wall, "diverged": est.diverged, "final_time": float(times[-1]),
           "log_evidence": float(np.nansum(est.innovation_loglik[:k - 1])),
           "analysed": int(np.sum(est.analysed[:k - 1]))}
    for i, name in enumerate(("mua", "mus")):
        e = optics[1:, i] - tru[1:, i]
        out[f"rmse_{name}"] = float(np.sqrt(np.mean(e ** 2)))
        out[f"rmse_{name}_heating"] = float(np.sqrt(np.mean((optics[on, i] - tru[on, i]) ** 2)))
        out[f"final_{name}"] = float(optics[-1, i])
        out[f"final_{name}_truth"] = float(tru[-1, i])
    out["lag_mus_s"] = lag(optics[:, 1], tru[:, 1], times, on)
    if est.effective_mean is not None:
        out["theta_final"] = {n: float(est.param_mean[k - 1, i]) for i, n in enumerate(est.names)}
    for j, z in ((1, 0.1), (2, 0.2)):
        m, s = est.tracked_mean[1:k, j], est.tracked_std[1:k, j]
        t = truth.temps[1:k, j]
        out[f"T_rmse_z{z}"] = float(np.sqrt(np.mean((m - t) ** 2)))
        out[f"T_cover_z{z}"] = float(np.mean(np.abs(m - t) <= 2 * s))
    snaps = [s for s in tracker.snapshots if s.step < k]
    n = min(len(snaps), events["damage"].shape[0])
    p = np.concatenate([s.p_damage for s in snaps[:n]])
    o = events["damage"][:n].ravel().astype(float)
    out["brier"] = float(np.mean((p - o) ** 2))
    out["brier_events"] = int(o.sum())
    out["brier_n"] = int(o.size)
    out["reliability"] = [[lab, n, pm, of] for lab, n, pm, of in reliability(p, o)]
    return out, est


def pooled_reliability(rows: list[dict]) -> list[tuple]:
    """(label, count, mean forecast, observed frequency) over the runs' bins."""
    runs = [r["reliability"] for r in rows if "reliability" in r]
    out = []
    for k, (lab, *_rest) in enumerate(runs[0] if runs else []):
        n = sum(run[k][1] for run in runs)
        pm = sum(run[k][1] * run[k][2] for run in runs if run[k][1]) / n if n else np.nan
        of = sum(run[k][1] * run[k][3] for run in runs if run[k][1]) / n if n else np.nan
        out.append((lab, n, pm, of))
    return out


def summarize(rows: list[dict]) -> dict:
    keys = [k for k, v in rows[0].items() if isinstance(v, float) and k not in ("wall_s",)]
    return {k: (float(np.nanmean([r[k] for r in rows])), float(np.nanmedian([r[k] for r in rows])))
            for k in keys}


def plot_optics(axes, case, truth, ests) -> None:
    """mua and mus (a pair of axes) with each filter's band against the truth's."""
    for ax, i, name in ((axes[0], 0, "mua"), (axes[1], 1, "mus")):
        ax.plot(truth.times, truth.optics[:, i], "k-", lw=2, label="truth (effective)")
        for model, est in ests.items():
            if est.effective_mean is not None:  # a log-normal band of the effective optics
                m, s = est.effective_mean[:, i], est.effective_std[:, i]
                with np.errstate(invalid="ignore", divide="ignore"):
                    s2 = np.log1p((s / m) ** 2)
                    mu = np.log(m) - 0.5 * s2
                    lo, hi = np.exp(mu - 2 * np.sqrt(s2)), np.exp(mu + 2 * np.sqrt(s2))
            else:  # the members' 2.3 and 97.7 % quantiles (positive, like the members)
                m = est.param_mean[:, i]
                lo, hi = est.param_band(i)
            ax.plot(est.times, m, label=model)
            ax.fill_between(est.times, lo, hi, alpha=0.2)
        ax.set(xlabel="time [s]", ylabel=f"{name} [cm$^{{-1}}$]", title=f"{case}, seed 0")
        ax.legend(fontsize=8)


def plot_temps(axes, case, truth, ests) -> None:
    """The temperature at 0.1 and 0.2 cm with each filter's +-2 sd band against the truth."""
    for ax, j, z in ((axes[0], 1, 0.1), (axes[1], 2, 0.2)):
        ax.plot(truth.times, truth.temps[:, j], "k-", lw=2, label="truth")
        for model, est in ests.items():
            m, sd = est.tracked_mean[:, j], est.tracked_std[:, j]
            ax.plot(est.times, m, label=f"{model} (+-2 sd)")
            ax.fill_between(est.times, m - 2 * sd, m + 2 * sd, alpha=0.2)
        ax.set(xlabel="time [s]", ylabel="temperature [deg C]", title=f"{case}, seed 0, "
               f"z = {z} cm (no sensor)")
        ax.legend(fontsize=8)


def plot_seed0(path, truths: dict, first: dict) -> bool:
    """One figure of seed 0, a row per panel pair: the optics of the single pulse and of the
    paper's ramp, the temperatures beneath the sensor of the single pulse and of the train.
    False (nothing written) when none of these cases ran."""
    rows = [(plot, case) for plot, case in
            ((plot_optics, "damage, single pulse"), (plot_optics, "ramp, paper"),
             (plot_temps, "damage, single pulse"), (plot_temps, "damage, pulse train"))
            if case in first]
    if not rows:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(rows), 2, figsize=(10, 3.6 * len(rows)),
                             constrained_layout=True, squeeze=False)
    for ax_pair, (plot, case) in zip(axes, rows, strict=True):
        plot(ax_pair, case, truths[case], first[case])
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(20)))
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    ap.add_argument("--n-members", type=int, default=50)
    ap.add_argument("--model-error", default="structured", choices=("white", "structured"),
                    help="both filters' model error (enkf.tissue.model_error)")
    ap.add_argument("--mean-field-rel-std", type=float, default=None,
                    help="the damage-driven filter's Coagulation.mean_field_rel_std (default: "
                    f"its default, {Coagulation().mean_field_rel_std}; 0: off)")
    ap.add_argument("--out", default=str(REPORTS / "coagulation.md"))
    ap.add_argument("--resume", help="a coagulation.json of an earlier run with the same seeds: "
                    "its cases are kept (not recomputed) unless named in --recompute")
    ap.add_argument("--recompute", nargs="*", default=[], choices=CASES)
    args = ap.parse_args(argv)
    tic = time.perf_counter()
    emu = emulator_for(progress=False)
    results, truths, first = {}, {}, {}
    old = {}
    if args.resume:
        prev = json.loads(Path(args.resume).read_text())
        if prev["seeds"] != args.seeds or prev.get("model_error", "white") != args.model_error \
                or prev.get("mean_field_rel_std") != args.mean_field_rel_std:
            raise SystemExit(f"{args.resume}: other seeds or model error than this run")
        old = {c: r for c, r in prev["results"].items() if c not in args.recompute}
    for case in args.cases:
        truth = make_truth(case, emu)
        truths[case] = truth
        if case in old:
            results[case] = old[case]
            continue
        events = truth_events(truth.times, truth.nodes)
        results[case] = {m: [] for m in MODELS}
        for seed in args.seeds:
            for model in MODELS:
                r, est = run_one(case, truth, model, seed, emu, args.n_members, events,
                                 args.model_error, args.mean_field_rel_std)
                results[case][model].append(r)
                if seed == args.seeds[0]:
                    first.setdefault(case, {})[model] = est
                print(f"{case} seed {seed} {model}: mua rmse {r['rmse_mua']:.3f}, mus rmse "
                      f"{r['rmse_mus']:.1f}, lag {r['lag_mus_s']:+.1f} s, T cover "
                      f"{r['T_cover_z0.1']:.2f}/{r['T_cover_z0.2']:.2f}, Brier {r['brier']:.5f}"
                      f", log ev {r['log_evidence']:.1f}, {r['wall_s']:.1f} s"
                      + (f", stopped: {r['diverged']}" if r["diverged"] else ""), flush=True)
    wall = time.perf_counter() - tic
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    from reporting import results_path

    results_path(out).write_text(json.dumps(
        {"seeds": args.seeds, "n_members": args.n_members, "wall_s": wall,
         "model_error": args.model_error, "mean_field_rel_std": args.mean_field_rel_std,
         "results": results}, indent=1, default=float) + "\n")
    figure = out.with_name(f"{out.stem}_seed0.png")
    if not plot_seed0(figure, truths, first):
        figure = None
    write_report(out, args, results, truths, wall, figure)


def write_report(out: Path, args, results: dict, truths: dict, wall: float,
                 figure: Path | None = None) -> None:
    runs_wall = sum(r["wall_s"] for res in results.values() for rows in res.values()
                    for r in rows)
    cmd = "python validation/coagulation.py --seeds " + " ".join(map(str, args.seeds))
    if list(args.cases) != list(CASES):
        cmd += " --cases " + " ".join(f'"{c}"' for c in args.cases)
    if args.n_members != 50:
        cmd += f" --n-members {args.n_members}"
    if args.model_error != "structured":
        cmd += f" --model-error {args.model_error}"
    if args.mean_field_rel_std is not None:
        cmd += f" --mean-field-rel-std {args.mean_field_rel_std:g}"
    mf = (Coagulation().mean_field_rel_std if args.mean_field_rel_std is None
          else args.mean_field_rel_std)
    me = (f"the structured model error (its relative sd {BASE_REL:g} + {mf:g} sqrt(F) for the "
          "damage-driven filter, F its coagulated fraction)" if args.model_error == "structured"
          else "the white model error")
    L = ["# Damage-driven optics against the random walk", "",
         f"Command: `{cmd}` ({len(args.seeds)} seeds; the filter runs took {runs_wall:.0f} s "
         "in all on the shared 2-core machine, the cached truths not counted).", "",
         f"Filters (the same data, N = {args.n_members}, ETKF, the paper's coarse model and "
         f"priors, {me}): **coagulation** = optics driven by each "
         "member's Arrhenius damage, native and coagulated mua, mus estimated (walk 0.005 "
         "per step); **random_walk** = "
         "the project's walk for drifting optics, [0.03, 0.10] per step with the laser on."
         , "",
         "The damage truths have no single (mua, mus): the numbers compare with the "
         "*effective* optics, native + F (coagulated - native), F the coagulated fraction of "
         "the truth's damage at the filter's nodes weighted as the filter weighs it (the "
         "square of the native absorbed power; enkf.paper.coagulation). Lag: the shift tau "
         "(s) in [-2, 4] with est(t) closest to truth(t - tau) while the laser is on "
         "(positive: behind; at -2 no shift brings them together: the estimate stays "
         "above). Brier: P(Omega > 1) at 4,851 nodes x 10 times against the truth's "
         "damage. Log evidence: the sum of the innovations' log-likelihood over the 150 "
         "readings. Numbers: mean over seeds (median in brackets).", ""]
    L += mean_field_section(truths, mf)
    for case, res in results.items():
        tr = truths[case]
        sc = SCENARIO[case]
        P, on, off, n = COAG_PULSES[sc]
        L += [f"## {case}", "",
              f"Laser {P:g} W, {n} x ({on:g} s on, {off:g} s off); truth: {tr.kind}"
              + (f" (computed in {tr.wall_seconds:.0f} s, {tr.mc_runs} Monte Carlo runs)"
                 if tr.kind == "damage" else "")
              + f"; surface max {tr.temps[:, 0].max():.1f} deg C; effective mua "
              f"{tr.optics[0, 0]:.2f} -> {tr.optics[-1, 0]:.2f}, mus {tr.optics[0, 1]:.0f} -> "
              f"{tr.optics[-1, 1]:.0f} cm^-1" + (f" (F at the end {tr.F[-1]:.2f})"
                                                  if tr.F[-1] > 0 else "") + ".", "",
              "| metric | coagulation | random_walk |", "|---|---|---|"]
        s = {m: summarize(res[m]) for m in MODELS}
        rows = [("RMSE mua (cm^-1)", "rmse_mua", 3), ("RMSE mus (cm^-1)", "rmse_mus", 1),
                ("RMSE mua while heating", "rmse_mua_heating", 3),
                ("RMSE mus while heating", "rmse_mus_heating", 1),
                ("lag of mus while heating (s)", "lag_mus_s", 2),
                (f"final mus (truth {tr.optics[-1, 1]:.0f})", "final_mus", 1),
                ("T RMSE z = 0.1 cm (deg C)", "T_rmse_z0.1", 3),
                ("T RMSE z = 0.2 cm (deg C)", "T_rmse_z0.2", 3),
                ("T +-2 sd coverage z = 0.1 cm", "T_cover_z0.1", 2),
                ("T +-2 sd coverage z = 0.2 cm", "T_cover_z0.2", 2),
                ("Brier P(Omega > 1)", "brier", 5), ("log evidence", "log_evidence", 1)]
        for label, key, d in rows:
            L.append(f"| {label} | " + " | ".join(
                f"{s[m][key][0]:.{d}f} ({s[m][key][1]:.{d}f})" for m in MODELS) + " |")
        nd = {m: sum(r["diverged"] is not None for r in res[m]) for m in MODELS}
        # a run stopped by the health check loses the comparison (its sum is over fewer
        # readings); the factor is over the seeds where both ran to the end
        pairs = list(zip(res["coagulation"], res["random_walk"], strict=True))
        both = [(a, b) for a, b in pairs if a["diverged"] is None and b["diverged"] is None]
        wins = sum(b["diverged"] is not None and a["diverged"] is None for a, b in pairs) + sum(
            a["log_evidence"] > b["log_evidence"] for a, b in both)
        diff = np.array([a["log_evidence"] - b["log_evidence"] for a, b in both])
        L += ["", f"Stopped by the health check: coagulation {nd['coagulation']}, random_walk "
              f"{nd['random_walk']} of {len(pairs)} (their metrics cover the steps before the "
              f"stop). The log evidence favours the damage-driven model on {wins} of "
              f"{len(pairs)} seeds (a stopped run loses)"
              + (f"; log Bayes factor where both ran to the end: mean {diff.mean():+.1f}, "
                 f"range {diff.min():+.1f} to {diff.max():+.1f} ({diff.size} seeds)."
                 if diff.size else ".")]
        tables = {m: pooled_reliability(res[m]) for m in MODELS}
        if all(tables.values()):
            L += ["", "Reliability of P(Omega > 1), pooled over the seeds (node-times; mean "
                  "forecast; observed frequency of the truth's damage):", "",
                  "| forecast | coagulation: n | mean | observed | random_walk: n | mean | "
                  "observed |", "|---|---|---|---|---|---|---|"]
            for a, b in zip(tables["coagulation"], tables["random_walk"], strict=True):
                if a[1] or b[1]:
                    L.append(f"| {a[0]} | " + " | ".join(
                        f"{r[1]} | {r[2]:.3f} | {r[3]:.3f}" if r[1] else "0 | - | -"
                        for r in (a, b)) + " |")
            L.append("")
        th = [r.get("theta_final") for r in res["coagulation"] if r.get("theta_final")]
        if th:
            L.append("Damage-driven estimates at the end (mean over seeds): " + ", ".join(
                f"{k} {np.mean([t[k] for t in th]):.3g}" for k in th[0]) + " (truth: mua 1, "
                "mus 100, mua_coag 1.5, mus_coag 300 for the damage truths).")
        L.append("")
    L += summary_section(results)
    if figure is not None:
        L += [f"![seed 0: the optics and the temperatures beneath the sensor]({figure.name})",
              ""]
    out.write_text("\n".join(L) + "\n")
    print(f"report: {out}")


def mean_field_section(truths: dict, mf: float) -> list[str]:
    """The damage-driven coarse model at the true optics against each fine damage truth: the
    relative error of the temperature rise, and the structured model error's relative sd
    with ``mean_field_rel_std = mf``."""
    fine = {c: t for c, t in truths.items() if t.kind == "damage"}
    if not fine:
        return []
    emu = emulator_for(progress=False)
    L = ["## The mean field at the true optics", "",
         "The damage-driven filter's coarse model run at the true native and coagulated "
         "optics (the identical twin) against the fine truth whose voxels coagulate on their "
         "own: the relative error of the temperature rise above the start, model / truth - 1, "
         "at the three tracked depths, with the truth's coagulated fraction F and the "
         f"structured model error's relative sd for that F ({BASE_REL:g} + "
         f"{mf:g} sqrt(F), `Coagulation.mean_field_rel_std`).", "",
         "| case | t (s) | F | rise truth z = 0 / 0.1 / 0.2 cm (deg C) | error of the rise | "
         "model error sd |", "|---|---|---|---|---|---|"]
    for case, tr in fine.items():
        twin = twin_damage_truth(SCENARIO[case], emu, tr.times)
        T0 = tr.temps[0]
        for t in (1.0, 3.0, 5.0, 7.0, 10.0, 15.0):
            i = int(np.argmin(np.abs(tr.times - t)))
            rise, model_rise = tr.temps[i] - T0, twin.temps[i] - T0
            err = model_rise / rise - 1
            L.append(f"| {case} | {tr.times[i]:g} | {tr.F[i]:.2f} | "
                     + " / ".join(f"{v:.1f}" for v in rise) + " | "
                     + " / ".join(f"{v:+.0%}" for v in err) + " | "
                     f"{BASE_REL + mf * np.sqrt(tr.F[i]):.2f} |")
    L += ["", "The tracked depths read the error of the whole step's tendency, which the "
          "structured model error perturbs (enkf.tissue.model_error); the mean field's "
          "error grows fast with the first coagulated layer and less after, hence sqrt(F).",
          ""]
    return L


def summary_section(results: dict) -> list[str]:
    """Which model each case's numbers favour, and whether the evidence picks it."""
    L = ["## Summary and recommendation", "",
         "| case | lower mus RMSE | lower mua RMSE | lower Brier | higher T coverage (0.1 cm) | "
         "evidence favours coagulation on |", "|---|---|---|---|---|---|"]
    for case, res in results.items():
        s = {m: summarize(res[m]) for m in MODELS}

        def better(key, low=True, s=s):
            a, b = s["coagulation"][key][0], s["random_walk"][key][0]
            if not (np.isfinite(a) and np.isfinite(b)):
                return "coagulation stopped" if not np.isfinite(a) else "random_walk stopped"
            return MODELS[0] if (a < b) == low else MODELS[1]

        pairs = list(zip(res["coagulation"], res["random_walk"], strict=True))
        wins = sum((b["diverged"] is not None and a["diverged"] is None)
                   or (a["diverged"] is None and b["diverged"] is None
                       and a["log_evidence"] > b["log_evidence"]) for a, b in pairs)
        L.append(f"| {case} | {better('rmse_mus')} | {better('rmse_mua')} | {better('brier')} | "
                 f"{better('T_cover_z0.1', low=False)} | {wins} of {len(pairs)} seeds |")
    L += ["", "Recommendation (what `identify` users should do when they do not know whether "
          "the optics follow the damage; docs/coagulation.md): run both models on the same "
          "data and compare `innovation_loglik.sum` in the two `summary.json` files, with "
          "the same model error for both: the damage-driven run with "
          "`[filter.coagulation] mean_field_rel_std = 0` (`--mean-field-rel-std 0` here). "
          "The mean-field term widens the damage-driven "
          "forecasts where the truth coagulates as a layer, and that costs it evidence "
          "wherever the surface reading does not need it (on the identical twin above all): "
          "the evidence measures the fit to the surface sensor only, and a surface sensor "
          "does not see the error beneath it. With the same model error the evidence picked "
          "the damage-driven model on every identical-twin seed and the walk on every ramp "
          "seed; on the fine-grid truths, which neither model represents, it is mixed. Once "
          "the damage-driven model is chosen, keep `mean_field_rel_std` at its default for "
          "the estimates, their bands and the damage-risk map: without it the bands "
          "beneath the surface are too narrow on the fine-grid truths.", ""]
    return L


if __name__ == "__main__":
    main()
