"""MCmatlab Example 9 (GeometryParametricSweep): light collected by a fiber behind a slab
of growing thickness.

A pencil beam enters the top of a 1 x 2 x 1.05 mm cuboid of air, 532 nm, in which a slab
of standard tissue (mua = 1, mus = 100 cm^-1, g = 0.9) ends at z = 1 mm and reaches up
to 1 mm - t. A fiber (core 1 mm, NA 0.22) 1.5 mm below the top, at y = -0.5 mm, looks
up at 45 deg (theta = 3 pi / 4, towards +y) at the slab's underside. The slab thickness
t is swept from 0 to 1 mm (``G.geom_func_params``) and the fiber's power is recorded.
With no slab the beam passes straight down and misses the fiber (0); thin slabs
scatter light towards it; thick ones absorb and send it back up: the curve rises and
falls.

    python examples/mcmatlab/ex09_geometry_parametric_sweep.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count per thickness instead of 2 s; the
quick run sweeps 6 thicknesses instead of 21.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model

SLAB_BOTTOM = 0.1  #: cm


def geometry(X, Y, Z, t):
    """0: air; 1: the tissue slab between ``SLAB_BOTTOM - t`` and ``SLAB_BOTTOM`` (t in cm)."""
    return np.where((Z > SLAB_BOTTOM - t) & (Z < SLAB_BOTTOM), 1, 0)


def build(quick: bool = False) -> Model:
    """The model of Example 9 (MCmatlab's 11 x 21 x 21 voxels); ``quick``: fewer photons."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 11, 21, 21
    G.Lx, G.Ly, G.Lz = 0.1, 0.2, 0.105  # cm
    G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0),
               Medium("standard tissue", mua=1.0, mus=100.0, g=0.9)]
    G.geom_func = geometry
    G.geom_func_params = 0.0

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
    LC.x, LC.y, LC.z = 0.0, -0.05, 0.15  # cm, the fiber tip
    LC.theta, LC.phi = 3 * math.pi / 4, math.pi / 2
    LC.f = math.inf  # a fiber
    LC.diam, LC.NA = 0.1, 0.22
    return model


def run(quick: bool = False) -> dict:
    """The sweep: ``{"t": (k,) cm, "power": (k,) W/W, "n_photons": (k,), "model": last model}``."""
    t_vec = np.linspace(0, 0.1, 6 if quick else 21)
    model = build(quick)
    power = np.empty_like(t_vec)
    n = np.empty(t_vec.size, dtype=int)
    for i, t in enumerate(t_vec):
        model.G.geom_func_params = float(t)
        model.MC.seed = 900 + i
        model = model.run_monte_carlo()
        power[i] = model.MC.light_collector.image
        n[i] = model.MC.n_photons
    return {"t": t_vec, "power": power, "n_photons": n, "model": model}


def check(result: dict) -> dict:
    """The sweep's shape: nothing without a slab, a maximum inside the range.

    * t = 0: only air (mus = 1e-8 cm^-1) and the beam runs straight down, past the fiber:
      no power is collected (a scattering in air happens with probability 1e-9).
    * The largest power beats that of the thickest slab (t = 1 mm) by at least 5
      standard errors: a packet's collected weight lies in [0, 1], so a run's standard
      error is at most sqrt(p (1 - p) / N), and those of two runs add in quadrature.
    """
    p, n = result["power"], result["n_photons"]
    k = int(np.argmax(p))
    se = math.hypot(math.sqrt(p[k] * (1 - p[k]) / n[k]), math.sqrt(p[-1] * (1 - p[-1]) / n[-1]))
    return {
        "no_slab_no_light": {
            "value": float(p[0]), "expected": 0.0, "tol": 1e-6,
            "what": "fiber power without a slab [W/W]"},
        "maximum_inside": {
            "value": float((p[k] - p[-1]) / se), "min": 5.0,
            "what": "largest power minus that at t = 1 mm, in standard errors"},
    }


def sweep_figure(result: dict):
    """Fiber power against slab thickness, with 2-standard-error bars (photon-count bound)."""
    import matplotlib.pyplot as plt

    t, p, n = result["t"], result["power"], result["n_photons"]
    fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
    ax.errorbar(t * 10, p, yerr=2 * np.sqrt(p * (1 - p) / n), marker="o", capsize=2)
    ax.set(xlabel="slab thickness [mm]", ylabel="power collected by the fiber [W/W]",
           title="Geometry sweep (Example 9)")
    ax.grid(True)
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="6 thicknesses, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    result = run(args.quick)
    for t, p in zip(result["t"], result["power"], strict=True):
        print(f"t = {10 * t:.2f} mm: collected power {p:.4g}")
    for name, c in check(result).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    result["model"].plot("G", args.out / "ex09")  # the thickest slab
    result["model"].plot("MC", args.out / "ex09")
    sweep_figure(result).savefig(args.out / "ex09_sweep.png", dpi=100)
    print(f"figures in {args.out}")
