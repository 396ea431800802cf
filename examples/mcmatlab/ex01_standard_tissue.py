"""MCmatlab Example 1 (StandardTissue): a pencil beam into "standard tissue" under air.

A block of standard tissue (mua = 1, mus = 100 cm^-1, g = 0.9) lies below a 0.3 mm
layer of air; a pencil beam along +z through the centre of the top face. nx and ny
are odd so that the beam runs down the middle of the centre column of voxels.
MCmatlab suggests its log10 view for the fluence rate and the absorption: the
figures here use log colour scales.

    python examples/mcmatlab/ex01_standard_tissue.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count instead of
``simulationTimeRequested = 0.1`` min (the same seed gives the same figures). In thin
media such as this air (mus = 1e-8 cm^-1) NFR is the track length per voxel, as
MCmatlab's continuous absorption gives it, so the beam shows in the air as in
MCmatlab's figures; in the tissue it is ``NA / mua``. ``model.plot("MC")`` cuts its xy
slice at the top face (in the air): ``ex01_NFR_tissue.png`` cuts it 0.1 mm below the
tissue surface.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model

Z_SURFACE = 0.03  #: cm, the tissue surface below the air layer


def geometry(X, Y, Z):
    """0: air above ``Z_SURFACE``, 1: standard tissue below (MCmatlab's media 1 and 2)."""
    return np.where(Z > Z_SURFACE, 1, 0)


def build(quick: bool = False) -> Model:
    """The model of Example 1; ``quick``: 21 x 21 x 30 voxels and 2 x 10^4 photons."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = (21, 21, 30) if quick else (101, 101, 150)
    G.Lx, G.Ly, G.Lz = 0.1, 0.1, 0.15  # cm
    G.media = [
        Medium("air", mua=1e-8, mus=1e-8, g=1.0),
        Medium("standard tissue", mua=1.0, mus=100.0, g=0.9),
    ]
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 20_000 if quick else 2_000_000
    MC.seed = 1
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1  # every face escapes
    MC.wavelength = 532  # nm
    src = MC.light_source
    src.source_type = 0  # pencil beam
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.0, G.Lz / 2  # a point the beam goes through
    src.theta, src.phi = 0.0, 0.0
    return model


def run(quick: bool = False) -> Model:
    """Build and run the Monte Carlo of Example 1."""
    return build(quick).run_monte_carlo()


def mirror_z_score(model) -> float:
    """Largest |z| of the absorbed power's differences across x = 0 and across y = 0.

    The geometry and the beam are symmetric under x -> -x and y -> -y. A packet
    deposits ``a+`` on one side and ``a-`` on the other, ``a+ + a- <= 1``, so the
    variance of ``a+ - a-`` is at most the absorbed fraction f: the standard error of
    the difference over N packets is at most sqrt(f / N). A centre column (odd nx or
    ny) belongs to neither side.
    """
    G, MC = model.G, model.MC
    absorbed = MC.NA * G.dx * G.dy * G.dz  # fraction of the launched power per voxel
    eps = 1e-9 * max(G.Lx, G.Ly)
    z = 0.0
    for axis, c in ((0, G.x), (1, G.y)):
        side = np.moveaxis(absorbed, axis, 0)
        plus, minus = side[c > eps].sum(), side[c < -eps].sum()
        z = max(z, abs(plus - minus) / math.sqrt((plus + minus) / MC.n_photons))
    return z


def check(model) -> dict:
    """Mirror symmetry of the absorption about the beam, and the energy balance."""
    return {
        "mirror_symmetry": {
            "value": mirror_z_score(model), "expected": 0.0, "tol": 4.0,
            "what": "|absorbed power left - right| in standard errors (bound sqrt(f/N)), x and y"},
        "energy_balance": {
            "value": model.MC.energy_balance, "expected": 1.0, "tol": 1e-9,
            "what": "absorbed + escaped + the rest, over the launched power (exact per packet)"},
    }


def fluence_figure(model):
    """NFR (log scale) on slices through the beam, the xy one 0.1 mm below the tissue surface.

    ``model.plot("MC")`` cuts its xy slice at the top face, which here lies in the air.
    """
    import matplotlib.pyplot as plt

    from mcmatlab_py.plotting.figures import positive_log_norm
    from mcmatlab_py.plotting.slices import orthogonal_slices

    G, NFR = model.G, model.MC.NFR
    fig = plt.figure(figsize=(8, 3.3), layout="constrained")
    orthogonal_slices(fig, np.where(NFR > 0, NFR, np.nan), G, (0.5, 0.5, (Z_SURFACE + 0.01) / G.Lz),
                      cmap="inferno", norm=positive_log_norm(NFR), label="NFR [W/cm$^2$/W]",
                      title=f"Normalized fluence rate, {model.MC.n_photons:.2g} photons")
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    model = run(args.quick)
    print(f"{100 * model.MC.absorbed_fraction:.3g}% of the incident light was absorbed "
          "within the cuboid")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex01")  # geometry, media properties
    model.plot("MC", args.out / "ex01")  # NA and NFR on log colour scales
    fluence_figure(model).savefig(args.out / "ex01_NFR_tissue.png", dpi=100)
    print(f"figures in {args.out}")
