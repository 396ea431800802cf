"""MCmatlab Example 24 (AzFzReflectanceTransmittance): MCML-style depth and radial views
of a layered medium.

Two layers fill a 5 x 5 x 1 cm cuboid (101 x 101 x 150 voxels): "tissue 1" (mua = 0.4,
mus = 100 cm^-1, g = 0.9) down to z = 2 mm, "tissue 2" (mua = 0.2) below; a pencil beam
along +z enters the centre of the top, 532 nm, every face escaping. The views MCML
gives: A(z), the absorbed power per unit depth, and F(z), the fluence rate summed over
x and y (:func:`mcmatlab_py.monte_carlo.layered.absorption_vs_depth`, MCmatlab's ``plotAzFz``), and
the reflectance R(r) and transmittance T(r) against the distance from the beam
(:func:`mcmatlab_py.monte_carlo.layered.radial_reflectance_transmittance`, MCmatlab's
``plotRadialReflectanceTransmittance``), here also MCML's own radial bins
(``MC.n_radial_bins``: ``Rd_r``, ``Tt_r``).

The check runs MCML's published slab (the MCML manual's Table
6.1, after van de Hulst 1980: n = 1, mua = 10, mus = 90 cm^-1, g = 0.75, 0.2 mm thick)
through the same radial tallies.

    python examples/mcmatlab/ex24_az_fz_reflectance_transmittance.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count instead of ``simulationTimeRequested =
0.1`` min; MCML's radial bins (0.5 mm wide) are drawn over MCmatlab's per-pixel R(r) and
T(r), which need ``calc_normalized_irradiance`` (MCmatlab computes the face maps always).
The published-slab run is this port's addition.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model
from mcmatlab_py.monte_carlo.layered import absorption_vs_depth

LAYER_DEPTH = 0.2  #: cm, the interface between the layers
#: MCML manual Table 6.1 (van de Hulst): total diffuse reflectance and total transmittance
RD_PUBLISHED, TT_PUBLISHED = 0.09739, 0.66096


def geometry(X, Y, Z):
    """0: tissue 1 above ``LAYER_DEPTH``, 1: tissue 2 below."""
    return np.where(Z > LAYER_DEPTH, 1, 0)


def build(quick: bool = False) -> Model:
    """The layered model of Example 24; ``quick``: 21 x 21 x 30 voxels and 5000 photons."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = (21, 21, 30) if quick else (101, 101, 150)
    G.Lx, G.Ly, G.Lz = 5.0, 5.0, 1.0  # cm
    G.media = [Medium("tissue 1", mua=0.4, mus=100.0, g=0.9),
               Medium("tissue 2", mua=0.2, mus=100.0, g=0.9)]
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 5_000 if quick else 300_000
    MC.seed = 24
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    MC.calc_normalized_irradiance = True  # R(r), T(r) from the face maps
    MC.n_radial_bins, MC.radial_bin_size = 50, 0.05  # MCML's bins: 0..2.5 cm
    src = MC.light_source
    src.source_type = 0  # pencil beam
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.0, G.Lz / 2
    return model


def build_published_slab(quick: bool = False) -> Model:
    """MCML's Table 6.1 slab: laterally infinite (cyclic sides), matched, 10 radial bins."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 1, 1, 4
    G.Lx, G.Ly, G.Lz = 1.0, 1.0, 0.02  # cm
    G.media = [Medium("van de Hulst slab", mua=10.0, mus=90.0, g=0.75, n=1.0)]
    MC = model.MC
    MC.n_photons_requested = 200_000 if quick else 2_000_000
    MC.seed = 2401
    MC.progress = False
    MC.boundary_type = 3  # top and bottom escape, sides cyclic
    MC.n_radial_bins, MC.radial_bin_size = 10, 0.01  # the last bin holds all beyond 0.1 cm
    MC.light_source.source_type = 0
    return model


def run(quick: bool = False) -> dict:
    """``{"model": the layered model, "slab": MCML's published slab}``, both run."""
    return {"model": build(quick).run_monte_carlo(),
            "slab": build_published_slab(quick).run_monte_carlo()}


def radial_totals(model) -> tuple[float, float]:
    """Total Rd and Tt as MCML sums them: its radial bins times their annulus areas."""
    MC = model.MC
    dr = MC.radial_bin_size
    ring = 2 * np.pi * (np.arange(MC.n_radial_bins) + 0.5) * dr * dr  # cm^2
    return float((MC.Rd_r * ring).sum()), float((MC.Tt_r * ring).sum())


def check(result: dict) -> dict:
    """MCML's published slab, through MCML's radial bins: total Rd and Tt.

    A packet's share of Rd (or Tt) lies in [0, 1], so the standard error over N packets
    is at most sqrt(p (1 - p) / N): within 4 of them. The published values are van de
    Hulst's (adding-doubling, exact to their digits), not Monte Carlo estimates.
    """
    MC = result["slab"].MC
    Rd, Tt = radial_totals(result["slab"])
    n = MC.n_photons
    out = {}
    for name, value, ref in (("Rd", Rd, RD_PUBLISHED), ("Tt", Tt, TT_PUBLISHED)):
        se = math.sqrt(ref * (1 - ref) / n)
        out[f"{name}_van_de_Hulst"] = {
            "value": value, "expected": ref, "tol": 4 * se,
            "what": f"total {name} of MCML's Table 6.1 slab from the radial bins "
                    "(4 standard errors)"}
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    from mcmatlab_py.plotting.outputs import plot_az_fz, plot_radial_reflectance_transmittance

    result = run(args.quick)
    model = result["model"]
    MC = model.MC
    z, A, F = absorption_vs_depth(model)
    Rd, Tt = radial_totals(model)
    print(f"layered: absorbed {MC.absorbed_fraction:.4g}, Rd {Rd:.4g}, Tt {Tt:.4g} (MCML bins); "
          f"sum A(z) dz = {A.sum() * model.G.dz:.4g}")
    for name, c in check(result).items():
        print(f"{name}: {c['value']:.6g} (published {c['expected']}; {c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex24")
    model.plot("MC", args.out / "ex24")
    plot_az_fz(model).savefig(args.out / "ex24_AzFz.png", dpi=100)
    plot_radial_reflectance_transmittance(model).savefig(args.out / "ex24_RT.png", dpi=100)
    print(f"figures in {args.out}")
