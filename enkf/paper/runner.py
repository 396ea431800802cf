"""One experiment of the paper end to end: truth, data, the filter, the summary, the files."""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mcmatlab_py.progress import Progress

from ..problem import DEFAULT_METHOD
from ..tissue.absorption import fill_prior_points
from ..tissue.estimates import persistence_summary
from ..tissue.identify import identify
from ..tissue.outputs import readable_stop, write_estimates_csv, write_json
from ..tissue.parameters import PARAMETER_NAMES, PARAMETER_UNITS, TRACKED_DEPTHS
from .figures import plot_data, plot_results
from .filters import emulator_for, filter_setup
from .scenarios import SCENARIOS, true_parameters
from .truth import Truth, TruthConfig, generate_truth, noisy_sensor, twin_truth

__all__ = ["PaperRun", "paper_advice", "run_experiment", "summarize", "write_run"]

@dataclass
class PaperRun:
    """One experiment: the truth, the data, the filter's estimates and the summary."""

    scenario: str
    truth: Truth
    data: np.ndarray
    estimates: object
    summary: dict


#: the advice of the filter's warnings in config keys, as the ``paper`` command says it
_PAPER_OPTIONS = (
    ('. Set [filter.drift] mode = "auto" to let the data decide',
     ". Run with --drift auto to let the data decide"),
    ("the drifting filters of [filter.drift]", "the drifting filters of --drift auto"),
)


def _clamp_advice(report: dict) -> str:
    """What to do about a clamp report (:meth:`TissueForwardModel.clamp_report`) in a paper
    run, whose emulator table and priors are the paper's (no filter.emulator keys)."""
    parts = []
    for name, table in report["table"].items():
        lo, hi = report["below_table"].get(name), report["above_table"].get(name)
        if lo is None and hi is None:
            continue
        side = " and ".join(f"{word} {edge:.4g}" for word, v, edge in
                            (("below", lo, table[0]), ("above", hi, table[1])) if v is not None)
        parts.append(f"members' {name} {side} {PARAMETER_UNITS[name]} were computed at the "
                     f"table's edge, which biases the {name} estimate towards it while they "
                     f"matter")
    ranges = ", ".join(f"{k} {list(v)}" for k, v in report["table"].items())
    return "; ".join(parts + [
        f"the paper's table ({ranges} cm^-1) and priors are fixed in `tissue-enkf paper` "
        "(--emulator-table sets only its number of points): --exact runs each member's own "
        "Monte Carlo instead (slow)"])


def paper_advice(message: str, clamped: dict | None = None) -> str:
    """``message``, a warning of the filter, with its advice put in what the ``paper``
    command can change: the clamp advice of ``clamped`` (``est.clamped``: one report, or
    one per filter of a drift bank) and [filter.drift] as --drift (the other config keys
    it names are the paper's and fixed)."""
    reports = [] if not clamped else [clamped] if "advice" in clamped else list(
        clamped.values())
    for r in reports:
        if r.get("advice") and r["advice"] in message:
            message = message.replace(r["advice"], _clamp_advice(r))
    for config, option in _PAPER_OPTIONS:
        message = message.replace(config, option)
    return message


def run_experiment(scenario: str, seed: int = 0, *, n_members: int = 50, method: str = DEFAULT_METHOD,
                   truth_config: TruthConfig | None = None, emulator_photons: int = 250_000,
                   emulator_table: int = 12, exact: bool = False, cache_dir=None,
                   progress: bool = True, twin: bool = False, client=None,
                   drift: str = "paper", **overrides) -> PaperRun:
    """Truth (cached), noisy data (``seed``), and the filter (``seed``) for one scenario.

    ``twin=True`` replaces the fine-grid truth by the filter's own coarse model at the
    true parameters (:func:`twin_truth`): the identical-twin experiment, free of model
    error. ``client`` (a ``dask.distributed`` client) spreads the emulator table, the
    constant truth's Monte Carlo and the exact mode's members over a cluster.
    ``drift``: ``"paper"`` (the scenario's own walk) or ``"auto"`` (a drift bank that
    tells from the data whether the optics drift; :func:`filter_setup`).
    ``overrides`` go to :class:`~enkf.tissue.TissueFilterSetup` (e.g. ``model_noise_std``).
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {SCENARIOS}, got {scenario!r}")
    t0 = time.perf_counter()
    tcfg = truth_config or TruthConfig(scenario=scenario)
    tcfg.scenario = scenario
    truth = generate_truth(tcfg, cache_dir=cache_dir, progress=progress, client=client)
    emu = emulator_for(n_photons=emulator_photons, progress=progress, cache_dir=cache_dir,
                       mc_grid=tcfg.grid, n_mua=emulator_table, n_mus=emulator_table,
                       client=client)
    if twin:
        truth = twin_truth(scenario, emu, truth, theta=overrides.get("theta"))
    data = noisy_sensor(truth, seed)
    absorption = emu
    if exact:
        from mcmatlab_py.emulator import DirectMonteCarloAbsorption

        absorption = DirectMonteCarloAbsorption(emu.spec, client=client)
    setup = filter_setup(scenario, absorption, seed=seed, n_members=n_members, method=method,
                         drift=drift, **overrides)
    fill_prior_points(setup)  # an on-demand emulator: the prior's points, outside the filter
    bar = Progress(len(truth.times) - 1, "filter", enabled=progress)
    n = len(truth.times) - 1

    def step(r):  # a drift bank's two filters one after the other
        bar.update(min(n, r.step) if r.component in (None, "still") else n)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")  # the outer filters decide when they are re-issued
        est = identify(setup, truth.times[1:], data[:, None], callback=step)
    bar.close()
    for w in caught:
        warnings.warn(paper_advice(str(w.message), est.clamped), w.category, stacklevel=2)
    summary = summarize(scenario, est, truth)
    summary["truth"] = {"grid": list(tcfg.grid), "mc_seed": tcfg.mc_seed,
                        "wall_seconds_when_computed": truth.wall_seconds,
                        "identical_twin": bool(twin)}
    summary["emulator"] = {"n_photons_per_point_at_mus_100": emu.spec.n_photons,
                           "table": [emu.spec.n_mua, emu.spec.n_mus],
                           "build_seconds": emu.build_seconds, "exact_mode": bool(exact)}
    summary["seed"] = seed
    # whether the innovations persist once the laser is off (docs/beyond.md), as identify's
    persistence = persistence_summary(est)
    if persistence["advice"]:
        persistence["advice"] = paper_advice(persistence["advice"])
    summary["innovation_persistence"] = persistence
    summary["wall_seconds"] = time.perf_counter() - t0
    return PaperRun(scenario, truth, data, est, summary)


def write_run(run: PaperRun, out_dir: Path) -> None:
    """estimates.csv, truth.csv, summary.json and figures/ of a run into ``out_dir``."""
    out_dir = Path(out_dir)
    (out_dir / "figures").mkdir(exist_ok=True)
    truth, data = run.truth, run.data
    write_estimates_csv(out_dir / "estimates.csv", run.estimates, truth, data)
    tp = true_parameters(run.scenario, truth.times)
    np.savetxt(out_dir / "truth.csv", np.column_stack(
        [truth.times, truth.temps, np.r_[np.nan, data], *[tp[k] for k in PARAMETER_NAMES]]),
        delimiter=",", comments="", fmt="%.8g",
        header="time_s,T_z0.0,T_z0.1,T_z0.2,sensor_data,mua,mus,VHC,TC")
    write_json(out_dir / "summary.json", run.summary)
    plot_results(out_dir / "figures" / "estimates.png", run.scenario, run.estimates, truth, data)
    plot_data(out_dir / "figures" / "data.png", run.scenario, truth, data)


def _over_steps(f, values: np.ndarray) -> float:
    """``f(mean(values))`` over the steps (``f`` None: the mean), NaN (null in
    summary.json) when the health check stopped the filter at its first step."""
    if not values.size:
        return float("nan")
    m = np.mean(values)
    return float(m if f is None else f(m))


def summarize(scenario: str, est, truth: Truth) -> dict:
    """The ``summary.json`` of a run: final errors, RMSE and coverage of the +-2 sd band."""
    # a filter stopped by its health check has NaN statistics at the failing step: the
    # metrics cover the steps before it, and "stopped" says when and why (identify's key)
    ok = np.all(np.isfinite(est.param_mean), axis=1) & np.all(np.isfinite(est.tracked_mean),
                                                               axis=1)
    k = int(np.argmin(ok)) if not ok.all() else len(est.times)
    params = {}
    tp = true_parameters(scenario, est.times[:k])
    for i, name in enumerate(est.names):
        mean, sd, tru = est.param_mean[:k, i], est.param_std[:k, i], tp[name]
        params[name] = {
            "truth_final": float(tru[-1]), "estimate_final": float(mean[-1]),
            "std_final": float(sd[-1]),
            "relative_error_final": float(abs(mean[-1] - tru[-1]) / tru[-1]),
            "rmse": _over_steps(np.sqrt, (mean[1:] - tru[1:]) ** 2),
            "coverage_2sd": _over_steps(None, np.abs(mean[1:] - tru[1:]) <= 2 * sd[1:]),
        }
        lo, hi = est.param_band(i)  # the members' 2.3-97.7% quantiles
        params[name]["band_final"] = [float(lo[k - 1]), float(hi[k - 1])]
        params[name]["band_covers_truth_final"] = bool(lo[k - 1] <= tru[-1] <= hi[k - 1])
    temps = {}
    for j, z in enumerate(TRACKED_DEPTHS):
        mean, sd = est.tracked_mean[1:k, j], est.tracked_std[1:k, j]
        tru = truth.temps[1:k, j]
        temps[f"z={z:.1f}"] = {
            "rmse": _over_steps(np.sqrt, (mean - tru) ** 2),
            "coverage_2sd": _over_steps(None, np.abs(mean - tru) <= 2 * sd),
            "truth_max": float(tru.max()) if tru.size else float("nan"),
        }
    lat = est.step_latency_s
    return {
        "scenario": scenario, "parameters": params, "temperatures": temps,
        "timing": {"filter_wall_s": est.filter_wall_s,
                   "step_latency_median_s": float(np.median(lat)),
                   "step_latency_max_s": float(np.max(lat)), "steps": int(len(lat)),
                   "ensemble_size": int(est.result.state_ensemble.shape[0])
                   if est.result is not None else None},
        "stopped": readable_stop(est.diverged, est.names),
        "final_time": float(est.times[k - 1]),
        **({} if est.drift_weight is None else {"drift": {
            "behaviour": est.drift_behaviour, "weight_final": float(est.drift_weight[k - 1])}}),
    }
