"""MCmatlab Example 20 (ReflectanceStatisticsAndCyclicBoundaries): diffuse reflectance
of a semi-infinite slab, with its statistical error.

Standard tissue (mua = 1, mus = 100 cm^-1, g = 0.9, n = 1.4) under one voxel layer of
air, lit by a pencil beam. Cyclic side boundaries (``boundary_type = 3``) make the
slab laterally infinite: a packet leaving a side re-enters through the opposite one,
so none is lost sideways and the cuboid may be narrow. The diffuse reflectance is the
power leaving the top face, ``sum(NI_zneg) dx dy``; without matched interfaces the
Fresnel reflection of the beam at the tissue surface, ((1 - 1.4)/(1 + 1.4))^2, is
subtracted. Each case is run five times with different seeds: the mean and its
standard error (standard deviation / sqrt(5)) are printed.

    python examples/mcmatlab/ex20_reflectance_statistics.py [--quick] [--out DIR]

Differences from MCmatlab: the seeds are fixed (1-5 matched, 6-10 mismatched) instead
of drawn afresh, so a run is repeatable; MCmatlab's per-run timing is printed as the
kernel's photons per second.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model

N_RUNS = 5
N_TISSUE = 1.4  #: refractive index of the tissue
SPECULAR = ((1 - N_TISSUE) / (1 + N_TISSUE)) ** 2  #: Fresnel reflectance at normal incidence


def geometry(X, Y, Z):
    """0: one voxel layer of air at the top, 1: standard tissue below."""
    M = np.ones(X.shape, dtype=int)
    M[:, :, 0] = 0
    return M


def build(quick: bool = False) -> Model:
    """The model of Example 20; ``quick``: 5 x 5 x 20 voxels and 2000 photons per run.

    MCmatlab notes that nx = ny = 2 already gives the same reflectance: with cyclic
    sides only the depth resolution matters for it.
    """
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = (5, 5, 20) if quick else (101, 101, 100)
    G.Lx, G.Ly, G.Lz = 0.5, 0.5, 2.0  # cm
    G.media = [Medium("air", mua=1e-8, mus=100.0, g=1.0, n=1.0),
               Medium("standard tissue", mua=1.0, mus=100.0, g=0.9, n=N_TISSUE)]
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 2_000 if quick else 100_000
    MC.progress = False
    MC.boundary_type = 3  # top and bottom escape, the sides are cyclic
    MC.n_outside = None  # MCmatlab's cuboid faces: the tissue's bottom face does not reflect
    MC.wavelength = 532  # nm
    MC.calc_normalized_irradiance = True  # NI_zneg: MCmatlab computes it always
    src = MC.light_source
    src.source_type = 0  # pencil beam
    src.x_focus = src.y_focus = src.z_focus = 0.0
    return model


def diffuse_reflectance(model) -> float:
    """The power through the top face, ``sum(NI_zneg) dx dy``, less the beam's Fresnel part."""
    G, MC = model.G, model.MC
    total = float(MC.NI_zneg.sum() * G.dx * G.dy)
    return total if MC.matched_interfaces else total - SPECULAR


def run(quick: bool = False) -> dict:
    """Five runs with matched interfaces, five without.

    Returns ``{"matched": model, "mismatched": model}`` (each after its last run) and
    ``"Rd_matched"``, ``"Rd_mismatched"``: (5,) diffuse reflectances, one per run.
    """
    out = {}
    for i, matched in enumerate((True, False)):
        model = build(quick)
        model.MC.matched_interfaces = matched
        Rd = np.empty(N_RUNS)
        for k in range(N_RUNS):
            model.MC.seed = 1 + k + i * N_RUNS
            model = model.run_monte_carlo()
            Rd[k] = diffuse_reflectance(model)
        name = "matched" if matched else "mismatched"
        out[name], out[f"Rd_{name}"] = model, Rd
    return out


def statistics(Rd: np.ndarray) -> tuple[float, float]:
    """Mean and standard error of the mean (sample standard deviation / sqrt(n))."""
    return float(Rd.mean()), float(Rd.std(ddof=1) / math.sqrt(Rd.size))


def se_bound(p: float, n_photons: int) -> float:
    """Upper bound of the standard error of a [0, 1]-valued tally of mean p over n packets.

    A packet's weight leaving the top is in [0, 1], so its variance is at most p (1 - p).
    """
    return math.sqrt(p * (1 - p) / n_photons)


def check(result: dict) -> dict:
    """The reflectance statistics: an index mismatch lowers Rd, and the run-to-run
    scatter agrees with the photon count.

    * Internal reflection at the n = 1.4 surface sends diffuse light back into the
      absorbing tissue: Rd(mismatched) < Rd(matched) (0.25 against 0.40 at 4 x 10^5
      photons), required by at least 5 standard errors (their photon-count bounds).
    * The two cases' standard errors from their five runs, pooled, over their bounds
      sqrt(p (1 - p) / (5 N)) pooled alike: in [0.1, 2]. Its true value is 0.69-0.70
      (200 runs of 2000 photons, both cases); an estimate from 2 x 4 degrees of freedom
      leaves [0.1, 2] with probability < 1e-6. Zero would mean that the runs were not
      independent (the same seed each time).
    """
    n_total = N_RUNS * result["matched"].MC.n_photons
    means, sem2, bound2 = {}, 0.0, 0.0
    for name in ("matched", "mismatched"):
        mean, sem = statistics(result[f"Rd_{name}"])
        means[name] = mean
        sem2 += sem**2
        bound2 += se_bound(mean, n_total) ** 2
    return {
        "mismatch_lowers_Rd": {
            "value": means["matched"] - means["mismatched"], "min": 5 * math.sqrt(bound2),
            "what": "Rd(matched) - Rd(mismatched), at least 5 standard errors"},
        "scatter_vs_photon_count": {
            "value": math.sqrt(sem2 / bound2), "min": 0.1, "max": 2.0,
            "what": "standard error of the runs over its photon-count bound (both cases pooled)"},
    }


def statistics_figure(result: dict):
    """The top face's irradiance map of the last mismatched run (log scale), and Rd per run."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    model = result["mismatched"]
    G, NI = model.G, model.MC.NI_zneg
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(8, 3.6), layout="constrained",
                                   gridspec_kw={"width_ratios": [1, 1.1]})
    fig.get_layout_engine().set(wspace=0.08)
    positive = NI[NI > 0]
    im = ax0.imshow(np.where(NI > 0, NI, np.nan).T, origin="lower", cmap="inferno",
                    extent=[-G.Lx / 2, G.Lx / 2, -G.Ly / 2, G.Ly / 2],
                    norm=LogNorm(max(positive.min(), positive.max() * 1e-4), positive.max()))
    fig.colorbar(im, ax=ax0, label="irradiance leaving the top [W/cm$^2$ per W]")
    ax0.set(xlabel="x [cm]", ylabel="y [cm]", title="light leaving the top (mismatched)")
    for i, name in enumerate(("matched", "mismatched")):
        Rd = result[f"Rd_{name}"]
        mean, sem = statistics(Rd)
        ax1.plot(np.full(Rd.size, i), Rd, "o", color=f"C{i}", alpha=0.5, label=f"{name}: runs")
        ax1.errorbar(i + 0.15, mean, yerr=sem, fmt="s", color=f"C{i}", capsize=4,
                     label=f"mean {mean:.4f} ± {sem:.4f}")
    ax1.set(xticks=[0, 1], xticklabels=["matched", "mismatched"], xlim=(-0.5, 1.6),
            ylabel="diffuse reflectance Rd", title=f"{N_RUNS} runs of {model.MC.n_photons} photons")
    ax1.legend(fontsize=7, loc="center right")
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    result = run(args.quick)
    for name in ("matched", "mismatched"):
        mean, sem = statistics(result[f"Rd_{name}"])
        rate = result[name].MC.photons_per_second
        print(f"Rd {name:<10} = {mean:.6f} +- {sem:.6f} (n = {N_RUNS}, {rate:.3g} photons/s)")
    for name, c in check(result).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    result["mismatched"].plot("MC", args.out / "ex20")  # the last run, as MCmatlab plots it
    statistics_figure(result).savefig(args.out / "ex20_reflectance.png", dpi=110)
    print(f"figures in {args.out}")
