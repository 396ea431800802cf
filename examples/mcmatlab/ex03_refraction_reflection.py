"""MCmatlab Example 3 (RefractionReflection): Fresnel refraction and reflection of an
isotropic source in water between air and a mirror.

Three layers: air (n = 1) at the top, 0.6 mm of water (n = 1.3) and a perfect
reflector (``n = inf``) below. An isotropic point source sits in the water, 0.1 mm
below the water surface. With ``matched_interfaces = False`` the packets refract and
reflect at the interfaces by Fresnel's equations: the mirror sends everything back up,
the water surface lets part of it out and reflects the rest, beyond the critical
angle all of it. ``n_example_paths = 100`` stores paths to draw.

    python examples/mcmatlab/ex03_refraction_reflection.py [--quick] [--out DIR]

The check traces the same geometry deterministically (:func:`ray_traced_top_escape`):
the water neither deflects (g = 1) nor, nearly, absorbs, so each direction leaving the
source is one ray, bounced specularly between the mirror, the water surface and the
side faces and thinned at each by Fresnel's reflectance; the light it passes into the
air and out through the top face, integrated over the sphere of directions, is the
top escape that the Monte Carlo must reproduce.

Differences from MCmatlab: a fixed photon count instead of 0.1 min (``useAllCPUs``
is not a setting: numba uses every core); ``quick`` uses 10^3 voxels (the layers lie
on voxel faces either way, the result does not depend on it). The cuboid's faces are
MCmatlab's (``MC.n_outside = None``): they neither reflect nor refract, a packet that
reaches one leaves, and only one leaving the air (n = 1) counts in the far field. NA is
zero in the air: the kernel deposits weight only where a packet interacts (mua + mus =
2e-8 cm^-1 in air); NFR there is the track length, as MCmatlab's.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model

Z_WATER = 0.03  #: cm, top of the water (air above)
Z_REFLECTOR = 0.09  #: cm, top of the reflector
Z_SOURCE = 0.04  #: cm, depth of the isotropic point source
N_WATER = 1.3
MUA_WATER = 0.00036  #: cm^-1
HALF_WIDTH = 0.05  #: cm, Lx / 2 = Ly / 2


def geometry(X, Y, Z):
    """0 air, 1 water below ``Z_WATER``, 2 reflector below ``Z_REFLECTOR``."""
    M = np.zeros(X.shape, dtype=int)
    M[Z > Z_WATER] = 1
    M[Z > Z_REFLECTOR] = 2
    return M


def build(quick: bool = False) -> Model:
    """The model of Example 3; ``quick``: 10^3 voxels and 3000 photons."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 10 if quick else 100
    G.Lx = G.Ly = G.Lz = 2 * HALF_WIDTH  # cm
    G.media = [
        Medium("air", mua=1e-8, mus=1e-8, g=1.0, n=1.0),
        Medium("water", mua=MUA_WATER, mus=10.0, g=1.0, n=N_WATER),
        Medium("reflector", mua=1.0, mus=1.0, g=0.0, n=math.inf),
    ]
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 3_000 if quick else 10_000
    MC.seed = 3
    MC.progress = not quick
    MC.n_example_paths = 100
    MC.matched_interfaces = False  # Fresnel at every change of n
    MC.n_outside = None  # MCmatlab's cuboid faces: no Fresnel where packets leave
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    src = MC.light_source
    src.source_type = 1  # isotropic point (emitter_length 0)
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.0, Z_SOURCE
    return model


def run(quick: bool = False) -> Model:
    """Build and run the Monte Carlo of Example 3."""
    return build(quick).run_monte_carlo()


def fresnel_reflectance(n1: float, n2: float, cos_in: np.ndarray) -> np.ndarray:
    """Unpolarised Fresnel reflectance from n1 into n2 at incidence cosines ``cos_in``
    (Born & Wolf, sec. 1.5.2): the mean of the s and p reflectances; 1 beyond the
    critical angle."""
    sin2_out = (n1 / n2) ** 2 * (1.0 - cos_in**2)
    cos_out = np.sqrt(np.clip(1.0 - sin2_out, 0.0, None))
    rs = ((n1 * cos_in - n2 * cos_out) / (n1 * cos_in + n2 * cos_out)) ** 2
    rp = ((n1 * cos_out - n2 * cos_in) / (n1 * cos_out + n2 * cos_in)) ** 2
    return np.where(sin2_out >= 1.0, 1.0, 0.5 * (rs + rp))


def ray_traced_top_escape(n_mu: int = 400, n_phi: int = 400, w_min: float = 1e-9,
                          sides_reflect: bool = False) -> float:
    """Fraction of the source's power leaving through the top face, by ray tracing.

    Directions on an ``n_mu x n_phi`` midpoint grid of (cos theta, phi), each weighted
    1 / (n_mu n_phi). A ray bounces in the water slab ``[-h, h]^2 x [Z_WATER,
    Z_REFLECTOR]``: the mirror reflects it whole; the water surface reflects the
    fraction R of Fresnel at its incidence and passes the rest; a side face passes all
    (MCmatlab's faces, ``MC.n_outside = None``), or with ``sides_reflect`` reflects as the
    surface does (water to ``MC.n_outside = 1``). What passes the surface refracts into
    the air and counts if it reaches z = 0 inside the top face (else it leaves through a
    side of the air layer). Along the way the weight falls by exp(-mua s). A ray stops
    when its weight is below ``w_min``; directions totally reflected at every face carry
    nothing out. Converged to 3e-4 at 400 x 400 (with ``sides_reflect``: 0.21311, 0.21345
    at 800 x 800).
    """
    h = HALF_WIDTH
    mu = -1.0 + (np.arange(n_mu) + 0.5) * 2.0 / n_mu
    phi = (np.arange(n_phi) + 0.5) * 2.0 * math.pi / n_phi
    MU, PHI = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1.0 - MU**2)
    u = np.stack([s * np.cos(PHI), s * np.sin(PHI), MU]).reshape(3, -1)
    R = np.stack([fresnel_reflectance(N_WATER, 1.0, np.abs(u[i])) for i in range(3)])
    if not sides_reflect:
        R[:2] = 0.0
    u, R = u[:, R.min(axis=0) < 1.0], R[:, R.min(axis=0) < 1.0]
    p = np.zeros_like(u)
    p[2] = Z_SOURCE
    w = np.ones(u.shape[1])
    top = 0.0
    live = np.arange(u.shape[1])
    while live.size:
        pp, uu, ww, RR = p[:, live], u[:, live], w[live], R[:, live]
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.stack([(np.sign(uu[0]) * h - pp[0]) / uu[0],
                          (np.sign(uu[1]) * h - pp[1]) / uu[1],
                          np.where(uu[2] < 0, Z_WATER - pp[2], Z_REFLECTOR - pp[2]) / uu[2]])
        d = np.where(np.isfinite(d), d, np.inf)
        face = d.argmin(axis=0)  # 0, 1: a side; 2: the surface or the mirror
        step = d[face, np.arange(live.size)]
        pp = pp + uu * step
        ww = ww * np.exp(-MUA_WATER * step)
        surface = (face == 2) & (uu[2] < 0)
        # through the surface: tangential components times n_water, then up through the air
        cos_air = np.sqrt(np.clip(1.0 - N_WATER**2 * (1.0 - uu[2] ** 2), 1e-300, None))
        xa = pp[0] + Z_WATER * N_WATER * uu[0] / cos_air
        ya = pp[1] + Z_WATER * N_WATER * uu[1] / cos_air
        out = surface & (np.abs(xa) <= h) & (np.abs(ya) <= h)
        top += float((ww * (1.0 - RR[2]))[out].sum())
        mirror = (face == 2) & ~surface
        ww = ww * np.where(mirror, 1.0, RR[face, np.arange(live.size)])
        uu[face, np.arange(live.size)] *= -1.0
        p[:, live], u[:, live], w[live] = pp, uu, ww
        live = live[ww > w_min]
    return top / (n_mu * n_phi)


def check(model) -> dict:
    """The light out through the top against ray tracing with Fresnel's equations, and
    the mirror lets nothing through."""
    MC = model.MC
    p = ray_traced_top_escape()
    n = MC.n_photons
    return {
        "top_escape_fresnel": {
            "value": MC.escaped["top"], "expected": p, "tol": 4 * math.sqrt(p * (1 - p) / n),
            "what": "power out through the top against the Fresnel ray trace, 4 standard "
                    "errors sqrt(p(1-p)/N)"},
        "mirror_tight": {
            "value": MC.escaped["bottom"], "expected": 0.0, "tol": 0.5 / n,
            "what": "power out through the bottom (below the n = inf reflector): not one packet"},
    }


def first_segments(paths: np.ndarray, k: int) -> np.ndarray:
    """The first ``k`` segments of each example path ((4, m) with NaN columns between
    paths, MCmatlab's layout), in the same layout."""
    starts = np.flatnonzero(np.isnan(paths[0]))
    ends = np.r_[starts[1:], paths.shape[1]]
    return np.hstack([paths[:, a:min(b, a + 2 + k)] for a, b in zip(starts, ends, strict=True)])


def layers_figure(model, k: int = 8):
    """The first ``k`` segments of the example paths seen along y, and NFR on the xz
    plane through the source (log scale), with the interfaces."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    G, MC = model.G, model.MC
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(8.4, 3.6), layout="constrained")
    P = first_segments(MC.example_paths, k)
    ax0.plot(P[0], P[2], lw=0.6, color="C0", alpha=0.6)
    ax0.plot([0], [Z_SOURCE], "o", color="C3", ms=4)
    ax0.set(xlim=(-G.Lx / 2, G.Lx / 2), ylim=(G.Lz, 0), xlabel="x [cm]", ylabel="z [cm]",
            title=f"{MC.n_example_paths} example paths, first {k} segments")
    ax0.set_aspect("equal")
    F = MC.NFR[:, G.ny // 2, :]
    # the colours span the water's values (the trapped light, 1st to 99th percentile: the
    # source's voxel is brighter); the rays leaving through the air (NFR from the track
    # length in thin media) are darker, below the scale
    water = F[:, G.z > Z_WATER]
    lo, hi = np.percentile(water[water > 0], [1, 99])
    im = ax1.imshow(np.where(F > 0, F, np.nan).T, origin="upper", cmap="inferno",
                    norm=LogNorm(vmin=lo, vmax=hi), extent=[-G.Lx / 2, G.Lx / 2, G.Lz, 0])
    fig.colorbar(im, ax=ax1, label="NFR [W/cm$^2$/W]", extend="both")
    ax1.set(title="fluence rate at y = 0 (trapped light)", xlabel="x [cm]", ylabel="z [cm]")
    for ax in (ax0, ax1):
        for z, label in ((Z_WATER, "air / water"), (Z_REFLECTOR, "water / reflector")):
            ax.axhline(z, color="0.5", lw=0.8, ls="--")
            ax.text(-G.Lx / 2 * 0.97, z - 0.002, label, fontsize=7, color="0.2",
                    bbox={"fc": "w", "ec": "none", "alpha": 0.7, "pad": 1})
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
          f"{MC.escaped['bottom']:.4f}; absorbed {MC.absorbed_fraction:.4f}")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} (expected {c['expected']:.6g} +- {c['tol']:.2g}; "
              f"{c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    from mcmatlab_py.plotting.outputs import plot_example_paths

    model.plot("G", args.out / "ex03")
    model.plot("MC", args.out / "ex03")
    plot_example_paths(model).savefig(args.out / "ex03_example_paths.png", dpi=110)
    layers_figure(model).savefig(args.out / "ex03_layers.png", dpi=110)
    print(f"figures in {args.out}")
