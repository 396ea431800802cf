"""MCmatlab Example 14 (Thermochromism): an absorption coefficient that depends on temperature.

A wedge of thermochromic material hangs in water above a flat sheet of the same material
(0.7 to 0.9 mm deep). Its absorption falls linearly from 150 cm^-1 at 20 deg C to
(almost) nothing at 40 deg C, ``mua = 150 max(1e-8, (40 - T) / 20)``; mus = 30 cm^-1,
g = 0.8, and a VHC of 2000 J cm^-3 K^-1 (water's is 4.19: it heats slowly). A Gaussian beam
(1/e^2 radius 50 um in its focus, 10 deg divergence, 2 W, 532 nm) tilted 30 deg towards
-y is focused into the sheet through the wedge. The light is on for 200 ms with 50
updates; every 2 updates (8 ms) the material's mua is re-evaluated at the voxel
temperatures (150 sub-media) and the Monte Carlo re-run. The wedge bleaches where the
beam crosses it and lets the light through to the sheet, which bleaches in turn.

    python examples/mcmatlab/ex14_thermochromism.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count instead of 0.02 min of simulation; the
heat equation on finite elements with the nodes at the voxel corners; the power is
``HS.P`` (MCmatlab's ``MC.P``); the first Monte Carlo sees 20 deg C through ``MC.T``
(MCmatlab takes it from ``HS.T``). The figures of the Monte Carlo are those of its last
run, at the end of the heat simulation (MCmatlab plots them before and after).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model

T0 = 20.0  #: deg C, initial temperature
N_BINS = 150  #: sub-media of the thermochromic material
MUA_COLD = 150.0  #: cm^-1, at 20 deg C
T_CLEAR = 40.0  #: deg C, where the absorption has gone


def thermochromic_mua(wavelength, FR, T, FD):
    """cm^-1: 150 at 20 deg C, falling linearly to 1e-8 of that at 40 deg C and above."""
    return MUA_COLD * np.maximum(1e-8, (T_CLEAR - T) / (T_CLEAR - T0))


def geometry(X, Y, Z):
    """0 water, 1 thermochromic: a wedge between two slanted planes, and a sheet below."""
    M = np.zeros(X.shape, dtype=int)
    M[0.2 * Y + (Z - 0.03) > 0] = 1
    M[-0.2 * Y + (Z - 0.05) > 0] = 0
    M[Z > 0.07] = 1
    M[Z > 0.09] = 0
    return M


def build(quick: bool = False) -> Model:
    """The model of Example 14; ``quick``: 30^3 voxels, 5 x 10^3 photons per Monte Carlo run
    and a 15^3 heat mesh."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 30 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = [
        Medium("water", mua=0.00036, mus=10.0, g=1.0, VHC=4.19, TC=5.8e-3),
        Medium("thermochromic material", mua=thermochromic_mua, mus=30.0, g=0.8,
               VHC=2000.0, TC=5e-3, n_bins=N_BINS),
    ]
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 5_000 if quick else 500_000
    MC.seed = 14
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    MC.T = T0  # deg C, what the first Monte Carlo sees
    src = MC.light_source
    src.source_type = 4  # radially factorizable beam
    src.focal_plane_intensity_distribution.radial_distr = 1  # Gaussian
    src.focal_plane_intensity_distribution.radial_width = 0.005  # cm
    src.angular_intensity_distribution.radial_distr = 1  # Gaussian
    src.angular_intensity_distribution.radial_width = math.radians(10)  # 1/e^2 half-angle
    src.x_focus, src.y_focus, src.z_focus = 0.0, -0.017, 0.078
    src.theta, src.phi = math.pi / 6, -math.pi / 2

    HS = model.HS
    HS.P = 2.0  # W
    HS.large_time_steps = True
    HS.heat_boundary_type = 0  # insulating
    HS.duration_on, HS.duration_off, HS.duration_end = 0.2, 0.0, 0.0
    HS.T_initial = T0
    HS.plot_temp_limits = (20.0, 50.0)
    HS.n_updates = 50
    HS.media_prop_recalc_period = 2  # re-run the Monte Carlo every 8 ms if mua changed
    HS.temp_sensor_positions = [(0, 0.009, 0.032), (0, 0.002, 0.044), (0, -0.007, 0.059),
                                (0, -0.017, 0.078)]
    HS.progress = not quick
    if quick:
        HS.mesh_divisions = (15, 15, 15)
    return model


def run(quick: bool = False) -> Model:
    """Build the model, run the Monte Carlo and the heat simulation (with its re-runs)."""
    model = build(quick).run_monte_carlo()
    return model.simulate_heat_distribution()


def mua_of_last_run(model) -> tuple[np.ndarray, np.ndarray]:
    """(mua, T) over the thermochromic voxels: the sub-medium mua (cm^-1) the last Monte Carlo
    ran on and the temperature (deg C) it was given."""
    G, MC = model.G, model.MC
    inside = G.medium_map() == 1
    mua = MC.media_properties.mua[MC.M]
    T = np.broadcast_to(MC.T, inside.shape)
    return mua[inside], T[inside]


def check(model) -> dict:
    """mua has gone where the temperature passed 40 deg C, and stays where it did not rise."""
    mua, T = mua_of_last_run(model)
    hot, cold = T >= T_CLEAR, T < T0 + 0.1
    bin_width = MUA_COLD / N_BINS  # farthest-point bins lie at most this far from a voxel
    return {
        "bleached": {
            "value": mua[hot].mean() if hot.any() else math.nan,
            "expected": 0.0, "tol": bin_width,
            "what": f"mean mua (cm^-1) of the last Monte Carlo where T >= {T_CLEAR:g} deg C "
                    "(NaN: no voxel got there); tolerance: one bin"},
        "unheated": {
            "value": mua[cold].mean() if cold.any() else math.nan,
            "expected": thermochromic_mua(None, 0.0, T[cold], 0.0).mean(), "tol": bin_width,
            "what": f"mean mua (cm^-1) where T < {T0 + 0.1:g} deg C against mua(T) there "
                    "(about 150); tolerance: one bin"},
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    model = run(args.quick)
    print(f"{model.HS.mc_runs} Monte Carlo re-runs; at the end "
          f"{100 * model.MC.absorbed_fraction:.3g}% of the light was absorbed in the cuboid")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    for what in ("G", "HS", "MC"):  # MC: the last run, on the bleached material
        model.plot(what, args.out / "ex14")
    print(f"figures in {args.out}")
