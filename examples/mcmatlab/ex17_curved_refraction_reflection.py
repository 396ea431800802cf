"""MCmatlab Example 17 (CurvedRefractionReflection): a plane wave focused by a
hemispherical water droplet, with smoothed interface normals.

A hemisphere of water (radius 0.4 mm, n = 1.3) sits on the bottom of a cuboid of air;
a plane wave falls on it from above. Refraction and reflection at the curved surface
use interface normals from the Sobel gradient of the voxelised droplet, smoothed over
``MC.smoothing_length_scale`` (Tran & Jacques 2020, J. Biomed. Opt. 25(2) 025001, whose
figure 3 this reproduces; :func:`mcmatlab_py.monte_carlo.optics.interface_normals`). The droplet
focuses the light towards the middle of its base; grazing incidence at its rim
reflects more. ``n_example_paths = 100`` stores paths to draw.

    python examples/mcmatlab/ex17_curved_refraction_reflection.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count instead of 0.1 min; the light leaving
the faces (``NI_*``, which MCmatlab always computes) is requested here for the check
and the figure. The cuboid's faces are MCmatlab's (``MC.n_outside = None``): the light
that reaches the droplet's base leaves without Fresnel reflection. NA is zero in the
air: the kernel deposits weight only where a packet interacts (mua + mus = 2e-8 cm^-1 in
air); NFR there is the track length, as MCmatlab's. ``quick`` keeps odd nx and ny so
that the grid stays symmetric about the droplet's axis.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model

DROPLET_RADIUS = 0.04  #: cm


def build(quick: bool = False) -> Model:
    """The model of Example 17; ``quick``: 41 x 41 x 21 voxels and 2 x 10^4 photons."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = (41, 41, 21) if quick else (201, 201, 101)
    G.Lx, G.Ly, G.Lz = 0.1, 0.1, 0.05  # cm
    G.media = [
        Medium("air", mua=1e-8, mus=1e-8, g=1.0, n=1.0),
        Medium("water", mua=0.00036, mus=10.0, g=1.0, n=1.3),
    ]
    z_base = G.z[-1]  # MCmatlab centres the droplet on the last voxel layer's centre

    def geometry(X, Y, Z):
        """0 air, 1 water: the hemisphere on the bottom."""
        return np.where(X**2 + Y**2 + (Z - z_base) ** 2 < DROPLET_RADIUS**2, 1, 0)

    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 20_000 if quick else 1_000_000
    MC.seed = 17
    MC.progress = not quick
    MC.n_example_paths = 100
    MC.matched_interfaces = False
    MC.n_outside = None  # MCmatlab's cuboid faces: the droplet's base does not reflect
    MC.smoothing_length_scale = G.Lx * 10  # cm, as MCmatlab's example
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    MC.calc_normalized_irradiance = True
    src = MC.light_source
    src.source_type = 2  # plane wave over the top face
    # MCmatlab sets a Gaussian focal plane and angular distribution here too; a plane
    # wave ignores them
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.0, G.Lz
    src.theta, src.phi = 0.0, 0.0
    return model


def run(quick: bool = False) -> Model:
    """Build and run the Monte Carlo of Example 17."""
    return build(quick).run_monte_carlo()


def mirror_z_score(model) -> float:
    """Largest |z| of the power out through the bottom face on either side of x = 0
    and of y = 0 (the droplet and the plane wave are symmetric under x -> -x, y -> -y).

    A packet leaves through one pixel with weight b+ on one side or b- on the other,
    b+ + b- <= 1, so (b+ - b-)^2 <= b+ + b-: the standard error of the difference over
    N packets is at most sqrt(f / N), f the bottom escape. Nearly every packet ends
    there, so the bound is nearly tight.
    """
    G, MC = model.G, model.MC
    out = MC.NI_zpos * G.dx * G.dy  # (nx, ny), fraction of the launched power per pixel
    z = 0.0
    for axis, c in ((0, G.x), (1, G.y)):
        side = np.moveaxis(out, axis, 0)
        plus, minus = side[c > 1e-12].sum(), side[c < -1e-12].sum()
        z = max(z, abs(plus - minus) / math.sqrt((plus + minus) / MC.n_photons))
    return z


def check(model) -> dict:
    """Mirror symmetry of the light leaving the bottom, and the energy balance."""
    return {
        "mirror_symmetry": {
            "value": mirror_z_score(model), "expected": 0.0, "tol": 4.0,
            "what": "|bottom escape x > 0 minus x < 0| (and y) in standard errors (bound sqrt(f/N))"},
        "energy_balance": {
            "value": model.MC.energy_balance, "expected": 1.0, "tol": 1e-9,
            "what": "absorbed + escaped + the rest, over the launched power (exact per packet)"},
    }


def droplet_figure(model, k: int = 6):
    """The first ``k`` segments of the example paths seen along y, and the light leaving
    the bottom face (the droplet's base) along x through its centre."""
    import matplotlib.pyplot as plt

    G, MC = model.G, model.MC
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(9, 3.4), layout="constrained",
                                   gridspec_kw={"width_ratios": [1.3, 1]})
    P = MC.example_paths
    starts = np.flatnonzero(np.isnan(P[0]))
    ends = np.r_[starts[1:], P.shape[1]]
    for a, b in zip(starts, ends, strict=True):
        seg = P[:, a + 1:min(b, a + 2 + k)]
        ax0.plot(seg[0], seg[2], lw=0.6, color="C0", alpha=0.7)
    t = np.linspace(0, math.pi, 200)
    ax0.plot(DROPLET_RADIUS * np.cos(t), G.z[-1] - DROPLET_RADIUS * np.sin(t), color="C3", lw=1)
    ax0.set(xlim=(-G.Lx / 2, G.Lx / 2), ylim=(G.Lz, 0), xlabel="x [cm]", ylabel="z [cm]",
            title=f"{MC.n_example_paths} example paths, first {k} segments")
    ax0.set_aspect("equal")
    row = MC.NI_zpos[:, G.ny // 2]
    # a bin no light left is a gap, not a drop off the log axis
    ax1.step(G.x, np.where(row > 0, row, np.nan), where="mid")
    ax1.axvspan(-DROPLET_RADIUS, DROPLET_RADIUS, color="C3", alpha=0.1, label="droplet base")
    ax1.axhline(1 / (G.Lx * G.Ly), color="0.5", ls="--", lw=0.8, label="incident plane wave")
    ax1.set(xlabel="x [cm]", ylabel="irradiance leaving the bottom [W/cm$^2$ per W]", yscale="log",
            title="light leaving the bottom, y = 0")
    ax1.legend(fontsize=7)
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    model = run(args.quick)
    MC = model.MC
    print(f"escaped: top {MC.escaped['top']:.4f}, sides {MC.escaped['sides']:.4f}, bottom "
          f"{MC.escaped['bottom']:.4f}")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    from mcmatlab_py.plotting.outputs import plot_boundary_irradiance, plot_example_paths

    model.plot("G", args.out / "ex17")
    model.plot("MC", args.out / "ex17")
    plot_boundary_irradiance(model).savefig(args.out / "ex17_NI.png", dpi=110)
    plot_example_paths(model).savefig(args.out / "ex17_example_paths.png", dpi=110)
    droplet_figure(model).savefig(args.out / "ex17_droplet.png", dpi=110)
    print(f"figures in {args.out}")
