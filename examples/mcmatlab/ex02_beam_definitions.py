"""MCmatlab Example 2 (BeamDefinitions): five light sources in a cuboid of air.

The cuboid holds only air (negligible absorption and scattering, ``g = 1``), so every
packet flies straight from its launch to a face, and the far field (``far_field_res``)
is the angular distribution of the source itself. Five sources, each set up from the
previous one as MCmatlab's script changes one model step by step:

1. ``line``: an isotropically emitting line of 0.5 mm (``source_type = 1``,
   ``emitter_length``) centred in the cuboid, its axis tilted by ``theta = pi/4``
   towards +y (``phi = pi/2``);
2. ``tophat_gaussian``: a beam straight down (``source_type = 4``, focus on the
   surface) with a top-hat focal plane of radius 100 um and a Gaussian angular
   distribution of 1/e^2 half-angle pi/6;
3. ``led``: an LED-like X/Y beam (``source_type = 5``): a 400 x 200 um rectangle
   turned by ``psi = pi/4``, Lambertian in angle;
4. ``ring``: custom radial arrays: a ring in the focal plane, rings of rays in angle;
5. ``custom_xy``: custom X/Y arrays (two lobes along X, three along Y), top-hat along X
   and Gaussian along Y in angle, turned by ``psi = -pi/4``.

    python examples/mcmatlab/ex02_beam_definitions.py [--quick] [--out DIR]

The checks compare each source with its definition: one number of the focal plane,
drawn with the run's own sampler (:func:`mcmatlab_py.light.source.sample_light_source`),
and one of the angles, from the run's far field where a bin edge allows it.

Differences from MCmatlab: a fixed photon count per source instead of 0.1 min, and
no key press between the runs. As MCmatlab's, the fluence-rate plots
(``ex02_<source>_NFR.png``) show the beams in the air: ``NFR`` in thin media is the track
length per voxel; ``NA`` stays zero (with mua + mus = 2e-8 cm^-1 no packet interacts in the
cuboid). The figures also show the light leaving the faces (``NI_*``, computed here on
request) and the far field (drawn over (theta, phi), not on MCmatlab's 3-D hemisphere);
one figure gathers all five sources.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model
from mcmatlab_py.light.source import beam_axes, sample_light_source
from mcmatlab_py.monte_carlo.outputs import far_field_solid_angles

LINE_LENGTH = 0.05  #: cm, the isotropic line emitter
TOPHAT_RADIUS = 0.01  #: cm, focal plane of the second source
GAUSS_HALF_ANGLE = math.pi / 6  #: rad, 1/e^2 half-angle of the second source
LED_HALF_WIDTHS = (0.02, 0.01)  #: cm, X and Y of the LED's rectangle
RING_WIDTH = 0.025  #: cm, radial extent of the custom focal-plane array
RING_ANGLE = math.pi / 4  #: rad, angular extent of the custom angular array
XY_WIDTHS = (0.02, 0.01)  #: cm, X and Y extent of the custom X/Y arrays
XY_ANGLE = math.pi / 8  #: rad, X top-hat and Y Gaussian half-angles of the last source
Z_SIGMA = 4.0  #: checks allow this many standard errors


def ring_profile(s):
    """MCmatlab's ring: the focal-plane intensity per area over s in [0, 20]."""
    return np.exp(-((s - 4.0) ** 2))


def lobes_profile(s):
    """MCmatlab's angular rings: intensity over s in [0, 7 pi] (tan of the angle)."""
    return 1.0 + np.cos(s)


def _line(src):
    src.source_type = 1  # isotropic point or line
    src.emitter_length = LINE_LENGTH
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.0, 0.05  # the centre of the line
    src.theta, src.phi = math.pi / 4, math.pi / 2  # the line's direction


def _tophat_gaussian(src):
    src.x_focus = src.y_focus = src.z_focus = 0.0
    src.source_type = 4  # radially factorizable beam
    src.focal_plane_intensity_distribution.radial_distr = 0  # top-hat
    src.focal_plane_intensity_distribution.radial_width = TOPHAT_RADIUS
    src.angular_intensity_distribution.radial_distr = 1  # Gaussian
    src.angular_intensity_distribution.radial_width = GAUSS_HALF_ANGLE
    src.theta = 0.0


def _led(src):
    src.source_type = 5  # X/Y factorizable beam
    FP, AN = src.focal_plane_intensity_distribution, src.angular_intensity_distribution
    FP.x_distr, FP.x_width = 0, LED_HALF_WIDTHS[0]  # top-hat
    FP.y_distr, FP.y_width = 0, LED_HALF_WIDTHS[1]
    AN.x_distr = AN.y_distr = 2  # Lambertian
    src.psi = math.pi / 4


def _ring(src):
    src.source_type = 4
    FP, AN = src.focal_plane_intensity_distribution, src.angular_intensity_distribution
    FP.radial_distr = ring_profile(np.linspace(0.0, 20.0, 1000))
    FP.radial_width = RING_WIDTH
    AN.radial_distr = lobes_profile(np.linspace(0.0, 7 * math.pi, 1000))
    AN.radial_width = RING_ANGLE


def _custom_xy(src):
    src.source_type = 5
    FP, AN = src.focal_plane_intensity_distribution, src.angular_intensity_distribution
    FP.x_distr, FP.x_width = np.sin(np.linspace(0.0, 2 * math.pi, 1000)) ** 2, XY_WIDTHS[0]
    FP.y_distr, FP.y_width = np.sin(np.linspace(0.0, 3 * math.pi, 1000)) ** 2, XY_WIDTHS[1]
    AN.x_distr, AN.x_width = 0, XY_ANGLE  # top-hat
    AN.y_distr, AN.y_width = 1, XY_ANGLE  # Gaussian
    src.psi = -math.pi / 4


#: the five sources in MCmatlab's order; each changes the source left by the one before
BEAMS = {"line": _line, "tophat_gaussian": _tophat_gaussian, "led": _led, "ring": _ring,
         "custom_xy": _custom_xy}


def build(quick: bool = False, beam: str = "line") -> Model:
    """The model of Example 2 with source ``beam`` (the setups up to it applied in order);
    ``quick``: 41 x 41 x 20 voxels, 2 x 10^4 photons, far field of 20 x 20 bins."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = (41, 41, 20) if quick else (201, 201, 100)
    G.Lx, G.Ly, G.Lz = 0.2, 0.2, 0.1  # cm
    G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0)]
    G.geom_func = None  # air everywhere (media[0])

    MC = model.MC
    MC.n_photons_requested = 20_000 if quick else 1_000_000
    MC.seed = 2
    MC.progress = not quick
    MC.far_field_res = 20 if quick else 200  # both put bin edges at pi/10 and pi/4
    MC.calc_normalized_irradiance = True  # NI_zpos: the beams' footprints on the bottom face
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    for name, setup in BEAMS.items():
        setup(MC.light_source)
        if name == beam:
            return model
    raise ValueError(f"beam must be one of {list(BEAMS)}, got {beam!r}")


def run(quick: bool = False) -> dict:
    """Run the five sources; returns ``{beam name: model}``."""
    return {name: build(quick, name).run_monte_carlo() for name in BEAMS}


# ------------------------------------------------------------------ expectations

def _mean(f, weight, lo: float, hi: float) -> float:
    """Mean of f(s) under the density ``weight(s)`` on [lo, hi] (fine trapezoid rule)."""
    s = np.linspace(lo, hi, 200_001)
    w = weight(s)
    return float(np.trapezoid(f(s) * w, s) / np.trapezoid(w, s))


def expected_ring_radius() -> float:
    """cm, mean focal-plane radius of the ring: the array is intensity per area, so the
    density of the radius is r I(r)."""
    scale = RING_WIDTH / 20.0
    return scale * _mean(lambda s: s, lambda s: s * ring_profile(s), 0.0, 20.0)


def expected_ring_fraction(theta_max: float) -> float:
    """Fraction of the ring source's rays within ``theta_max`` of the axis: the angular
    array spans tan(angle) in [0, tan(RING_ANGLE)], intensity per area of tan space."""
    t_max = math.tan(RING_ANGLE)
    t = math.tan(theta_max) / t_max * 7 * math.pi  # the array's argument at theta_max

    def density(s):
        return s * lobes_profile(s)

    s = np.linspace(0.0, 7 * math.pi, 200_001)
    inside = s <= t
    return float(np.trapezoid(density(s) * inside, s) / np.trapezoid(density(s), s))


def expected_xy_square(width: float, lobes: int) -> float:
    """cm^2, mean square offset along X of a sin^2 array of ``lobes`` lobes over [-width, width]."""
    return width**2 * _mean(lambda s: (2 * s - 1) ** 2,
                            lambda s: np.sin(lobes * math.pi * s) ** 2, 0.0, 1.0)


# ------------------------------------------------------------------ measurements

def far_field_fraction(model, theta_max: float) -> tuple[float, int]:
    """Fraction of the far field's power within ``theta_max`` of +z, and the packets.

    ``theta_max`` must be a bin edge of the far field (bins of pi / far_field_res).
    """
    MC = model.MC
    k = theta_max / (math.pi / MC.far_field_res)
    if abs(k - round(k)) > 1e-9:
        raise ValueError(f"theta_max = {theta_max} is not a far-field bin edge")
    FF = MC.far_field
    return float(FF[: round(k)].sum() / FF.sum()), MC.n_photons


def launches(model) -> dict:
    """Launch points and directions of ``n_photons`` packets of the model's source, in the
    beam's frame: ``a``, ``b`` (cm) along v and w in the focal plane, ``tx``, ``ty`` (tan
    of the ray's angles in the (u, v) and (u, w) planes), ``tan_theta``, and ``s`` (cm,
    position along the axis from the focus)."""
    src = model.MC.light_source
    d = sample_light_source(model, model.MC.n_photons, seed=model.MC.seed)
    u, v, w = beam_axes(src.theta, src.phi, src.psi)
    p = np.stack([d["x"] - src.x_focus, d["y"] - src.y_focus, d["z"] - src.z_focus])
    r = np.stack([d["ux"], d["uy"], d["uz"]])
    along = u @ r
    return {"a": v @ p, "b": w @ p, "s": u @ p, "tx": (v @ r) / along, "ty": (w @ r) / along,
            "tan_theta": np.sqrt((v @ r) ** 2 + (w @ r) ** 2) / along}


def mean_entry(samples: np.ndarray, expected: float, what: str) -> dict:
    """The mean of per-packet ``samples`` against ``expected``, within Z_SIGMA standard errors."""
    se = float(samples.std(ddof=1) / math.sqrt(samples.size))
    return {"value": float(samples.mean()), "expected": expected, "tol": Z_SIGMA * se,
            "what": what}


def fraction_entry(model, theta_max: float, expected: float, what: str) -> dict:
    """A far-field fraction against ``expected``, within Z_SIGMA binomial standard errors."""
    p, n = far_field_fraction(model, theta_max)
    return {"value": p, "expected": expected,
            "tol": Z_SIGMA * math.sqrt(expected * (1 - expected) / n), "what": what}


def check(models: dict) -> dict:
    """Each source against its definition: a focal-plane statistic and an angular one."""
    out = {}
    m = models["line"]
    out["line_length"] = mean_entry(
        launches(m)["s"] ** 2, LINE_LENGTH**2 / 12,
        "mean square position along the line (cm^2): uniform over its length L, L^2/12")
    out["line_isotropic"] = fraction_entry(
        m, math.pi / 4, (1 - math.cos(math.pi / 4)) / 2,
        "far-field fraction within pi/4 of +z: isotropic, (1 - cos(pi/4)) / 2")

    m = models["tophat_gaussian"]
    L = launches(m)
    out["tophat_radius"] = mean_entry(
        L["a"] ** 2 + L["b"] ** 2, TOPHAT_RADIUS**2 / 2,
        "mean square focal-plane radius (cm^2): top-hat disc of radius R, R^2/2")
    t_ratio = math.tan(math.pi / 10) / math.tan(GAUSS_HALF_ANGLE)
    out["gaussian_angle"] = fraction_entry(
        m, math.pi / 10, 1 - math.exp(-2 * t_ratio**2),
        "far-field fraction within pi/10: Gaussian in tan(angle), 1/e^2 at tan(pi/6)")

    m = models["led"]
    out["led_rectangle"] = mean_entry(
        launches(m)["a"] ** 2, LED_HALF_WIDTHS[0] ** 2 / 3,
        "mean square offset along the turned X axis (cm^2): uniform over [-X, X], X^2/3")
    out["led_lambertian"] = fraction_entry(
        m, math.pi / 4, math.sin(math.pi / 4) ** 2,
        "far-field fraction within pi/4: Lambertian, sin^2(pi/4)")

    m = models["ring"]
    L = launches(m)
    out["ring_radius"] = mean_entry(
        np.hypot(L["a"], L["b"]), expected_ring_radius(),
        "mean focal-plane radius (cm) of the custom ring array (intensity per area)")
    out["ring_angles"] = fraction_entry(
        m, math.pi / 10, expected_ring_fraction(math.pi / 10),
        "far-field fraction within pi/10 of the custom angular rings")

    m = models["custom_xy"]
    L = launches(m)
    out["xy_lobes"] = mean_entry(
        L["a"] ** 2, expected_xy_square(XY_WIDTHS[0], 2),
        "mean square offset along the turned X axis (cm^2) of the two-lobe sin^2 array")
    out["xy_gaussian_angle"] = mean_entry(
        L["ty"] ** 2, math.tan(XY_ANGLE) ** 2 / 4,
        "mean square tan(angle) along Y: Gaussian with 1/e^2 at tan(pi/8), tan^2(pi/8) / 4")
    return out


def beams_figure(models: dict):
    """Per source: where its packets cross the focal plane (the line: where they start,
    seen along x), the light leaving the bottom face (``NI_zpos``), and the far field."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, len(models), figsize=(12, 7.4), layout="constrained")
    for col, (name, model) in enumerate(models.items()):
        G, MC = model.G, model.MC
        d = sample_light_source(model, MC.n_photons, seed=MC.seed)
        ax = axes[0, col]
        if name == "line":
            ax.hist2d(d["y"], d["z"], bins=80, cmap="inferno", cmin=1,
                      range=[[-G.Ly / 4, G.Ly / 4], [0.0, G.Lz]])
            ax.set(xlabel="y [cm]", ylabel="z [cm] (start points)", ylim=(G.Lz, 0.0))
        else:
            h = 0.03
            ax.hist2d(d["x"], d["y"], bins=80, cmap="inferno", cmin=1, range=[[-h, h], [-h, h]])
            ax.set(xlabel="x [cm]", ylabel="y [cm] (focal plane)" if col == 1 else None)
        ax.set_aspect("equal")
        ax.set_title(name)
        ax = axes[1, col]
        ax.imshow(MC.NI_zpos.T, origin="lower", cmap="inferno",
                  extent=[-G.Lx / 2, G.Lx / 2, -G.Ly / 2, G.Ly / 2])
        ax.set(xlabel="x [cm]", ylabel="y [cm], light leaving the bottom" if col == 0 else None)
        ax = axes[2, col]
        ax.pcolormesh(np.degrees(MC.far_field_phi), np.degrees(MC.far_field_theta),
                      MC.far_field / far_field_solid_angles(MC.far_field_res),  # W/sr/W
                      shading="nearest", cmap="inferno", vmin=0.0)
        ax.set(xlabel="phi [deg]",
               ylabel="theta [deg] (far field, W/sr/W)" if col == 0 else None,
               ylim=(180, 0))
    fig.suptitle("Example 2: focal plane (sampled), light leaving the bottom face 1 mm below, "
                 "far field")
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    models = run(args.quick)
    for name, c in check(models).items():
        print(f"{name}: {c['value']:.6g} (expected {c['expected']:.6g} +- {c['tol']:.2g}; "
              f"{c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    import matplotlib.pyplot as plt

    from mcmatlab_py.plotting.outputs import plot_boundary_irradiance, plot_far_field

    models["line"].plot("G", args.out / "ex02")
    for name, model in models.items():
        # MCmatlab's plot(model, 'MC'): the fluence rate in the air (the track length)
        model.plot("MC")["NFR"].savefig(args.out / f"ex02_{name}_NFR.png", dpi=110)
        plot_boundary_irradiance(model).savefig(args.out / f"ex02_{name}_NI.png", dpi=110)
        plot_far_field(model).savefig(args.out / f"ex02_{name}_far_field.png", dpi=110)
        plt.close("all")
    beams_figure(models).savefig(args.out / "ex02_beams.png", dpi=110)
    print(f"figures in {args.out}")
