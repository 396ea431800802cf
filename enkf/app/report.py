"""What a run writes: estimates, figures, volume fields and the run.json manifest (an edge module)."""

from __future__ import annotations

import platform
import sys
import time
from pathlib import Path

import numpy as np

from ..tissue.estimates import persistence_summary
from ..tissue.outputs import readable_stop
from ..tissue.parameters import ABSORPTION_INPUTS, PARAMETER_LABELS
from .rundir import write_json

__all__ = ["manifest", "plot_identification", "write_identify_outputs"]


def _versions() -> dict:
    import importlib.metadata as md

    out = {"python": platform.python_version()}
    for pkg in ("tissue-enkf", "numpy", "scipy", "numba", "scikit-fem", "meshio", "matplotlib",
                "dask"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = None
    return out


#: the command line of this run (set by enkf.cli.main; default sys.argv)
command_line: list[str] | None = None


def manifest(path: Path, *, command: str, config: dict | None, seed, timings: dict,
             extra: dict | None = None) -> None:
    """``run.json``: the full resolved config, versions, seed, timings (s), command line."""
    argv = command_line if command_line is not None else sys.argv
    write_json(path, {"command": command, "argv": argv, "config": config, "seed": seed,
                      "versions": _versions(), "timings_s": timings,
                      "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **(extra or {})})


def plot_identification(path, est, times, data, power, data_column: int = 0,
                        data_label: str = "data (first column)",
                        persistence: dict | None = None, advice: list | None = None) -> None:
    """Temperature tracks (top, with ``data[:, data_column]`` beside the first tracked
    point, labelled ``data_label``) and parameters (bottom); a caution above them when
    ``persistence`` (:func:`~enkf.tissue.estimates.persistence_summary`) is flagged; with
    ``advice`` (:class:`~enkf.tissue.advice.AdviceRow` per reading) a panel of when the
    target is coagulated and the risks (:func:`~enkf.tissue.advice.plot_advice`).

    Temperature bands are mean +- 2 sd; parameter bands are the ensemble's 2.3 % and 97.7 %
    quantiles (positive, like the members: the filter works on log parameters, where a
    mean +- 2 sd in linear units can reach below zero)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = est.times
    drift = getattr(est, "drift_weight", None)
    n_tr, n_par = est.tracked_mean.shape[1], len(est.names)
    n_bottom = n_par + (drift is not None) + bool(advice)
    cols = max(n_tr, n_bottom)
    fig = plt.figure(figsize=(4.2 * cols, 7.5), constrained_layout=True)
    top, bottom = fig.subfigures(2, 1)
    # each row as wide as it needs: no empty panel when there are fewer parameters
    axes_t = np.atleast_1d(top.subplots(1, n_tr, squeeze=False)[0])
    axes_p = np.atleast_1d(bottom.subplots(1, n_bottom, squeeze=False)[0])
    method = {"etkf": "ETKF", "enkf": "EnKF"}.get(getattr(est, "method", None) or "", "filter")
    on = np.array([power(x) > 0 for x in t])
    restarts = [r["time_s"] for r in getattr(est, "restarts", ())]
    for ax in list(axes_t) + list(axes_p):  # laser on: shaded; restarts: dashed
        for a, b in _runs(t, on):
            ax.axvspan(a, b, color="0.88", lw=0)
        for k, tr in enumerate(restarts):
            ax.axvline(tr, color="b", ls="--", lw=0.9,
                       label="restart from the smoother" if k == 0 and ax is axes_p[0] else None)
    for j in range(n_tr):
        ax = axes_t[j]
        m, s = est.tracked_mean[:, j], est.tracked_std[:, j]
        if j == 0 and data is not None and data.shape[1]:
            ax.plot(times, data[:, data_column], "k.", ms=2.5, label=data_label)
        ax.plot(t, m, "r-", lw=1.4, label=f"{method} mean")
        ax.fill_between(t, m - 2 * s, m + 2 * s, color="r", alpha=0.15, lw=0, label="$\\pm 2$ sd")
        x, y, z = est.tracked_positions[j]
        ax.set(title=f"T at ({x:g}, {y:g}, {z:g}) cm", xlabel="time [s]", ylabel="T [$^\\circ$C]")
        if j == 0:
            ax.legend(fontsize=8)
    for i, name in enumerate(est.names):
        ax = axes_p[i]
        m = est.param_mean[:, i]
        lo, hi = est.param_band(i) if hasattr(est, "param_band") else (
            m - 2 * est.param_std[:, i], m + 2 * est.param_std[:, i])
        ax.plot(t, m, "r-", lw=1.4, label=f"{method} mean")
        ax.fill_between(t, lo, hi, color="r", alpha=0.15, lw=0, label="2.3-97.7 % of members")
        ax.set(title=f"{name} [{PARAMETER_LABELS.get(name, '')}]", xlabel="time [s]")
        if i == 0:
            ax.legend(fontsize=8)
    if drift is not None:  # the bank: which behaviour of the optics the data support
        ax = axes_p[n_par]
        ax.plot(t[: len(drift)], drift, "k-", lw=1.4)
        ax.axhline(0.5, color="0.5", lw=0.8, ls=":")
        ax.set(title="P(optics drift while heated)", xlabel="time [s]", ylim=(-0.03, 1.03))
        ax.text(0.98, 0.04, "still" if drift[-1] < 0.5 else "drifting",
                transform=ax.transAxes, ha="right", va="bottom", fontsize=9)
    if advice:  # how long to keep the laser on
        from ..tissue.advice import plot_advice

        plot_advice(axes_p[-1], advice)
    # a model that misses the data's physics: said where the bands are drawn
    if persistence is not None and persistence["flagged"]:
        fig.suptitle(f"Caution: the innovations persist while the laser is off (lag-1 "
                     f"{persistence['laser_off']:.2f}):\nthe model misses something the data show, "
                     "and the bands below the surface may be too narrow (summary.json)",
                     color="firebrick", fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def drift_summary(est, k: int | None = None) -> dict:
    """summary.json's ``drift``: with a drift bank (:class:`enkf.tissue.drift.DriftBank`),
    the probability that the optics drift at the end (``weight_final``; at row ``k``),
    when it first passed 0.5 and its largest value, the behaviour the data support, and
    each filter's final estimates and log evidence."""
    k = len(est.times) - 1 if k is None else k
    w = est.drift_weight
    over = np.flatnonzero(w > 0.5)
    comps = {}
    for name, e in (est.components or {}).items():
        j = len(e.times) - (2 if e.diverged and len(e.times) > 1 else 1)
        comps[name] = {
            "parameters": {n: {"estimate_final": float(e.param_mean[j, i]),
                               "std_final": float(e.param_std[j, i])}
                           for i, n in enumerate(e.names)},
            "weight_final": float(est.component_weights[name][k]),
            "log_evidence": e.log_evidence(), "stopped": e.diverged,
            "smoother_restarts": len(e.restarts)}
    return {"behaviour": "drifting" if w[k] >= 0.5 else "still",
            "weight_final": float(w[k]), "weight_max": float(w.max()),
            "first_over_half_s": float(est.times[over[0]]) if over.size else None,
            "components": comps}


def _runs(t, on):
    out, start = [], None
    for x, o in zip(t, on, strict=True):
        if o and start is None:
            start = x
        if not o and start is not None:
            out.append((start, x))
            start = None
    if start is not None:
        out.append((start, t[-1]))
    return out


def _data_beside_first_point(setup) -> tuple[int, str]:
    """The data column drawn beside the first tracked point, and its label: the first
    sensor; with a camera alone, the pixel whose centre is nearest the point."""
    n_sensors = setup.sensors.positions.shape[0]
    if n_sensors or setup.sensors.image is None or not len(setup.sensors.tracked):
        return 0, "data (first sensor)" if n_sensors else "data (first column)"
    centres = setup.sensors.image.pixel_centers()[:, :2]
    k = int(np.argmin(np.hypot(*(centres - setup.sensors.tracked[0][:2]).T)))
    x, y = centres[k]
    return n_sensors + k, f"data (pixel at {x:.3g}, {y:.3g} cm)"


def write_identify_outputs(out: Path, setup, est, times, data, *, absorption=None,
                           risk=None, media: dict | None = None, advisor=None) -> dict:
    """estimates.csv, summary.json, figures/estimates.png, fields/final.vtu into ``out``.

    ``advisor``: an :class:`enkf.tissue.advice.Advisor` that followed the run: its advice
    at each reading into advice.csv, summary.json's ``advice`` and a panel of the figure.

    ``media``: ``{parameter: medium name}`` (several media), written into summary.json.
    ``risk``: an :class:`enkf.risk.RiskTracker` that followed the run (media with E, A):
    its last fields go into final.vtu (``p_damage``, ``p_T_above_60C``, ``p_T_ever_above_60C``,
    ``damage_Omega_mean``), its series into fields/risk.pvd, a depth map into figures/.
    """
    import fem

    from ..tissue.outputs import write_estimates_csv

    out = Path(out)
    (out / "figures").mkdir(exist_ok=True)
    (out / "fields").mkdir(exist_ok=True)
    write_estimates_csv(out / "estimates.csv", est)
    advice = None if advisor is None else advisor.table(est)
    if advice:
        from ..tissue.outputs import write_advice_csv

        write_advice_csv(out / "advice.csv", advice, advisor.quantiles)
    # "final": the last step the health check accepted (when it stopped the run, the
    # rejected step is the last row of estimates.csv and summary["rejected"])
    k = len(est.times) - (2 if est.diverged and len(est.times) > 1 else 1)
    persistence = persistence_summary(est)
    plot_identification(out / "figures" / "estimates.png", est, times, data, setup.power,
                        *_data_beside_first_point(setup), persistence=persistence,
                        advice=advice)
    summary = {
        "parameters": {n: {"estimate_final": float(est.param_mean[k, i]),
                           "std_final": float(est.param_std[k, i]),
                           **({"medium": media[n]} if n in (media or {}) else {})}
                       for i, n in enumerate(est.names)},
        "tracked": [{"position_cm": [float(v) for v in est.tracked_positions[j]],
                     "T_final": float(est.tracked_mean[k, j]),
                     "std_final": float(est.tracked_std[k, j])}
                    for j in range(est.tracked_mean.shape[1])],
        "steps": int(len(est.times) - 1), "analysed": int(np.sum(est.analysed)),
        "stopped": readable_stop(est.diverged, est.names),
        "stopped_at_s": float(est.times[-1]) if est.diverged else None,
        # members whose optics left the emulator's table (clamped to its edge), and what to do
        "emulator_clamped": getattr(est, "clamped", None),
        "final_time_s": float(est.times[k]),
        # log-density of the readings under the filter's forecasts, summed: the difference
        # of two runs on the same data (e.g. parameter_model "coagulation" against
        # "random_walk") is their log Bayes factor under the filter's Gaussian approximation
        "innovation_loglik": {
            "sum": est.log_evidence() if hasattr(est, "log_evidence") else None,
            "per_reading": est.log_evidence() / max(1, int(np.sum(est.analysed)))
            if hasattr(est, "log_evidence") else None},
        # whether the innovations persist from reading to reading while the laser is off:
        # the model then misses something the data show, and the bands below the surface
        # may be too narrow (docs/beyond.md)
        "innovation_persistence": persistence,
        "timing": {"filter_wall_s": float(est.filter_wall_s),
                   "step_latency_median_s": float(np.median(est.step_latency_s))
                   if len(est.step_latency_s) else 0.0,
                   "step_latency_max_s": float(np.max(est.step_latency_s))
                   if len(est.step_latency_s) else 0.0},
    }
    if advice:  # how long to keep the laser on (enkf.tissue.advice)
        from ..tissue.advice import advice_summary

        summary["advice"] = advice_summary(advisor, advice)
    if getattr(est, "restarts", ()):  # the restarts from the smoother (smoother_restarts)
        summary["smoother_restarts"] = list(est.restarts)
    if getattr(est, "drift_weight", None) is not None:
        summary["drift"] = drift_summary(est, k)
    if getattr(est, "effective_mean", None) is not None:
        summary["effective_optics"] = {
            n: {"estimate_final": float(est.effective_mean[k, i]),
                "std_final": float(est.effective_std[k, i])} for i, n in enumerate(("mua", "mus"))}
        summary["effective_optics"]["coagulated_fraction_final"] = float(
            est.coagulated_fraction[k])
    if getattr(est, "sensor_offset_mean", None) is not None:
        summary["sensor_offsets"] = [
            {"position_cm": setup.sensors.positions[j].tolist(), "unit": "deg C",
             "estimate_final": float(est.sensor_offset_mean[k, j]),
             "std_final": float(est.sensor_offset_std[k, j])}
            for j in range(est.sensor_offset_mean.shape[1])]
    if est.diverged:
        summary["rejected"] = {n: {"mean": float(est.param_mean[-1, i]),
                                   "std": float(est.param_std[-1, i])}
                               for i, n in enumerate(est.names)}
    write_json(out / "summary.json", summary)
    # volume fields: the final ensemble mean and spread of the temperature, and the
    # absorbed power (nodal load per W) of the final mean parameters
    res = est.result
    mesh = setup.grid.mesh()
    point_data = {}
    if res is not None and res.state_ensemble is not None:
        point_data["T_mean"] = res.state_ensemble.mean(axis=0)
        point_data["T_std"] = res.state_ensemble.std(axis=0, ddof=1)
    if absorption is not None and getattr(absorption, "kind", "") == "load":
        optics = [n for n in ABSORPTION_INPUTS if n in est.names]
        vals = absorption.unique(*(est.param_mean[k, [est.names.index(n)]] for n in optics))
        vals = vals[0][absorption.inverse]
        point_data["absorbed_power_per_W"] = vals
    if risk is not None and risk.omega is not None:
        from ..tissue.risk import plot_depth_maps

        last = risk.snapshots[-1] if risk.snapshots else None
        final = risk.point_data(risk.snapshot())  # the tracker's own names and thresholds
        point_data["damage_Omega_mean"] = final.pop("omega_mean")
        final.pop("T_mean", None)  # the filter's T_mean/T_std are written above
        final.pop("T_std", None)
        point_data.update(final)
        if last is not None:
            risk.write_vtu(out / "fields" / "risk.pvd", mesh)
            plot_depth_maps(out / "figures" / "risk_depth_map.png", last, setup.grid,
                            risk.T_threshold)
        summary["risk"] = {"nodes_p_damage_over_0.5": int(np.sum(point_data["p_damage"] > 0.5)),
                           "max_p_damage": float(point_data["p_damage"].max())}
        write_json(out / "summary.json", summary)
    if point_data:
        fem.write_vtu(out / "fields" / "final.vtu", mesh, point_data=point_data)
    return summary
