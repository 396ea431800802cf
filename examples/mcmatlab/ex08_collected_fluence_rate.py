"""MCmatlab Example 8 (CollectedFluenceRate): where the light that reaches a detector went.

Standard tissue (mua = 1, mus = 100 cm^-1, g = 0.9) under 0.1 mm of air, 400 nm. A
collimated Gaussian beam (1/e^2 radius 0.1 mm) enters at y = +0.25 mm; a lens (f = 1
mm, aperture 1 mm, field 0.4 mm, 50 x 50 pixels) looks straight down (theta = 0) at
y = -0.25 mm. Only the top face lets light escape (``boundary_type = 2``). With
``deposition_criteria.only_collected`` only the packets that end in the lens add to
``NA`` and ``NFR``: the fluence rate shows the "banana" of paths from the beam to the
imaged spot, and 20 example paths are drawn.

    python examples/mcmatlab/ex08_collected_fluence_rate.py [--quick] [--out DIR]

Differences from MCmatlab: none in the parameters (5 x 10^6 photons on 100^3 voxels in
the full run); the example paths are drawn by matplotlib in 3-D.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import IntensityDistribution, Medium, Model

Z_SURFACE = 0.01  #: cm, the tissue surface under the air


def geometry(X, Y, Z):
    """0: air above ``Z_SURFACE``, 1: standard tissue below."""
    return np.where(Z > Z_SURFACE, 1, 0)


def build(quick: bool = False) -> Model:
    """The model of Example 8; ``quick``: 40^3 voxels and 2 x 10^5 photons."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 40 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0),
               Medium("standard tissue", mua=1.0, mus=100.0, g=0.9)]
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 200_000 if quick else 5_000_000
    MC.seed = 8
    MC.progress = not quick
    MC.n_example_paths = 20
    MC.matched_interfaces = True
    MC.boundary_type = 2  # only the top face escapes
    MC.wavelength = 400  # nm
    src = MC.light_source
    src.source_type = 4  # radial-factorizable beam
    src.focal_plane_intensity_distribution = IntensityDistribution(radial_distr=1,
                                                                   radial_width=0.01)
    src.angular_intensity_distribution = IntensityDistribution(radial_distr=1, radial_width=0.0)
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.025, 0.0  # cm
    src.theta = src.phi = 0.0
    MC.use_light_collector = True
    LC = MC.light_collector
    LC.x, LC.y, LC.z = 0.0, -0.025, 0.0  # cm, centre of the object plane
    LC.theta, LC.phi = 0.0, math.pi / 2
    LC.f, LC.diam, LC.field_size = 0.1, 0.1, 0.04  # cm
    LC.res = 50
    MC.deposition_criteria.only_collected = True
    return model


def run(quick: bool = False) -> Model:
    """Build and run the Monte Carlo of Example 8."""
    return build(quick).run_monte_carlo()


def check(model) -> dict:
    """The collected light's absorption is mirror-symmetric in x and leans to the detector.

    * Beam and lens lie on x = 0: the absorbed power of the collected packets at x > 0
      and at x < 0 differ by at most 4 standard errors (a packet's share of the
      difference lies in [-1, 1] and averages 0; its variance is at most the absorbed
      fraction f: standard error sqrt(f / N)).
    * ``only_collected`` keeps the paths from the beam (y = +0.25 mm) to the imaged spot
      (y = -0.25 mm): the absorption-weighted mean y lies below the beam's axis by at
      least 5 standard errors (it is near 0; without the criteria it would be the beam's
      +0.25 mm). Each collected packet's mean y lies in [-0.5, 0.5] mm, so its variance
      is at most (0.5 mm)^2 (Popoviciu): the standard error is about 0.5 mm over
      sqrt(collected packets) (their absorbed weights differ little).
    """
    G, MC = model.G, model.MC
    absorbed = MC.NA * G.dx * G.dy * G.dz
    diff = absorbed[G.x > 1e-12].sum() - absorbed[G.x < -1e-12].sum()
    se = math.sqrt(absorbed.sum() / MC.n_photons)
    by_y = absorbed.sum(axis=(0, 2))
    y_mean = float((by_y * G.y).sum() / by_y.sum())
    y_beam = MC.light_source.y_focus
    return {
        "x_mirror_symmetry": {
            "value": diff / se, "expected": 0.0, "tol": 4.0,
            "what": "absorbed power of collected packets x > 0 minus x < 0, in standard errors"},
        "banana_towards_detector": {
            "value": y_mean, "max": y_beam - 5 * (G.Ly / 2) / math.sqrt(MC.n_photons_collected),
            "what": "absorption-weighted mean y of the collected packets [cm], >= 5 standard "
                    "errors below the beam axis"},
    }


def banana_figure(model):
    """The absorption of the collected packets summed over x (log scale), and the lens image."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    G, MC, LC = model.G, model.MC, model.MC.light_collector
    A = MC.NA.sum(axis=0) * G.dx  # (ny, nz) W/cm^2/W
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained",
                                   gridspec_kw={"width_ratios": [1.2, 1]})
    im = ax0.imshow(np.where(A > 0, A, np.nan).T, extent=[-G.Ly / 2, G.Ly / 2, G.Lz, 0],
                    cmap="inferno", norm=LogNorm(vmin=A.max() * 1e-3, vmax=A.max()))
    ax0.axvline(MC.light_source.y_focus, color="w", ls=":", lw=0.8)
    ax0.axvline(LC.y, color="c", ls=":", lw=0.8)
    ax0.set(xlabel="y [cm]", ylabel="z [cm]",
            title="Absorption of the collected light, summed over x")
    fig.colorbar(im, ax=ax0, label="[W/cm$^2$/W]")
    h = LC.field_size / 2
    im = ax1.imshow(LC.image.T, origin="lower", extent=[-h + LC.x, h + LC.x, -h + LC.y, h + LC.y],
                    cmap="inferno")
    ax1.set(xlabel="x [cm]", ylabel="y [cm]", title="Lens image (beam at y = +0.025 cm)")
    fig.colorbar(im, ax=ax1, label="[W/cm$^2$/W]")
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    from mcmatlab_py.plotting.outputs import plot_example_paths, plot_light_collector

    model = run(args.quick)
    MC, LC = model.MC, model.MC.light_collector
    power = LC.image.sum() * (LC.field_size / LC.res) ** 2
    print(f"{MC.n_photons_collected} of {MC.n_photons:.3g} packets collected; the collected "
          f"power is {power:.3g} W/W")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex08")
    model.plot("MC", args.out / "ex08")  # NA, NFR of the collected packets only
    plot_light_collector(model).savefig(args.out / "ex08_image.png", dpi=100)
    banana_figure(model).savefig(args.out / "ex08_banana.png", dpi=100)
    plot_example_paths(model).savefig(args.out / "ex08_paths.png", dpi=100)
    print(f"figures in {args.out}")
