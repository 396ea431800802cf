"""MCmatlab Example 12 (SaturableAbsorber): optical properties that depend on the fluence rate.

A collimated Gaussian beam (1/e^2 radius 200 um, 5 W, 532 nm) falls through 0.3 mm of
air onto the boundary plane y = 0 between two saturable absorbers. Absorber 1 (y < 0)
has ``mua = 50 / (1 + FR / 2000)`` cm^-1; in absorber 2 (y > 0) ``mua = 50 / (1 + FR /
1000)``, ``mus = 10 / (1 + FR / 500)`` and ``g = 1 - 0.1 / (1 + FR / 300)`` (FR the
fluence rate, W/cm^2). Such media are split into sub-media of similar properties (50 and,
to show the binning as steps in the figures, 9), and the Monte Carlo is iterated 15
times, each run seeing the fluence rate ``P x NFR`` of the one before, with the photon
count doubling up to the requested one. The beam bleaches its way in; its wings, less
intense, are absorbed first, so it narrows with depth.

    python examples/mcmatlab/ex12_saturable_absorber.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count instead of 0.2 min of simulation;
MCmatlab's ``MC.FRinitial = 0`` is the default ``MC.FR = 0`` (the fluence rate the first
run sees).
"""

from __future__ import annotations

import argparse
import copy
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model

ABSORBER_DEPTH = 0.03  #: cm, air above
POWER = 5.0  #: W, incident on the top face (MC.P)
LOW_POWER = 0.5  #: W, the comparison run of the check
FR_ITERATIONS = 15  #: MCmatlab's MC.FRdepIterations


def geometry(X, Y, Z):
    """0 air above ``ABSORBER_DEPTH``; below, 1 saturable absorber 1 (y <= 0), 2 absorber 2."""
    M = np.zeros(X.shape, dtype=int)
    M[Z > ABSORBER_DEPTH] = 1
    M[(Z > ABSORBER_DEPTH) & (Y > 0)] = 2
    return M


def media() -> list[Medium]:
    """Air and the two saturable absorbers (functions of wavelength, FR, T, FD)."""
    return [
        Medium("air", mua=1e-8, mus=1e-8, g=0.0),
        Medium("saturable absorber 1", mua=lambda wl, FR, T, FD: 50.0 / (1 + FR / 2000),
               mus=10.0, g=0.9, n_bins=50),
        Medium("saturable absorber 2", mua=lambda wl, FR, T, FD: 50.0 / (1 + FR / 1000),
               mus=lambda wl, FR, T, FD: 10.0 / (1 + FR / 500),
               g=lambda wl, FR, T, FD: 1 - 0.1 / (1 + FR / 300), n_bins=9),
    ]


def build(quick: bool = False) -> Model:
    """The model of Example 12; ``quick``: 20 x 20 x 40 voxels, 2 x 10^4 photons."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = (20, 20, 40) if quick else (100, 100, 200)
    G.Lx, G.Ly, G.Lz = 0.1, 0.1, 0.2  # cm
    G.media = media()
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 20_000 if quick else 2_000_000
    MC.seed = 12
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    MC.calc_normalized_irradiance = True  # the transmitted light on the bottom face
    src = MC.light_source
    src.source_type = 4  # radially factorizable beam
    src.focal_plane_intensity_distribution.radial_distr = 1  # Gaussian
    src.focal_plane_intensity_distribution.radial_width = 0.02  # cm, 1/e^2 radius
    src.angular_intensity_distribution.radial_distr = 1  # Gaussian ...
    src.angular_intensity_distribution.radial_width = 0.0  # ... of zero width: collimated
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.0, G.Lz / 2
    src.theta = src.phi = 0.0
    MC.FR = 0.0  # W/cm^2, the first run's fluence rate (MCmatlab's FRinitial)
    MC.P = POWER  # W, incident on the top face
    MC.fr_dep_iterations = FR_ITERATIONS
    return model


def run(quick: bool = False) -> Model:
    """Build the model and run the Monte Carlo, iterated on the fluence rate at ``POWER``."""
    return build(quick).run_monte_carlo()


def transmission(model, half: int = 0) -> float:
    """Fraction of the launched power leaving through the bottom face: all of it (``half``
    = 0), or below absorber 1 (``half`` = -1, y < 0) or absorber 2 (``half`` = +1, y > 0)."""
    G, MC = model.G, model.MC
    if half == 0:
        return MC.escaped["bottom"]
    cols = G.y > 0 if half > 0 else G.y < 0
    return float(MC.NI_zpos[:, cols].sum() * G.dx * G.dy)


def check(model) -> dict:
    """The transmission rises with the power, and more behind the more saturable absorber."""
    low = copy.deepcopy(model)
    low.MC.FR, low.MC.P = 0.0, LOW_POWER
    low.run_monte_carlo()
    t_hi, t_lo = transmission(model), transmission(low)
    t1, t2 = transmission(model, -1), transmission(model, +1)
    n = model.MC.n_photons
    return {
        "saturation": {
            "value": (t_hi - t_lo) / math.sqrt((t_hi + t_lo) / n), "min": 4.0,
            "what": f"transmission at {POWER:g} W minus that at {LOW_POWER:g} W, in standard "
                    "errors (bound sqrt(T / N) each)"},
        "absorber_2_bleaches_more": {
            "value": (t2 - t1) / math.sqrt((t1 + t2) / n), "min": 4.0,
            "what": "transmission behind absorber 2 minus absorber 1, in standard errors "
                    "(bound sqrt(T / N))"},
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    model = run(args.quick)
    print(f"{100 * model.MC.absorbed_fraction:.3g}% of the incident light was absorbed "
          f"within the cuboid, {100 * transmission(model):.3g}% transmitted")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex12")
    model.plot("MC", args.out / "ex12")  # the media properties show the range of the bins
    print(f"figures in {args.out}")
