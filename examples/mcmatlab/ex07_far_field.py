"""MCmatlab Example 7 (FarField): the angular distribution of the light leaving a cuboid.

A Gaussian beam (1/e^2 radius 150 um, Gaussian angular spread of 1/e^2 half-angle 15
deg) focused 0.3 mm deep, tilted by theta = 30 deg in the y-z plane (phi = -pi/2), at
450 nm into a 1 mm cube of a "fluorescence absorber" (mua = 1 cm^-1 below 500 nm, 100
above; mus = 100 cm^-1, g = 0.9) holding a cylinder of "fluorescer" along x (radius
0.1 mm, axis 0.3 mm deep; mua = 100 cm^-1 below 500 nm, 1 above; quantum yield 0.4).
Every face escapes; ``far_field_res = 50`` tallies the escaping power over 50 x 50 bins
of (theta, phi). The fluorescence Monte Carlo (550 nm, ``model.FMC``) then carries the
light the cylinder re-emits, with its own far field.

    python examples/mcmatlab/ex07_far_field.py [--quick] [--out DIR]

Differences from MCmatlab: the far fields are drawn over (theta, phi), as power per
solid angle, instead of on MCmatlab's 3-D sphere; fixed photon counts replace
``simulationTimeRequested = 0.1`` min for each run.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import IntensityDistribution, Medium, Model
from mcmatlab_py.monte_carlo.outputs import far_field_solid_angles

CYLINDER_RADIUS = 0.01  #: cm; its axis lies along x at y = 0, z = 3 radii


def geometry(X, Y, Z):
    """0: fluorescence absorber; 1: the fluorescer cylinder along x."""
    return np.where(Y**2 + (Z - 3 * CYLINDER_RADIUS) ** 2 < CYLINDER_RADIUS**2, 1, 0)


def absorber_mua(wavelength):
    """cm^-1: weak for the blue excitation, strong for the fluorescence."""
    return 1.0 if wavelength < 500 else 100.0


def fluorescer_mua(wavelength):
    """cm^-1: strong for the excitation, weak for its own fluorescence."""
    return 100.0 if wavelength < 500 else 1.0


def build(quick: bool = False) -> Model:
    """The model of Example 7; ``quick``: 21^3 voxels and 3 x 10^4 photons."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 21 if quick else 101
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = [Medium("fluorescence absorber", mua=absorber_mua, mus=100.0, g=0.9),
               Medium("fluorescer", mua=fluorescer_mua, mus=100.0, g=0.9, QY=0.4)]
    G.geom_func = geometry

    for sim, wavelength, seed in ((model.MC, 450.0, 7), (model.FMC, 550.0, 70)):
        sim.n_photons_requested = 30_000 if quick else 2_000_000
        sim.seed = seed
        sim.progress = not quick
        sim.far_field_res = 50
        sim.matched_interfaces = True
        sim.boundary_type = 1
        sim.wavelength = wavelength  # nm
    src = model.MC.light_source
    src.source_type = 4  # radial-factorizable beam
    src.focal_plane_intensity_distribution = IntensityDistribution(radial_distr=1,
                                                                   radial_width=0.015)
    src.angular_intensity_distribution = IntensityDistribution(radial_distr=1,
                                                               radial_width=math.radians(15))
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.0, 0.03  # cm
    src.theta, src.phi = math.pi / 6, -math.pi / 2
    return model


def run(quick: bool = False) -> Model:
    """Build and run the excitation, then the fluorescence Monte Carlo of Example 7."""
    return build(quick).run_monte_carlo().run_monte_carlo("fluorescence")


def check(model) -> dict:
    """The far fields hold all the escaping light; the excitation's is mirror-symmetric in x.

    * ``sum(far_field)`` equals the power that escaped through the faces (tallies of the
      same packets, in fixed point): for the excitation, per W incident; for the
      fluorescence, per W of incident excitation, so its escaped fraction times
      ``FMC.emitted_power``. The larger relative difference of the two: below 1e-9.
    * The beam and the cylinder are symmetric under x -> -x, which takes phi to
      pi - phi (the 50 phi bins pair up exactly), so ``sum(far_field cos(phi))``, the
      mean x direction of the escaping light, is 0. A packet adds a value in [-1, 1]
      times its escaping weight, so the standard error over N packets is at most
      sqrt(escaped / N): within 4 of them.
    """
    MC, FMC = model.MC, model.FMC
    escaped = sum(MC.escaped.values())
    totals = ((MC.far_field.sum(), escaped),
              (FMC.far_field.sum(), FMC.emitted_power * sum(FMC.escaped.values())))
    moment = float((MC.far_field * np.cos(MC.far_field_phi)[None, :]).sum())
    return {
        "far_field_totals": {
            "value": float(max(abs(a / b - 1) for a, b in totals)), "expected": 0.0, "tol": 1e-9,
            "what": "sum of the far field against the escaped power, relative, worse of "
                    "excitation and fluorescence"},
        "x_mirror_symmetry": {
            "value": moment / math.sqrt(escaped / MC.n_photons), "expected": 0.0, "tol": 4.0,
            "what": "sum(far_field cos phi) in standard errors (bound sqrt(escaped / N))"},
    }


def far_field_figure(model):
    """The far fields of the excitation and the fluorescence, as power per solid angle."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    for ax, sim, title in ((axes[0], model.MC, "excitation, 450 nm"),
                           (axes[1], model.FMC, "fluorescence, 550 nm")):
        solid = far_field_solid_angles(sim.far_field_res)  # sr per bin
        im = ax.pcolormesh(np.degrees(sim.far_field_phi), np.degrees(sim.far_field_theta),
                           sim.far_field / solid, shading="nearest", cmap="inferno")
        # theta = 0 at the top, as the far fields of examples 2 and 21
        ax.set(xlabel="phi [deg]", title=f"Far field, {title}", ylim=(180, 0))
        fig.colorbar(im, ax=ax, label="radiant intensity [W/sr per W of excitation]")
    axes[0].set_ylabel("theta [deg] (0: +z, down; 180: up through the top)")
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    model = run(args.quick)
    MC, FMC = model.MC, model.FMC
    print(f"{100 * MC.absorbed_fraction:.3g}% of the incident light was absorbed; "
          f"{100 * sum(MC.escaped.values()):.3g}% escaped; fluorescence emitted: "
          f"{FMC.emitted_power:.3g} W/W, of which {100 * sum(FMC.escaped.values()):.3g}% escaped")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex07")
    model.plot("MC", args.out / "ex07")
    model.plot("FMC", args.out / "ex07_fluorescence")
    far_field_figure(model).savefig(args.out / "ex07_far_field.png", dpi=100)
    print(f"figures in {args.out}")
