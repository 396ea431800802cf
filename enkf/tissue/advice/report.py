"""The advice in summary.json and on the run's figure (:mod:`enkf.tissue.advice`)."""

from __future__ import annotations

import numpy as np

from .advisor import Advisor

__all__ = ["advice_line", "advice_summary", "plot_advice"]


def advice_summary(advisor: Advisor, rows: list) -> dict:
    """summary.json's ``advice``: what was asked (the points, limits, plan), the last
    reading's advice, the interval's width at the first and the last reading, and the
    forecasts' wall time."""
    q = advisor.quantiles
    width = [r.target_time[2] - r.target_time[1] for r in rows]
    ms = [1e3 * r.wall_s for r in rows]
    return {
        "points_cm": {k: v.tolist() for k, v in advisor.points.items()},
        "limits": {"protected_T": advisor.protected_T, "protected_omega": advisor.protected_omega,
                   "surface_T": advisor.surface_T},
        "plan": {"power_W": advisor.plan.power, "pulses_s": [list(p) for p in advisor.plan.pulses]},
        "quantiles": list(q), "step_s": advisor.step, "engine": advisor.engine,
        "filters": "one filter" if set(advisor.tracks) <= {None} else
        "the drift bank's filters, their members weighed by each filter's probability",
        "final": rows[-1].as_dict(q) if rows else None,
        "interval_width_s": {"first": width[0] if rows else None,
                             "last": width[-1] if rows else None},
        "wall_ms": {"median": float(np.median(ms)) if ms else None,
                    "max": float(np.max(ms)) if ms else None}}


def advice_line(summary: dict) -> str:
    """The last reading's advice in one line, from :func:`advice_summary`'s dict: when the
    target coagulates and when to stop (medians and intervals), the risks under the plan,
    and the hottest the protected tissue and the surface get."""
    f, lim = summary.get("final") or {}, summary.get("limits") or {}
    if not f:
        return "advice: no reading"
    q = [k[len("target_time_q"):-2] for k in f if k.startswith("target_time_q")]

    def finite(v):  # summary.json writes inf (beyond the horizon) as null
        return v is not None and np.isfinite(v)

    def when(what):
        med, lo, hi = (f.get(f"{what}_median_s"), *(f.get(f"{what}_q{v}_s") for v in q))
        hi_s = f"{hi:.2f}" if finite(hi) else "beyond the horizon"
        return f"{med:.2f} s ({lo:.2f} to {hi_s})"

    if finite(f.get("target_time_median_s")):
        head = (f"target coagulated at {when('target_time')}, stop at "
                f"{when('stop_time') if finite(f.get('stop_time_median_s')) else 'the horizon'}")
    else:
        head = (f"target not coagulated within the horizon (P = "
                f"{f.get('p_target', 0.0):.2f})")
    parts = [f"advice at {f['time_s']:g} s: {head}"]
    for region, limit in (("protected", lim.get("protected_T")), ("surface", lim.get("surface_T"))):
        peak = f.get(f"{region}_peak_T_median_C")
        p = f.get(f"p_{region}_plan")
        if p is None and peak is None:
            continue
        bits = []
        if p is not None:
            over = f" over {limit:g} deg C" if limit is not None else " over its limit"
            bits.append(f"P({region}{over}) {p:.2f}")
        if peak is not None:
            lo, hi = (f.get(f"{region}_peak_T_q{v}_C") for v in q)
            bits.append(f"hottest {peak:.1f} deg C ({lo:.1f} to {hi:.1f})")
        parts.append(", ".join(bits))
    return "; ".join(parts)


def plot_advice(ax, rows: list) -> None:
    """On ``ax``: after each reading, when the target is coagulated under the plan (median
    and interval) and when to stop (median), with the risks under the plan on a second
    axis (0 to 1)."""
    t = np.array([r.time for r in rows])

    def col(get):  # beyond the horizon: not drawn
        v = np.array([get(r) for r in rows], float)
        return np.where(np.isfinite(v), v, np.nan)

    ax.fill_between(t, col(lambda r: r.target_time[1]), col(lambda r: r.target_time[2]),
                    color="g", alpha=0.2, lw=0, label="target: interval")
    ax.plot(t, col(lambda r: r.target_time[0]), "g-", lw=1.4, label="target: median")
    ax.plot(t, col(lambda r: r.stop_time[0]), "k--", lw=1.0, label="stop: median")
    ax.plot(t, t, color="0.6", lw=0.8, ls=":")
    ax.set(title="advice: target coagulated at", xlabel="time [s]", ylabel="[s]")
    ax.legend(fontsize=7, loc="upper left")
    if rows and rows[0].risks:
        ax2 = ax.twinx()
        for k, c in (("protected_plan", "m"), ("surface_plan", "r")):
            if k in rows[0].risks:
                ax2.plot(t, [r.risks[k] for r in rows], color=c, lw=0.9,
                         label=f"P({k.split('_')[0]} over its limit)")
        ax2.set(ylim=(-0.03, 1.03), ylabel="probability under the plan")
        ax2.legend(fontsize=7, loc="lower right")
