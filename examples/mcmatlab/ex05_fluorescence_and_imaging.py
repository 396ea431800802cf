"""MCmatlab Example 5 (FluorescenceAndImaging): a fluorescing cylinder imaged through a lens.

A cylinder of radius 0.1 mm along x, its axis 0.3 mm deep, absorbs the 450 nm excitation
(mua = 100 cm^-1, 1 cm^-1 at the fluorescence) and fluoresces with quantum yield 0.4; the
block around it absorbs mostly the 900 nm fluorescence (mua = 100 cm^-1, 1 cm^-1 at the
excitation); both scatter with mus = 100 cm^-1, g = 0.9. A plane wave along +z lights the
top face. A lens above the cuboid (f = 2 mm, aperture 1 mm, field 1 mm, 50 x 50 pixels),
focused 0.3 mm deep, images the light that leaves, once for the excitation and once for
the fluorescence, which shows a blurred image of the cylinder. 100 example paths of each.

    python examples/mcmatlab/ex05_fluorescence_and_imaging.py [--quick] [--out DIR]

Differences from MCmatlab: fixed photon counts instead of ``simulationTimeRequested = 0.1``
min for each run (the same seeds give the same figures); MCmatlab's
``runMonteCarlo(model, 'fluorescence')`` is ``model.run_monte_carlo("fluorescence")``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model

CYLINDER_RADIUS = 0.01  #: cm
CYLINDER_DEPTH = 3 * CYLINDER_RADIUS  #: cm, depth of its axis
QY = 0.4  #: the fluorescer's quantum yield


def geometry(X, Y, Z):
    """0: fluorescence absorber, 1: the fluorescing cylinder along x."""
    return np.where(Y**2 + (Z - CYLINDER_DEPTH) ** 2 < CYLINDER_RADIUS**2, 1, 0)


def _step(below_500: float, above_500: float):
    """mua (cm^-1) of wavelength (nm): one value below 500 nm, another above."""
    return lambda wavelength: below_500 if wavelength < 500 else above_500


def _collector(LC, res: int) -> None:
    LC.x, LC.y, LC.z = 0.0, 0.0, CYLINDER_DEPTH  # cm, centre of the focal plane
    LC.theta, LC.phi = 0.0, math.pi / 2  # facing the top face
    LC.f = 0.2  # cm, focal length
    LC.diam = 0.1  # cm, aperture
    LC.field_size = 0.1  # cm
    LC.NA = 0.22  # used only by a fiber
    LC.res = res


def build(quick: bool = False) -> Model:
    """The model of Example 5; ``quick``: 20^3 voxels, 2 x 10^4 photons per run."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 20 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = [
        Medium("fluorescence absorber", mua=_step(1.0, 100.0), mus=100.0, g=0.9),
        Medium("fluorescer", mua=_step(100.0, 1.0), mus=100.0, g=0.9, QY=QY),
    ]
    G.geom_func = geometry
    for sim, wavelength, seed in ((model.MC, 450.0, 1), (model.FMC, 900.0, 2)):
        sim.n_photons_requested = 20_000 if quick else 1_000_000
        sim.seed = seed
        sim.progress = not quick
        sim.n_example_paths = 100
        sim.matched_interfaces = True
        sim.boundary_type = 1
        sim.wavelength = wavelength  # nm
        sim.use_light_collector = True
        _collector(sim.light_collector, 20 if quick else 50)
    model.MC.light_source.source_type = 2  # plane wave
    model.MC.light_source.theta = model.MC.light_source.phi = 0.0
    return model


def run(quick: bool = False) -> Model:
    """The excitation, then the fluorescence Monte Carlo."""
    model = build(quick).run_monte_carlo()
    return model.run_monte_carlo("fluorescence")


def emitted_ratio(model) -> float:
    """Fluorescence emitted over QY (lambda_x / lambda_f) times the excitation absorbed in
    the fluorescer (1: QY counts photons, lambda_x / lambda_f is their energy ratio)."""
    G, MC, FMC = model.G, model.MC, model.FMC
    absorbed = MC.NA[G.medium_map() == 1].sum() * G.dx * G.dy * G.dz
    return FMC.emitted_power / (QY * MC.wavelength / FMC.wavelength * absorbed)


def mirror_z_score(model) -> float:
    """|fluorescence absorbed at y > 0 - at y < 0| in standard errors.

    The geometry and the plane wave are symmetric under y -> -y. A packet deposits a
    share in [0, 1] of its power on either side, so the standard error of a difference over
    N packets is at most P sqrt(f / N) (P the power launched, f the fraction absorbed).
    Two runs add their noise: the fluorescence run's (P emitted, f absorbed fluorescence)
    and the excitation's imbalance of the emitters (P = QY lambda_x/lambda_f, f the
    excitation absorbed in the fluorescer), of which at most all is absorbed again.
    """
    G, MC, FMC = model.G, model.MC, model.FMC
    absorbed = FMC.NA * G.dx * G.dy * G.dz
    plus, minus = absorbed[:, G.y > 1e-12].sum(), absorbed[:, G.y < -1e-12].sum()
    c = QY * MC.wavelength / FMC.wavelength
    f_fluorescer = FMC.emitted_power / c
    se = math.sqrt(FMC.emitted_power**2 * FMC.absorbed_fraction / FMC.n_photons
                   + c**2 * f_fluorescer / MC.n_photons)
    return abs(plus - minus) / se


def check(model) -> dict:
    """Energy of the fluorescence (exact), and the y-mirror symmetry of its absorption."""
    return {
        "emitted_over_qy_absorbed": {
            "value": emitted_ratio(model), "expected": 1.0, "tol": 1e-9,
            "what": "fluorescence emitted / (QY lambda_x/lambda_f excitation absorbed in the "
                    "fluorescer)"},
        "fluorescence_mirror_symmetry": {
            "value": mirror_z_score(model), "expected": 0.0, "tol": 4.0,
            "what": "|fluorescence absorbed y > 0 - y < 0| in standard errors (bound)"},
    }


def images_figure(model):
    """The lens images of the excitation and of the fluorescence side by side."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), layout="constrained")
    for ax, sim, what in ((axes[0], model.MC, "excitation, 450 nm"),
                          (axes[1], model.FMC, "fluorescence, 900 nm")):
        LC = sim.light_collector
        h = LC.field_size / 2
        im = ax.imshow(LC.image.T, origin="lower", extent=[-h, h, -h, h], cmap="inferno")
        ax.set(xlabel="X [cm]", ylabel="Y [cm]", title=f"Collected {what}")
        fig.colorbar(im, ax=ax, label="image irradiance [W/cm$^2$ per W incident]")
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    model = run(args.quick)
    MC, FMC = model.MC, model.FMC
    print(f"{100 * MC.absorbed_fraction:.3g}% of the incident light was absorbed within the "
          "cuboid")
    print(f"{100 * MC.light_collector.image.sum() * (0.1 / MC.light_collector.res) ** 2:.3g}% "
          "of the incident light ends up on the detector")
    absorbed_in_fluorescer = FMC.emitted_power / (QY * MC.wavelength / FMC.wavelength)
    print(f"{100 * FMC.emitted_power / MC.absorbed_fraction:.3g}% of the absorbed incident "
          f"light was re-emitted as fluorescence ({100 * absorbed_in_fluorescer:.3g}% of the "
          "incident light was absorbed in the fluorescer)")
    print(f"{100 * FMC.absorbed_fraction:.3g}% of the fluorescence was absorbed within the cuboid")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex05")
    model.plot("MC", args.out / "ex05")
    model.plot("FMC", args.out / "ex05_FMC")  # emitters, NA, NFR, image, example paths
    from mcmatlab_py.plotting.outputs import plot_example_paths, plot_light_collector

    plot_light_collector(model).savefig(args.out / "ex05_light_collector.png", dpi=110)
    plot_example_paths(model).savefig(args.out / "ex05_example_paths.png", dpi=110)
    images_figure(model).savefig(args.out / "ex05_images.png", dpi=100)
    print(f"figures in {args.out}")
