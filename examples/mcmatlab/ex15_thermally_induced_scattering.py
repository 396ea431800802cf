"""MCmatlab Example 15 (ThermallyInducedScattering): scattering that rises with thermal damage.

Egg white (0.3 to 0.8 mm deep, under water) rests on a black absorber (mua = 300 cm^-1).
A top-hat beam (radius 150 um in its focus on the absorber's surface, Gaussian divergence
of 10 deg, 0.5 W, 532 nm) heats the absorber for 20 ms, then 20 ms of cooling; the faces
are held at the initial 20 deg C. The egg white coagulates by Arrhenius' law (MCmatlab's
placeholder E and A), and its scattering follows the fractional damage
``FD = 1 - exp(-Omega)``: ``mus = 1 + 1000 FD`` cm^-1 (20 sub-media). Every 5 updates
the Monte Carlo is re-run on the new scattering: the opaque dome of coagulated egg white
over the hot spot turns the light back, and less of it reaches the absorber.

    python examples/mcmatlab/ex15_thermally_induced_scattering.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count instead of 0.05 min of simulation; the
heat equation on finite elements with the nodes at the voxel corners; the power is
``HS.P`` (MCmatlab's ``MC.P``); the first Monte Carlo sees 20 deg C through ``MC.T``.
The figures of the Monte Carlo (and the 50 example paths) are those of its last run, at
the end of the heat simulation.
"""

from __future__ import annotations

import argparse
import copy
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model

T0 = 20.0  #: deg C, initial and boundary temperature
N_BINS = 20  #: sub-media of the egg white
EGG_WHITE, ABSORBER = 1, 2  #: medium indices


def egg_white_mus(wavelength, FR, T, FD):
    """cm^-1: 1 for native egg white, 1001 when fully coagulated."""
    return 1.0 + 1000.0 * FD


def geometry(X, Y, Z):
    """0 water, 1 egg white below 0.3 mm, 2 absorber below 0.8 mm."""
    M = np.zeros(X.shape, dtype=int)
    M[Z > 0.03] = EGG_WHITE
    M[Z > 0.08] = ABSORBER
    return M


def build(quick: bool = False) -> Model:
    """The model of Example 15; ``quick``: 30^3 voxels, 5 x 10^3 photons per Monte Carlo run
    and a 15^3 heat mesh."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 30 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = [
        Medium("water", mua=0.00036, mus=10.0, g=1.0, VHC=4.19, TC=5.8e-3),
        Medium("egg white", mua=1.0, mus=egg_white_mus, g=0.5, VHC=4.19, TC=5.8e-3,
               E=390e3, A=7.6e67, n_bins=N_BINS),  # J/mol, 1/s: MCmatlab's placeholders
        Medium("absorber", mua=300.0, mus=100.0, g=0.9, VHC=4.19, TC=5.8e-3),
    ]
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 5_000 if quick else 500_000
    MC.seed = 15
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    MC.n_example_paths = 50
    MC.T = T0
    src = MC.light_source
    src.source_type = 4  # radially factorizable beam
    src.focal_plane_intensity_distribution.radial_distr = 0  # top-hat
    src.focal_plane_intensity_distribution.radial_width = 0.015  # cm
    src.angular_intensity_distribution.radial_distr = 1  # Gaussian
    src.angular_intensity_distribution.radial_width = math.radians(10)  # 1/e^2 half-angle
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.0, 0.08
    src.theta = src.phi = 0.0

    HS = model.HS
    HS.P = 0.5  # W
    HS.large_time_steps = True
    HS.heat_boundary_type = 1  # faces held at their initial temperature
    HS.duration_on, HS.duration_off, HS.duration_end = 0.02, 0.0, 0.02
    HS.n_pulses = 1
    HS.T_initial = T0
    HS.plot_temp_limits = (20.0, 130.0)
    HS.n_updates = 30
    HS.media_prop_recalc_period = 5
    HS.temp_sensor_positions = [(0, 0, 0.065), (0, 0, 0.075), (0, 0, 0.085)]
    HS.progress = not quick
    if quick:
        HS.mesh_divisions = (15, 15, 15)
    return model


def run(quick: bool = False) -> Model:
    """Build the model, run the Monte Carlo and the heat simulation (with its re-runs)."""
    model = build(quick).run_monte_carlo()
    return model.simulate_heat_distribution()


def absorber_fraction(model) -> float:
    """Fraction of the incident power absorbed in the absorber by the last Monte Carlo run."""
    G, MC = model.G, model.MC
    return float(MC.NA[G.medium_map() == ABSORBER].sum() * G.dx * G.dy * G.dz)


def native_egg_white(model) -> Model:
    """The first Monte Carlo again, on undamaged egg white at 20 deg C."""
    before = copy.deepcopy(model)
    before.MC.T, before.MC.FD = T0, 0.0
    return before.run_monte_carlo()


def check(model) -> dict:
    """mus has risen where the egg white coagulated, and shields the absorber."""
    G, MC = model.G, model.MC
    egg = G.medium_map() == EGG_WHITE
    FD = np.broadcast_to(MC.FD, egg.shape)[egg]
    mus = MC.media_properties.mus[MC.M][egg]
    damaged = FD > 0.5
    after, before = absorber_fraction(model), absorber_fraction(native_egg_white(model))
    n = MC.n_photons
    return {
        "mus_where_damaged": {
            "value": mus[damaged].mean() - egg_white_mus(None, 0, 0, FD[damaged]).mean()
            if damaged.any() else math.nan,
            "expected": 0.0, "tol": 1000.0 / N_BINS,
            "what": "mean mus (cm^-1) of the last Monte Carlo where FD > 0.5, minus "
                    "1 + 1000 FD there (NaN: no damage); tolerance: one bin"},
        "absorber_shielded": {
            "value": (before - after) / math.sqrt((before + after) / n), "min": 4.0,
            "what": "power absorbed in the absorber before the damage minus after, in "
                    "standard errors (bound sqrt(f / N))"},
    }


if __name__ == "__main__":
    from mcmatlab_py.plotting.outputs import plot_example_paths

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    model = run(args.quick)
    print(f"{model.HS.mc_runs} Monte Carlo re-runs; at the end "
          f"{100 * absorber_fraction(model):.3g}% of the light reached the absorber")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    for what in ("G", "HS", "MC"):  # MC: the last run, through the coagulated egg white
        model.plot(what, args.out / "ex15")
    plot_example_paths(model).savefig(args.out / "ex15_example_paths.png", dpi=110)
    print(f"figures in {args.out}")
