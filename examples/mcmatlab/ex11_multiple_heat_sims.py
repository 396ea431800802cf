"""MCmatlab Example 11 (MultipleHeatSims): two heat simulations chained into one pulse train.

The tissue and the light are those of Example 4 (``ex04_blood_vessel.py``): a collimated
top-hat beam of radius 300 um at 532 nm on gel, epidermis, dermis and a blood vessel.
At 4 W peak power, a first heat simulation gives one pulse of 2 ms on and 3 ms off; a
second call of ``simulate_heat_distribution`` goes on from the temperatures, damage and
clock where the first ended, with nine pulses of 0.5 ms on and 4.5 ms off and then 10 ms
of cooling: 60 ms in all. Both runs take MCmatlab's large automatic time steps and 10
updates per pulse; the movie (full size only) holds the frames of both runs, the first
run keeping its frames (``defer_movie_write``) for the second to append to and write.

    python examples/mcmatlab/ex11_multiple_heat_sims.py [--quick] [--out DIR]

Differences from MCmatlab: as in ``ex04_blood_vessel.py`` (a fixed photon count, the
heat equation on finite elements with the nodes at the voxel corners); the power is
``HS.P`` (MCmatlab's ``MC.P``); the movie is written only at full size and needs
imageio-ffmpeg.
"""

from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from ex04_blood_vessel import geometry, media  # noqa: E402  (Example 4's tissue)

from mcmatlab_py import Model  # noqa: E402

#: the two chained runs: (duration_on, duration_off, duration_end) s and n_pulses
RUNS = ((0.002, 0.003, 0.0, 1), (0.0005, 0.0045, 0.01, 9))
POWER = 4.0  #: W, peak power of the pulses


def build(quick: bool = False) -> Model:
    """The model of Example 11; ``quick``: 40^3 voxels, 2 x 10^4 photons, a 20^3 heat mesh."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 40 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = media()
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 20_000 if quick else 2_000_000
    MC.seed = 11
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
    HS.P = POWER
    HS.large_time_steps = True
    HS.heat_boundary_type = 0  # insulating
    HS.T_initial = 37.0  # deg C
    HS.plot_temp_limits = (37.0, 100.0)
    HS.n_updates = 10
    HS.steps_at_updates = True  # the chained runs march the steps of the one long run (check)
    # ... with the implicit steps' power-of-two lengths, which the chained and the one long run
    # share; the explicit RKC steps' lengths (HS.integrator = "auto" picks them for these ms
    # pulses) vary continuously from step to step, so the two would differ by the time error
    HS.integrator = "implicit"
    # MCmatlab's (0.5, 0.6, 1) puts the xy slice on the bottom wall of its 3-D view; on the
    # flat panels here that is the bottom face, unheated: slice through the hottest voxel
    HS.slice_positions = None
    HS.temp_sensor_positions = [(0, 0, 0.038), (0, 0, 0.04), (0, 0, 0.042), (0, 0, 0.044)]
    HS.progress = not quick
    HS.make_movie = not quick
    if quick:
        HS.mesh_divisions = (20, 20, 20)
    return model


def set_run(HS, on: float, off: float, end: float, n_pulses: int) -> None:
    """The pulses of one heat simulation."""
    HS.duration_on, HS.duration_off, HS.duration_end, HS.n_pulses = on, off, end, n_pulses


def run(quick: bool = False, movie_path: str | Path | None = None) -> Model:
    """Build the model, run the Monte Carlo and the two chained heat simulations."""
    model = build(quick).run_monte_carlo()
    HS = model.HS
    if movie_path is not None:
        HS.movie_path = str(movie_path)
    for i, settings in enumerate(RUNS):
        HS.defer_movie_write = i < len(RUNS) - 1  # the last run writes the whole movie
        set_run(HS, *settings)
        model.simulate_heat_distribution()
    return model


def pulse_train_power(t: float) -> float:
    """W at time ``t`` (s) of the whole train of ``RUNS``, as one function of time."""
    start = 0.0
    for on, off, end, n in RUNS:
        period = on + off
        if start <= t < start + n * period:
            return POWER if (t - start) % period < on else 0.0
        start += n * period + end
    return 0.0


def one_long_run(model) -> Model:
    """The same 60 ms as one heat simulation: a single 'pulse' with ``P(t)`` the whole train.

    One update every 0.5 ms, as the chained runs have, so that both march the same steps.
    """
    single = copy.deepcopy(model)
    HS = single.HS
    HS.reset()
    total = sum(n * (on + off) + end for on, off, end, n in RUNS)
    HS.P = pulse_train_power
    HS.make_movie = HS.defer_movie_write = HS.progress = False
    set_run(HS, total, 0.0, 0.0, 1)
    HS.n_updates = round(total / 0.0005)
    return single.simulate_heat_distribution()


def heat_balance(model) -> float:
    """Heat gained by the tissue over the energy absorbed from all pulses of both runs.

    With insulating faces the heat content ``sum_i C_i (T_i - T0)`` (C the lumped P1 heat
    capacity of node i, J/K) equals ``P x (total on time) x`` the absorbed fraction; a
    second run that restarted from 37 deg C would miss the first run's 31% of it.
    """
    import fem

    G, MC, HS = model.G, model.MC, model.HS
    vhc = np.array([m.VHC for m in G.media])
    elem_medium = G.medium_map().ravel()[fem.element_voxel_index(HS.mesh, G.grid)]
    capacity = fem.lumped_mass(HS.mesh, vhc[elem_medium])  # J/K per node
    gained = float(capacity @ (HS.T_nodes - HS.T_initial))
    on_time = sum(n * on for on, off, end, n in RUNS)
    return gained / (POWER * on_time * MC.absorbed_fraction)


def check(model) -> dict:
    """Energy kept across the two runs, and the chained runs against one long run."""
    single = one_long_run(model)
    rise = model.HS.T_voxels.max() - model.HS.T_initial
    return {
        "heat_balance": {
            "value": heat_balance(model), "expected": 1.0, "tol": 1e-6,
            "what": "heat content gained / energy absorbed over both runs (insulating: 1)"},
        "chained_equals_one_run": {
            "value": np.abs(model.HS.T_voxels - single.HS.T_voxels).max() / rise,
            # the same steps give the same field up to the solves' own tolerance: exact with
            # the sparse LU of the quick run (5e-15), about 1e-8 of the rise with the PCG of
            # the full-size mesh (relative residual 1e-9 per solve, started from other
            # guesses in the chained run); a step taken differently would differ by 1e-3
            "expected": 0.0, "tol": 1e-7,
            "what": "max |T chained - T one run with P(t)| over the largest rise (same steps)"},
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    model = run(args.quick, movie_path=args.out / "ex11_heat.mp4")
    print(f"{100 * model.MC.absorbed_fraction:.3g}% of the incident light was absorbed "
          "within the cuboid")
    names = [m.name for m in model.G.media]
    for name, T in zip(names, model.HS.max_media_temps, strict=True):
        print(f"highest temperature in the {name}: {T:.1f} deg C")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    for what in ("G", "MC", "HS"):
        model.plot(what, args.out / "ex11")
    print(f"figures in {args.out}" + ("" if args.quick else f", movie {model.HS.movie_path}"))
