"""MCmatlab Test 1 (AllFRTDependences): every property depends on fluence rate and temperature.

Two layers (material 1 above 0.1 mm, material 2 below) whose mua, mus, g, quantum yield,
VHC and TC are all functions of the fluence rate FR (W/cm^2) and the temperature T
(deg C), split into 20 and 30 sub-media. A rectangular X/Y beam (top-hat, 200 x 100 um
half-widths, Lambertian divergence of pi/8 in both directions, turned pi/4 about its
axis, 2 W, 532 nm) starts on a random initial temperature field of 0 to 5 deg C. The
Monte Carlo is iterated on the fluence rate, the fluorescence at 600 nm follows, and the
heat simulation gives 2 pulses of 6 ms on and 4 ms off and 3 ms of cooling, with the
faces held at their initial temperatures; every 10 updates (at the end of each pulse)
the media are re-evaluated and the Monte Carlo (iterated on the fluence rate again) and
the fluorescence re-run. The fluorescence heats where it is absorbed, not where it is
emitted.

    python examples/mcmatlab/test1_all_frt_dependences.py [--quick] [--out DIR]

Differences from MCmatlab: a fixed photon count instead of 0.05 and 0.1 min of
simulation; ``MC.fr_dep_iterations = 20`` is set (the default of the MCmatlab version the
script was written for; MCmatlab 4's is 0); the power is ``MC.P`` for the Monte Carlo and
``HS.P`` for the heat simulation (MCmatlab's ``MC.P`` serves both); material 1's power
yield ``PY`` (not a ``Medium`` field) is given as the quantum yield ``QY = PY x 600 / 532``,
the same emitted power; the heat simulation runs as two chained calls, one per pulse, so
that the heat source in force during each pulse is known to the check: the updates and
re-evaluations fall at the same times as in one call, but the automatic time step is
chosen again for the second pulse.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model
from mcmatlab_py.heat import heat_source

POWER = 2.0  #: W
EXCITATION, FLUORESCENCE = 532.0, 600.0  #: nm
FR_ITERATIONS = 20  #: MC.fr_dep_iterations (MCmatlab 3's default FRdepIterations)
PULSE = (0.006, 0.004)  #: s, on and off
END = 0.003  #: s, cooling after the second pulse


def geometry(X, Y, Z):
    """0 material 1 above 0.1 mm, 1 material 2 below."""
    return np.where(Z > 0.01, 1, 0)


def media() -> list[Medium]:
    """The two materials; every function takes arrays over the voxels of its medium."""
    def power_yield_1(wl, FR, T, FD):
        return 0.5 / (1 + FR / 700 + T / 10)

    return [
        Medium("material 1",
               mua=lambda wl, FR, T, FD: 0.00036 + (T + FR) / 100,
               mus=lambda wl, FR, T, FD: 10 + FR / 1000 - T / 100,
               g=lambda wl, FR, T, FD: np.exp(-(T + FR / 500)),
               QY=lambda wl, FR, T, FD: power_yield_1(wl, FR, T, FD) * FLUORESCENCE / EXCITATION,
               VHC=lambda T, FD: 4.19 + T / 200, TC=lambda T, FD: 5.8e-3 + T / 25000,
               n_bins=20),
        Medium("material 2",
               mua=lambda wl, FR, T, FD: 0.0073 + (T + 2 * FR) / 60,
               mus=lambda wl, FR, T, FD: 50 + FR / 7000 + T / 150,
               g=lambda wl, FR, T, FD: (0.2 * (0.5 + 0.5 * np.tanh(T))
                                        + 0.05 * (0.5 + 0.5 * np.tanh(FR / 500))),
               QY=lambda wl, FR, T, FD: (0.35 - 0.25 * np.tanh((FR - 250) / 100)
                                         + 0.1 * np.tanh((T - 10) / 10)),
               VHC=lambda T, FD: 2.19 + T / 400, TC=lambda T, FD: 10e-3 + T / 150,
               n_bins=30),
    ]


def enthalpy(medium: int, T):
    """J cm^-3, the integral of the medium's VHC over T from 0 deg C."""
    return 4.19 * T + T**2 / 400 if medium == 0 else 2.19 * T + T**2 / 800


def build(quick: bool = False) -> Model:
    """The model of Test 1; ``quick``: 24^3 voxels, 10^4 photons and a 12^3 heat mesh."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 24 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = media()
    G.geom_func = geometry
    T_initial = 5.0 * np.random.default_rng(1).random((G.nx, G.ny, G.nz))  # deg C

    MC = model.MC
    MC.n_photons_requested = 10_000 if quick else 1_000_000
    MC.seed = 101
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = EXCITATION
    MC.T = T_initial  # the state the first Monte Carlo sees (MCmatlab: HS.T)
    MC.P = POWER  # W
    MC.fr_dep_iterations = FR_ITERATIONS
    src = MC.light_source
    src.source_type = 5  # X/Y factorizable beam
    fp, ang = src.focal_plane_intensity_distribution, src.angular_intensity_distribution
    fp.x_distr, fp.x_width, fp.y_distr, fp.y_width = 0, 0.02, 0, 0.01  # top-hat, cm
    ang.x_distr, ang.x_width = 2, np.pi / 8  # Lambertian, rad
    ang.y_distr, ang.y_width = 2, np.pi / 8
    src.psi = np.pi / 4
    src.x_focus = src.y_focus = src.z_focus = 0.0
    src.theta = src.phi = 0.0

    FMC = model.FMC
    FMC.n_photons_requested = MC.n_photons_requested
    FMC.seed = 102
    FMC.progress = not quick
    FMC.matched_interfaces = True
    FMC.boundary_type = 1
    FMC.wavelength = FLUORESCENCE

    HS = model.HS
    HS.P = MC.P  # W, the heating laser
    HS.large_time_steps = True
    HS.heat_boundary_type = 1  # faces held at their initial temperatures
    HS.T_initial = T_initial
    HS.plot_temp_limits = (0.0, 45.0)
    HS.n_updates = 10
    HS.media_prop_recalc_period = 10
    # MCmatlab's (0.5, 0.6, 1) puts the xy slice on the bottom wall of its 3-D view; on the
    # flat panels here that is the bottom face, unheated: slice through the hottest voxel
    HS.slice_positions = None
    HS.temp_sensor_positions = [(0, 0, 0.005), (0, 0, 0.015), (0, 0, 0.035), (0, 0, 0.065)]
    HS.progress = not quick
    if quick:
        HS.mesh_divisions = (12, 12, 12)
    return model


def run(quick: bool = False) -> dict:
    """Build the model, run the Monte Carlo (iterated on FR), the fluorescence, then the heat.

    Returns ``{"model": model, "heated": [W per W incident turned into heat in the cuboid
    during pulse 1, pulse 2]}``.
    """
    model = build(quick).run_monte_carlo()
    model.run_monte_carlo("fluorescence")
    G, HS = model.G, model.HS
    heated = []
    # pulse 1, then pulse 2 and the cooling: the 10th update of each call is the end of its
    # pulse, where one call of 23 updates would re-evaluate the media (updates 10 and 20)
    for end in (0.0, END):
        heated.append(float(heat_source(model).sum() * G.dx * G.dy * G.dz))
        HS.duration_on, HS.duration_off, HS.duration_end, HS.n_pulses = *PULSE, end, 1
        model.simulate_heat_distribution()
    return {"model": model, "heated": heated}


def heat_gained(model) -> float:
    """J: enthalpy gained by the voxels from their initial temperatures (T-dependent VHC)."""
    G, HS = model.G, model.HS
    M, T, T0 = G.medium_map(), HS.T_voxels, HS.T_initial
    gained = sum(np.where(M == i, enthalpy(i, T) - enthalpy(i, T0), 0.0) for i in (0, 1))
    return float(gained.sum() * G.dx * G.dy * G.dz)


def check(result: dict) -> dict:
    """Heat kept at most the heat delivered; no voxel colder than the coldest start."""
    model = result["model"]
    HS = model.HS
    delivered = POWER * PULSE[0] * sum(result["heated"])  # J
    return {
        "heat_kept": {
            "value": heat_gained(model) / delivered, "min": 0.0, "max": 1.0,
            "what": "enthalpy gained / energy turned into heat (held faces only take heat "
                    "away)"},
        "minimum_principle": {
            "value": HS.T_voxels.min() - np.min(HS.T_initial), "min": -1e-6,
            "what": "coldest final voxel minus coldest initial one, deg C (heat sources only, "
                    "faces held at their start: >= 0 up to the solver's tolerance)"},
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    result = run(args.quick)
    model = result["model"]
    print(f"heat source in pulse 1, 2 (W per W): {result['heated']}; "
          f"{model.HS.mc_runs} Monte Carlo re-runs during the heat simulation")
    for name, c in check(result).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    for what in ("G", "MC", "HS"):
        model.plot(what, args.out / "test1")
    model.plot("FMC", args.out / "test1_FMC")  # emitters, NA, NFR of the fluorescence
    print(f"figures in {args.out}")
