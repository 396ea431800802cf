"""MCmatlab Example 22 (CombiningModelObjects): two beams of different power, run apart
and combined.

Standard tissue (mua = 1, mus = 100 cm^-1, g = 0.9) under 0.3 mm of air, 532 nm, as in
Example 1. Two pencil beams along +z enter at y = -0.1 mm (power 1 W) and y = +0.1 mm
(0.2 W), each model's ``MC.P``; each is run on its own, then
:func:`mcmatlab_py.combine.combine_models` adds them with weights given by their powers.
The combined ``NA`` and ``NFR`` are per W of the total 1.2 W (its ``MC.P``), as MCmatlab's
``combineModels``.

    python examples/mcmatlab/ex22_combining_model_objects.py [--quick] [--out DIR]

Differences from MCmatlab: fixed photon counts and seeds instead of
``simulationTimeRequested = 0.1`` min.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model
from mcmatlab_py.combine import combine_models

Z_SURFACE = 0.03  #: cm, the tissue surface under the air
POWERS = (1.0, 0.2)  #: W, the two beams (their MC.P)
Y_BEAMS = (-0.01, 0.01)  #: cm


def geometry(X, Y, Z):
    """0: air above ``Z_SURFACE``, 1: standard tissue below."""
    return np.where(Z > Z_SURFACE, 1, 0)


def build(quick: bool = False, y_focus: float = Y_BEAMS[0], power: float = POWERS[0]) -> Model:
    """One beam's model; ``quick``: 21 x 21 x 30 voxels and 2 x 10^4 photons."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = (21, 21, 30) if quick else (101, 101, 150)
    G.Lx, G.Ly, G.Lz = 0.1, 0.1, 0.15  # cm
    G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0),
               Medium("standard tissue", mua=1.0, mus=100.0, g=0.9)]
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 20_000 if quick else 1_000_000
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    MC.P = power  # W
    src = MC.light_source
    src.source_type = 0  # pencil beam
    src.x_focus, src.y_focus, src.z_focus = 0.0, y_focus, G.Lz / 2
    return model


def run(quick: bool = False) -> dict:
    """``{"models": [beam 1, beam 2], "combined": model}``."""
    models = []
    for i, (y, power) in enumerate(zip(Y_BEAMS, POWERS, strict=True)):
        m = build(quick, y, power)
        m.MC.seed = 220 + i
        models.append(m.run_monte_carlo())
    return {"models": models, "combined": combine_models(models)}  # weights: each MC.P


def side_powers(model) -> tuple[float, float, float]:
    """(absorbed at y < 0, at y > 0, in total), fractions of the incident power."""
    G = model.G
    absorbed = model.MC.NA * G.dx * G.dy * G.dz
    return (float(absorbed[:, G.y < -1e-12].sum()), float(absorbed[:, G.y > 1e-12].sum()),
            float(absorbed.sum()))


def check(result: dict) -> dict:
    """The combination is the power-weighted mean, and the beams mirror each other.

    * The combined model's absorbed power on the y < 0 side equals
      (1 W x beam 1's + 0.2 W x beam 2's) / 1.2 W, computed here from the two runs'
      ``NA``: to rounding.
    * Beam 2 is beam 1 mirrored in y: the power beam 1 puts at y < 0 and that beam 2
      puts at y > 0 agree within 4 standard errors (each run's at most sqrt(f / N), f
      its absorbed fraction, added in quadrature).
    """
    (l1, r1, f1), (l2, r2, f2) = (side_powers(m) for m in result["models"])
    lc, _, _ = side_powers(result["combined"])
    n1, n2 = (m.MC.n_photons for m in result["models"])
    expected = (POWERS[0] * l1 + POWERS[1] * l2) / sum(POWERS)
    se = math.hypot(math.sqrt(f1 / n1), math.sqrt(f2 / n2))
    return {
        "power_weighted_mean": {
            "value": lc, "expected": expected, "tol": 1e-12,
            "what": "combined absorbed power at y < 0 against (1 x beam 1 + 0.2 x beam 2) / 1.2"},
        "beams_mirror": {
            "value": (l1 - r2) / se, "expected": 0.0, "tol": 4.0,
            "what": "beam 1's absorbed power at y < 0 minus beam 2's at y > 0, in standard errors"},
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    result = run(args.quick)
    for name, c in check(result).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    combined = result["combined"]
    combined.plot("G", args.out / "ex22")
    combined.plot("MC", args.out / "ex22")  # NA, NFR per W of the 1.2 W in all
    print(f"figures in {args.out}")
