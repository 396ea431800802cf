"""MCmatlab Example 6 (TimeTagging): a time-resolved image of light scattered by two
diagonal lines of voxels in air.

A plane wave (``source_type = 2``) falls straight down (+z) on a 1 mm cube of air
holding two lines of weakly absorbing isotropic scatterers (mus = 100 cm^-1, g = 0):
the voxels of the x = y = z - Lz/2 diagonal and those of the yz diagonal in the first
x layer. A lens (f = 2 mm, aperture 2 mm, field 2 mm, 100 x 100 pixels) looks at the
cube's centre along (theta, phi) = (atan(1/sqrt(2)), -3 pi/4), from above the top face;
its detection is split into 100 time bins from -0.15 to 5.5 ps (plus a bin before and
one after). The xyz diagonal lies in the lens's object plane: light scattered once at
depth z has flown z to the scatterer and nothing more to the object plane, so it
arrives at t = z / c, imaged at Y = -sqrt(3) (z - Lz/2). The image therefore shows a
spot running along the diagonal as time goes on; the yz diagonal is seen obliquely.

    python examples/mcmatlab/ex06_time_tagging.py [--quick] [--out DIR]

The check uses a second run of the same model in which only singly scattered packets
reach the image (``deposition_criteria``: exactly one scattering).

Differences from MCmatlab: a fixed number of collected packets
(``request_collected_photons``) instead of ``simulationTimeRequested = 0.5`` min; the
figure shows the time-integrated image and a few time bins side by side instead of
MCmatlab's time slider.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model
from mcmatlab_py.light.collector import DepositionCriteria

C = 29979245800.0  #: cm/s, speed of light in vacuum (the media have n = 1)


def geometry(X, Y, Z):
    """0: air; 1: the voxels of the xyz diagonal and of the yz diagonal at the first x."""
    M = np.zeros(X.shape, dtype=int)
    i = np.arange(min(X.shape))
    M[i, i, i] = 1
    M[0, i, i] = 1
    return M


def build(quick: bool = False) -> Model:
    """The model of Example 6 (20^3 voxels as MCmatlab); ``quick``: fewer collected packets."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 20
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0),
               Medium("test scatterer", mua=1e-7, mus=100.0, g=0.0)]
    G.geom_func = geometry

    MC = model.MC
    MC.seed = 6
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    src = MC.light_source
    src.source_type = 2  # plane wave
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.0, G.Lz / 2
    MC.use_light_collector = True
    MC.request_collected_photons = True
    MC.n_photons_requested = 3_000 if quick else 100_000  # collected packets
    LC = MC.light_collector
    LC.x, LC.y, LC.z = 0.0, 0.0, G.Lz / 2  # cm, centre of the object plane
    LC.theta, LC.phi = math.atan(1 / math.sqrt(2)), -3 * math.pi / 4
    LC.f, LC.diam, LC.field_size = 0.2, 0.2, 0.2  # cm: a lens
    LC.res = 100
    LC.t_start, LC.t_end, LC.n_time_bins = -1.5e-13, 5.5e-12, 100  # s
    return model


def run(quick: bool = False) -> dict:
    """MCmatlab's run (``"model"``) and the same with only singly scattered light (``"single"``)."""
    model = build(quick).run_monte_carlo()
    single = build(quick)
    single.MC.seed = 60
    single.MC.n_photons_requested = 6_000 if quick else 30_000
    single.MC.deposition_criteria = DepositionCriteria(min_scatterings=1, max_scatterings=1)
    return {"model": model, "single": single.run_monte_carlo()}


def diagonal_slope(model) -> tuple[float, float]:
    """Power-weighted least-squares slope of Y against sqrt(3) c t on the xyz diagonal's
    image, and a bound of its standard error.

    Pixels with |X| < 0.1 mm and time bins with c t > 0.35 mm (away from the yz
    diagonal's image, which crosses X = 0 near the top, at c t < 0.25 mm). The cut is on
    the time, the regressor: a cut on Y would bias the slope. Single scattering gives a slope of -1. Each
    packet's offset from the line ``Y = -sqrt(3)(c t - Lz/2)`` is bounded by where in
    its voxel it scattered (half a voxel along each axis, times the projections) and
    the binning (half a pixel, half a time bin); this offset is the same on average for
    every voxel of the diagonal, so it moves the line but not its slope. The standard
    error is at most that bound over sqrt(packets) times the spread of sqrt(3) c t.
    """
    G, LC = model.G, model.MC.light_collector
    img = LC.image[:, :, 1:-1]  # (res, res, n_time_bins): drop before/after
    X, Y, T = np.meshgrid(LC.X, LC.Y, LC.t[1:-1], indexing="ij")
    w = np.where((np.abs(X) < 0.01) & (C * T > 0.035), img, 0.0)
    s = math.sqrt(3) * C * T
    s_mean = (w * s).sum() / w.sum()
    s_var = (w * (s - s_mean) ** 2).sum() / w.sum()
    slope = float((w * (s - s_mean) * Y).sum() / w.sum() / s_var)
    dt = (LC.t_end - LC.t_start) / LC.n_time_bins
    bound = math.sqrt(3) * G.dx + LC.field_size / LC.res / 2 + math.sqrt(3) * C * dt / 2
    n = model.MC.n_photons_collected * w.sum() / LC.image.sum()
    return slope, bound / math.sqrt(n * s_var)


def check(result: dict) -> dict:
    """Time of flight: singly scattered light reaches the object plane at t = z / c.

    The slope of the diagonal's image position against sqrt(3) c t is -1 within 4
    standard errors (:func:`diagonal_slope`; about 3% in the quick run, 1% in the full one).

    MCmatlab's run itself has no such clean number: with 10^8 packets launched, a few
    scatter in the air (mus = 1e-8 cm^-1) between the lens and the object plane, and
    arrive "before" t = 0 (that bin is not empty in the full run).
    """
    slope, se = diagonal_slope(result["single"])
    return {
        "arrival_time_slope": {
            "value": slope, "expected": -1.0, "tol": 4 * se,
            "what": "dY / d(sqrt(3) c t) on the diagonal's image, single scattering "
                    "(4 standard errors)"},
    }


def time_figure(model):
    """The time-integrated image and the image in four time bins (log scale)."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    LC = model.MC.light_collector
    h = LC.field_size / 2
    frames = [("all times", LC.image.sum(axis=2))]
    for t_ps in (0.5, 1.5, 2.5, 3.2):
        k = int(np.argmin(np.abs(LC.t - t_ps * 1e-12)))
        frames.append((f"t = {LC.t[k] * 1e12:.2f} ps", LC.image[:, :, k]))
    fig, axes = plt.subplots(1, 5, figsize=(14, 3.2), layout="constrained")
    vmax = frames[0][1].max()
    for ax, (title, img) in zip(axes, frames, strict=True):
        norm = LogNorm(vmin=vmax * 1e-4, vmax=vmax if title == "all times" else img.max() or 1)
        ax.imshow(np.where(img > 0, img, np.nan).T, origin="lower", extent=[-h, h, -h, h],
                  cmap="inferno", norm=norm)
        ax.set(title=title, xlabel="X [cm]")
    axes[0].set_ylabel("Y [cm]")
    fig.suptitle("Lens image of the scatterers, time-resolved (log scale)")
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="few collected packets (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    result = run(args.quick)
    model = result["model"]
    print(f"{model.MC.n_photons:.3g} packets launched, {model.MC.n_photons_collected} collected")
    for name, c in check(result).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex06")
    time_figure(model).savefig(args.out / "ex06_time_resolved.png", dpi=100)
    print(f"figures in {args.out}")
