"""MCmatlab Example 10 (MediaPropertyParametricSweep): light collected by a fiber under a
thin slab as the scattering anisotropy g sweeps from -1 to 1.

A pencil beam enters the top of a 0.1 mm thick, 1 x 1 mm slab (mua = 10, mus = 100
cm^-1), 532 nm, every face escaping. A fiber (core 1 mm, NA 0.22) 0.6 mm below the top,
at y = -0.5 mm, looks up at 45 deg (theta = 3 pi / 4) at the slab's underside. The
medium's g is swept over 21 values from -1 to 1 (MCmatlab passes it through
``mediaPropParams``; here the sweep sets ``Medium.g``) and the fiber's power recorded.

    python examples/mcmatlab/ex10_media_property_parametric_sweep.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count per g instead of 2 s; the quick run
sweeps 5 values of g instead of 21. MCmatlab's ``mediaPropParams`` has no counterpart:
a ``Medium`` is changed directly between runs.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model


def build(quick: bool = False, g: float = 0.0) -> Model:
    """The model of Example 10 (MCmatlab's 21^3 voxels) with anisotropy ``g``."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 21
    G.Lx, G.Ly, G.Lz = 0.1, 0.1, 0.01  # cm
    G.media = [Medium("variable g medium", mua=10.0, mus=100.0, g=g)]

    MC = model.MC
    MC.n_photons_requested = 50_000 if quick else 500_000
    MC.progress = False
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    src = MC.light_source
    src.source_type = 0  # pencil beam
    src.x_focus = src.y_focus = src.z_focus = 0.0
    MC.use_light_collector = True
    LC = MC.light_collector
    LC.x, LC.y, LC.z = 0.0, -0.05, 0.06  # cm, the fiber tip
    LC.theta, LC.phi = 3 * math.pi / 4, math.pi / 2
    LC.f = math.inf  # a fiber
    LC.diam, LC.NA = 0.1, 0.22
    return model


def run(quick: bool = False) -> dict:
    """The sweep: ``{"g": (k,), "power": (k,) W/W, "n_photons": (k,), "model": last model}``."""
    g_vec = np.linspace(-1, 1, 5 if quick else 21)
    model = build(quick)
    power = np.empty_like(g_vec)
    n = np.empty(g_vec.size, dtype=int)
    for i, g in enumerate(g_vec):
        model.G.media[0].g = float(g)
        model.MC.seed = 1000 + i
        model = model.run_monte_carlo()
        power[i] = model.MC.light_collector.image
        n[i] = model.MC.n_photons
    return {"g": g_vec, "power": power, "n_photons": n, "model": model}


def check(result: dict) -> dict:
    """The sweep's shape: nothing at g = +-1; forward scattering sends more to the fiber.

    * g = -1 and g = 1 scatter exactly backwards and forwards: every packet stays on the
      beam's axis and leaves along z, never within 45 +- 13 deg of the fiber's axis: no
      power at both ends (the sum of the two).
    * The fiber sees the slab's underside: more light gets through with forward
      scattering, so the power at g = 0.5 exceeds that at g = -0.5 by at least 5
      standard errors (a run's standard error is at most sqrt(p (1 - p) / N), as a
      packet's collected weight lies in [0, 1]; two runs add in quadrature).
    """
    g, p, n = result["g"], result["power"], result["n_photons"]
    lo, hi = (int(np.flatnonzero(np.isclose(g, v))[0]) for v in (-0.5, 0.5))
    se = math.hypot(*(math.sqrt(p[i] * (1 - p[i]) / n[i]) for i in (lo, hi)))
    return {
        "nothing_at_g_pm1": {
            "value": float(p[0] + p[-1]), "expected": 0.0, "tol": 1e-9,
            "what": "fiber power at g = -1 plus at g = 1 [W/W]"},
        "forward_scattering_reaches_fiber": {
            "value": float((p[hi] - p[lo]) / se), "min": 5.0,
            "what": "power at g = 0.5 minus at g = -0.5, in standard errors"},
    }


def sweep_figure(result: dict):
    """Fiber power against g, with 2-standard-error bars (photon-count bound)."""
    import matplotlib.pyplot as plt

    g, p, n = result["g"], result["power"], result["n_photons"]
    fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
    ax.errorbar(g, p, yerr=2 * np.sqrt(p * (1 - p) / n), marker="o", capsize=2)
    ax.set(xlabel="scattering anisotropy g", ylabel="power collected by the fiber [W/W]",
           title="Media property sweep (Example 10)")
    ax.grid(True)
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="5 values of g, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    result = run(args.quick)
    for g, p in zip(result["g"], result["power"], strict=True):
        print(f"g = {g:+.2f}: collected power {p:.4g}")
    for name, c in check(result).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    result["model"].plot("G", args.out / "ex10")
    result["model"].plot("MC", args.out / "ex10")  # g = 1
    sweep_figure(result).savefig(args.out / "ex10_sweep.png", dpi=100)
    print(f"figures in {args.out}")
