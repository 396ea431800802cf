"""MCmatlab Example 4 (BloodVessel): a top-hat beam on skin with a blood vessel, then heat.

A collimated top-hat beam of radius 300 um at 532 nm falls on skin under a layer of
gel (water): epidermis, dermis and a blood vessel of radius 100 um at 0.4 mm below
the skin surface, along y (the mcxyz website's example, with every face escaping and
100^3 voxels). The media's mua and mus come from Jacques' formulas
(:func:`mcmatlab_py.calc_mua`, :func:`mcmatlab_py.calc_mus`). The absorbed power
then drives the heat simulation: 5 pulses of 1 ms at 3 W peak power with 4 ms off,
then 20 ms of cooling, from 37 deg C, insulating boundaries; four temperature sensors
along the axis across the top of the vessel, and Arrhenius damage of the blood
(MCmatlab's placeholder E and A).

    python examples/mcmatlab/ex04_blood_vessel.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count instead of 0.1 min of simulation;
the heat equation on finite elements whose nodes are the voxel corners (the
temperatures at the voxel centres are ``HS.T_voxels``), not MCmatlab's voxel finite
differences; ``useAllCPUs`` is not a setting (numba uses every core); no movie
(``make_movie`` needs imageio-ffmpeg; the figures show the temperature and damage).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model, calc_mua, calc_mus

Z_SURF = 0.01  #: cm, the skin surface (gel above)
EPIDERMIS = 0.006  #: cm, epidermis thickness
VESSEL_RADIUS = 0.01  #: cm
VESSEL_DEPTH = 0.04  #: cm below the skin surface (of the vessel's axis)


def geometry(X, Y, Z):
    """0 water (gel), 1 epidermis, 2 dermis, 3 blood: a vessel along y at x = 0."""
    M = np.zeros(X.shape, dtype=int)
    M[Z > Z_SURF] = 1
    M[Z > Z_SURF + EPIDERMIS] = 2
    M[X**2 + (Z - (Z_SURF + VESSEL_DEPTH)) ** 2 < VESSEL_RADIUS**2] = 3
    return M


def media() -> list[Medium]:
    """MCmatlab's four media; mua(wavelength) from (S, B, W, F, M), mus from (a', f_Ray, b_Mie, g)."""
    skin_vhc, skin_tc = 3391 * 1.109e-3, 0.37e-2  # J cm^-3 K^-1, W cm^-1 K^-1
    return [
        Medium("water", mua=0.00036, mus=10.0, g=1.0, VHC=4.19, TC=5.8e-3),
        Medium("epidermis",
               mua=lambda w: calc_mua(w, S=0.75, B=0.0, W=0.75, F=0.0, M=0.03),
               mus=lambda w: calc_mus(w, 40.0, 0.0, 1.0, 0.9),
               g=0.9, VHC=skin_vhc, TC=skin_tc),
        Medium("dermis",
               mua=lambda w: calc_mua(w, S=0.67, B=0.002, W=0.65, F=0.0, M=0.0),
               mus=lambda w: calc_mus(w, 42.4, 0.62, 1.0, 0.9),
               g=0.9, VHC=skin_vhc, TC=skin_tc),
        Medium("blood",
               mua=lambda w: calc_mua(w, S=0.75, B=1.0, W=0.95, F=0.0, M=0.0),
               mus=lambda w: calc_mus(w, 10.0, 0.0, 1.0, 0.9),
               g=0.9, VHC=3617 * 1.050e-3, TC=0.52e-2,
               E=422.5e3, A=7.6e66),  # J/mol, 1/s: MCmatlab's placeholder values
    ]


def build(quick: bool = False) -> Model:
    """The model of Example 4; ``quick``: 40^3 voxels, 2 x 10^4 photons, a 20^3 heat mesh."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 40 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = media()
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 20_000 if quick else 2_000_000
    MC.seed = 4
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    src = MC.light_source
    src.source_type = 4  # radially factorizable beam
    src.focal_plane_intensity_distribution.radial_distr = 0  # top-hat
    src.focal_plane_intensity_distribution.radial_width = 0.03  # cm
    src.angular_intensity_distribution.radial_distr = 0  # top-hat ...
    src.angular_intensity_distribution.radial_width = 0.0  # ... of zero width: collimated
    src.x_focus = src.y_focus = src.z_focus = 0.0
    src.theta = src.phi = 0.0

    HS = model.HS
    HS.P = 3.0  # W, peak power of the pulses (MCmatlab's model.MC.P)
    HS.heat_boundary_type = 0  # insulating
    HS.duration_on = 0.001  # s
    HS.duration_off = 0.004  # s
    HS.duration_end = 0.02  # s of cooling after the pulse train
    HS.n_pulses = 5
    HS.T_initial = 37.0  # deg C
    HS.plot_temp_limits = (37.0, 100.0)
    HS.n_updates = 10 if quick else 50
    # MCmatlab's (0.5, 0.6, 1) puts the xy slice on the bottom wall of its 3-D view; on the
    # flat panels here that is the bottom face, unheated: slice through the hottest voxel
    HS.slice_positions = None
    HS.temp_sensor_positions = [(0, 0, 0.038), (0, 0, 0.04), (0, 0, 0.042), (0, 0, 0.044)]
    HS.progress = not quick
    if quick:
        HS.mesh_divisions = (20, 20, 20)  # a sparse LU of the 40^3-node mesh takes ~20 s
    return model


def run(quick: bool = False) -> Model:
    """Build the model, run the Monte Carlo and then the heat simulation."""
    model = build(quick).run_monte_carlo()
    return model.simulate_heat_distribution()


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


def heat_balance(model) -> tuple[float, float]:
    """Heat gained by the tissue over the energy absorbed from the pulses, and its tolerance.

    With insulating faces no heat leaves, so the heat content ``sum_i C_i (T_i - T0)``
    (C the lumped P1 heat capacity of node i, J/K) equals ``P x (total on time) x`` the
    absorbed fraction: the ratio is 1. The implicit steps conserve it up to the linear
    solver: the iterative one (large meshes) stops at a residual of 1e-9 of a right-hand
    side that holds the heat content ``C T``, so each step may be off by
    ``1e-9 sum_i C_i |T_i|``; the tolerance adds that over the steps (the sparse LU of
    small meshes is exact to rounding).
    """
    import fem

    G, MC, HS = model.G, model.MC, model.HS
    vhc = np.array([m.VHC for m in G.media])
    elem_medium = G.medium_map().ravel()[fem.element_voxel_index(HS.mesh, G.grid)]
    capacity = fem.lumped_mass(HS.mesh, vhc[elem_medium])  # J/K per node
    gained = float(capacity @ (HS.T_nodes - np.mean(HS.T_initial)))
    delivered = HS.P * HS.n_pulses * HS.duration_on * MC.absorbed_fraction
    n_steps = HS.sensor_times.size - 1
    tol = 1e-9 * n_steps * float(capacity @ np.abs(HS.T_nodes)) / delivered
    return gained / delivered, tol


def check(model) -> dict:
    """Symmetry of the absorption, and conservation of the absorbed energy as heat."""
    ratio, tol = heat_balance(model)
    return {
        "mirror_symmetry": {
            "value": mirror_z_score(model), "expected": 0.0, "tol": 4.0,
            "what": "|absorbed power across x = 0 and y = 0| in standard errors (bound sqrt(f/N))"},
        "heat_balance": {
            "value": ratio, "expected": 1.0, "tol": tol,
            "what": "heat content gained / energy absorbed (insulating faces: 1)"},
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    model = run(args.quick)
    print(f"{100 * model.MC.absorbed_fraction:.3g}% of the incident light was absorbed "
          "within the cuboid")
    names = [m.name for m in model.G.media]
    for name, T in zip(names, model.HS.max_media_temps, strict=True):
        print(f"highest temperature in the {name}: {T:.1f} deg C")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    for what in ("G", "MC", "HS"):  # MCmatlab's plot(model, 'G'), 'MC', 'HS'
        model.plot(what, args.out / "ex04")
    print(f"figures in {args.out}")
