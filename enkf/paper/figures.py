"""The paper's figures: estimates against the truth, the data, the sensitivity study."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..tissue.parameters import PARAMETER_LABELS, TRACKED_DEPTHS
from .scenarios import PULSES, true_parameters

if TYPE_CHECKING:
    from .truth import Truth

__all__ = ["plot_data", "plot_results", "plot_sensitivity"]

def plot_results(path, scenario: str, est, truth: Truth, data: np.ndarray) -> None:
    """The paper's figure: temperature tracks (top) and parameter tracks (bottom)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = est.times
    n_par = len(est.names)
    fig, axes = plt.subplots(2, max(3, n_par), figsize=(4.2 * max(3, n_par), 7.5),
                             constrained_layout=True)
    tp = true_parameters(scenario, t)
    for j, z in enumerate(TRACKED_DEPTHS):
        ax = axes[0, j]
        m, s = est.tracked_mean[:, j], est.tracked_std[:, j]
        _shade_pulses(ax, scenario)
        if j == 0:
            ax.plot(truth.times[1:len(data) + 1], data, "k.", ms=2.5, label="sensor data")
        ax.plot(truth.times[: len(t)], truth.temps[: len(t), j], "k--", lw=1.2, label="truth")
        ax.plot(t, m, "r-", lw=1.4, label=f"{_method(est)} mean")
        ax.plot(t, m + 2 * s, "r--", lw=0.8, label="$\\pm 2$ sd")
        ax.plot(t, m - 2 * s, "r--", lw=0.8)
        ax.set(title=f"temperature at z = {z:g} cm", xlabel="time [s]", ylabel="T [$^\\circ$C]")
        if j == 0:
            ax.legend(fontsize=8)
    labels = {"mua": "$\\mu_a$", "mus": "$\\mu_s$", "VHC": "$c_v$", "TC": "$k$"}
    for i, name in enumerate(est.names):
        ax = axes[1, i]
        m = est.param_mean[:, i]
        lo, hi = est.param_band(i)
        _shade_pulses(ax, scenario)
        ax.plot(t, tp[name], "k--", lw=1.2)
        ax.plot(t, m, "r-", lw=1.4)
        ax.plot(t, lo, "r--", lw=0.8)  # 2.3 % and 97.7 % quantiles of the ensemble
        ax.plot(t, hi, "r--", lw=0.8)
        ax.set(title=labels[name], xlabel="time [s]", ylabel=f"{labels[name]} [{PARAMETER_LABELS[name]}]")
    spare = list(range(n_par, axes.shape[1]))
    ens = getattr(getattr(est, "result", None), "param_ensemble", None)
    if spare and ens is not None and n_par >= 2 and len(ens):
        # the members at the end in the (mua, mus) plane: the joint spread that the two
        # parameter panels show one at a time (and how the two trade off)
        ax = axes[1, spare.pop(0)]
        ia, ib = est.names.index("mua"), est.names.index("mus")
        ax.scatter(ens[:, ia], ens[:, ib], s=10, c="r", alpha=0.6, lw=0, label="members")
        ax.plot(tp["mua"][-1], tp["mus"][-1], "k+", ms=12, mew=2, label="truth")
        ax.set(title=f"the members at t = {t[-1]:g} s", xlabel=f"{labels['mua']} [{PARAMETER_LABELS['mua']}]",
               ylabel=f"{labels['mus']} [{PARAMETER_LABELS['mus']}]")
        ax.legend(fontsize=8)
    for i in spare:
        axes[1, i].axis("off")
    fig.suptitle(f"{_method(est)}, scenario '{scenario}'; parameter bands: 2.3-97.7 % "
                 "quantiles of the ensemble")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _method(est) -> str:
    """The analysis's name for a legend (ETKF, EnKF)."""
    m = getattr(est, "method", None)
    return {"etkf": "ETKF", "enkf": "EnKF"}.get(m, m or "EnKF")


def _shade_pulses(ax, scenario: str) -> None:
    """Grey bands where the laser of ``scenario`` is on."""
    _, on, off, n = PULSES.get(scenario, PULSES["constant"])
    for i in range(n):
        ax.axvspan(i * (on + off), i * (on + off) + on, color="0.88", lw=0)


def plot_data(path, scenario: str, truth: Truth, data: np.ndarray) -> None:
    """The paper's data figure: the sensor series (left) and the true parameters (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # one panel per property: on a shared (twin) axis two constant lines fall on one
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(13, 3.8), constrained_layout=True)
    for ax in (a, b, c):
        _shade_pulses(ax, scenario)
    a.plot(truth.times[1:], data, "k.", ms=3)
    a.set(xlabel="time [s]", ylabel="T [$^\\circ$C]", title="sensor data at (0, 0, 0)")
    tp = true_parameters(scenario, truth.times)
    b.plot(truth.times, tp["mua"], "b-")
    b.set(xlabel="time [s]", ylabel="$\\mu_a$ [cm$^{-1}$]", title="true absorption $\\mu_a$")
    c.plot(truth.times, tp["mus"], "g-")
    c.set(xlabel="time [s]", ylabel="$\\mu_s$ [cm$^{-1}$]", title="true scattering $\\mu_s$")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_sensitivity(path, res: dict) -> None:
    """Sensor temperature for each mua (left) and each mus (right), pulse shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True, sharey=True)
    for ax, which, label in ((axes[0], "mua", "$\\mu_a$"), (axes[1], "mus", "$\\mu_s$")):
        ax.axvspan(0, 5, color="0.88", lw=0)
        for v, series in res[which].items():
            ax.plot(res["times"], series, label=f"{label} = {v:g} cm$^{{-1}}$")
        ax.set(xlabel="time [s]", title=f"sensitivity to {label}")
        ax.legend(fontsize=8)
    axes[0].set_ylabel("T at (0, 0, 0) [$^\\circ$C]")
    fig.savefig(path, dpi=110)
    plt.close(fig)
