"""MCmatlab Example 26 (DistributedSource): light emitted from a sphere buried in tissue.

Instead of a light source, ``MC.source_distribution`` gives each voxel a weight: packets
start at uniformly random points of voxels drawn in proportion to it and are emitted
isotropically, as fluorescence is. Here the emitters fill a sphere of radius 100 um,
0.7 mm below the surface of standard tissue (mua = 1, mus = 100 cm^-1, g = 0.9) under
0.3 mm of air, at 41 wavelengths from 400 to 600 nm with a (nx, ny, nz, 41) distribution,
Gaussian in wavelength around 500 nm (1/e half-width 50 nm), as MCmatlab's. NA and NFR are
per W emitted in all, with a wavelength axis; the figures sum over it.

    python examples/mcmatlab/ex26_distributed_source.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count instead of 0.1 min (``--quick``: 3
wavelengths). NA and NFR are zero in the air (the kernel deposits weight only where a
packet interacts; mua + mus = 2e-8 cm^-1 in air).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model
from mcmatlab_py.light.source import sample_light_source

Z_SURFACE = 0.03  #: cm, the tissue surface below the air layer
SPHERE_CENTRE = (0.0, 0.0, 0.1)  #: cm
SPHERE_RADIUS = 0.01  #: cm


def geometry(X, Y, Z):
    """0: air above ``Z_SURFACE``, 1: standard tissue below."""
    return np.where(Z > Z_SURFACE, 1, 0)


def emitters(G, wavelengths) -> np.ndarray:
    """(nx, ny, nz, n) source weights: the sphere (voxel centres inside it) times a Gaussian
    spectrum around 500 nm, MCmatlab's ``exp(-(lambda - 500)^2 / 50^2)``."""
    X, Y, Z = np.meshgrid(G.x, G.y, G.z, indexing="ij")
    x0, y0, z0 = SPHERE_CENTRE
    sphere = ((X - x0) ** 2 + (Y - y0) ** 2 + (Z - z0) ** 2 < SPHERE_RADIUS**2).astype(float)
    return sphere[..., None] * np.exp(-((np.asarray(wavelengths) - 500.0) / 50.0) ** 2)


def build(quick: bool = False) -> Model:
    """The model of Example 26; ``quick``: 41 x 41 x 60 voxels, 3 wavelengths, 2 x 10^4
    photons in all."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = (41, 41, 60) if quick else (101, 101, 150)
    G.Lx, G.Ly, G.Lz = 0.1, 0.1, 0.15  # cm
    G.media = [
        Medium("air", mua=1e-8, mus=1e-8, g=1.0),
        Medium("standard tissue", mua=1.0, mus=100.0, g=0.9),
    ]
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 20_000 if quick else 2_000_000
    MC.seed = 26
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = np.linspace(400.0, 600.0, 3 if quick else 41)  # nm
    MC.source_distribution = emitters(G, MC.wavelength)  # need not be normalised
    return model


def run(quick: bool = False) -> Model:
    """Build and run the Monte Carlo of Example 26."""
    return build(quick).run_monte_carlo()


def centroid_z_score(model) -> float:
    """Largest |z| over x, y, z of the launch centroid against the distribution's.

    The launch points of ``n_photons`` packets, drawn by the run's sampler, against the
    centroid of the weights (each voxel's centre: a point uniform in a voxel averages to
    it); the standard error of each coordinate's mean is the sample standard deviation
    over sqrt(N).
    """
    G, MC = model.G, model.MC
    S = np.asarray(MC.source_distribution).sum(axis=-1)  # every wavelength has this shape
    mono = build(quick=G.nx < 101)
    mono.MC.wavelength, mono.MC.source_distribution = 500.0, S
    d = sample_light_source(mono, int(np.sum(MC.n_photons)), seed=MC.seed)
    z = 0.0
    for axis, (key, c) in enumerate((("x", G.x), ("y", G.y), ("z", G.z))):
        marginal = np.moveaxis(S, axis, 0).reshape(S.shape[axis], -1).sum(axis=1)
        expected = float(marginal @ c / marginal.sum())
        p = d[key]
        z = max(z, abs(p.mean() - expected) / (p.std(ddof=1) / math.sqrt(p.size)))
    return z


def check(model) -> dict:
    """The launch centroid of the emitters, and the energy balance."""
    return {
        "emitter_centroid": {
            "value": centroid_z_score(model), "expected": 0.0, "tol": 4.0,
            "what": "|launch centroid - weighted centroid of source_distribution| in standard "
                    "errors, largest of x, y, z"},
        "energy_balance": {
            "value": float(np.max(np.abs(np.asarray(model.MC.energy_balance) - 1.0))) + 1.0,
            "expected": 1.0, "tol": 1e-9,
            "what": "absorbed + escaped + the rest, over the emitted power, worst wavelength "
                    "(exact per packet)"},
    }


def source_figure(model):
    """The emitter distribution and NFR (log scale) on the xz plane through the sphere."""
    import matplotlib.pyplot as plt

    from mcmatlab_py.plotting.figures import positive_log_norm

    G, MC = model.G, model.MC
    j = int(np.argmin(abs(G.y - SPHERE_CENTRE[1])))
    ext = [-G.Lx / 2, G.Lx / 2, G.Lz, 0]
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(8, 4.4), layout="constrained")
    S = np.asarray(MC.source_distribution).sum(axis=-1)
    ax0.imshow(S[:, j, :].T, extent=ext, cmap="Greys", origin="upper")
    ax0.set(title="source distribution, all wavelengths (y = 0)", xlabel="x [cm]",
            ylabel="z [cm]")
    F = MC.NFR[:, j, :].sum(axis=-1)
    im = ax1.imshow(np.where(F > 0, F, np.nan).T, extent=ext, cmap="inferno", origin="upper",
                    norm=positive_log_norm(F))
    fig.colorbar(im, ax=ax1, label="NFR [W/cm$^2$/W emitted]")
    ax1.set(title="fluence rate (y = 0)", xlabel="x [cm]")
    for ax in (ax0, ax1):
        ax.axhline(Z_SURFACE, color="C0", lw=0.8, ls="--")
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    model = run(args.quick)
    MC = model.MC
    w = np.asarray(MC.spectrum)  # each wavelength's share of the emitted power

    def total(x):
        return float(np.sum(np.asarray(x) * w))

    print(f"{100 * total(MC.absorbed_fraction):.3g}% of the emitted light was absorbed within "
          f"the cuboid; escaped: top {total(MC.escaped['top']):.4f}, bottom "
          f"{total(MC.escaped['bottom']):.4f}, sides {total(MC.escaped['sides']):.4f}")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex26")
    model.plot("MC", args.out / "ex26")
    source_figure(model).savefig(args.out / "ex26_source.png", dpi=110)  # MCmatlab's figure 7
    print(f"figures in {args.out}")
