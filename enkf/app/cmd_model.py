"""The commands that run a TOML model: ``mc`` (Monte Carlo) and ``heat`` (Monte Carlo then heat)."""

from __future__ import annotations

import time
from pathlib import Path

from fem.checks import check_number
from mcmatlab_py.heat import check_heat
from mcmatlab_py.model import MAX_PHOTONS

from .common import apply_threads, close_client, dask_client

__all__ = ["cmd_heat", "cmd_mc"]

def _run_model_mc(args, heat: bool):
    """Load CONFIG with the common overrides, validate, run its Monte Carlo; the model."""
    from mcmatlab_py.config import model_from_config, read_toml

    from .config import check_identify_keys
    from .rundir import check_out_dir

    check_out_dir(args.out, args.force)
    apply_threads(args.threads)
    raw = read_toml(args.config)
    model = model_from_config(raw)
    check_identify_keys(raw)  # unused here, but a typo there is still an error
    if args.seed is not None:
        model.MC.seed = args.seed
    if args.photons is not None:
        model.MC.n_photons_requested = check_number("--photons", args.photons, integer=True,
                                                    lo=1, hi=MAX_PHOTONS)
    model.MC.progress = model.HS.progress = not args.quiet
    model.MC.n_threads = args.threads
    model.MC.validate(model.G)
    if heat:
        model.HS.validate(model.G)
        check_heat(model.G, model.HS)  # before the Monte Carlo: refuse what cannot finish
        if not model.HS.temp_sensor_positions:
            model.HS.temp_sensor_positions = [(0.0, 0.0, 0.0)]
    client = dask_client(args, raw)
    try:
        model.run_monte_carlo(client=client)
    finally:
        close_client(client)
    return model


def cmd_mc(args) -> int:
    from mcmatlab_py.export import write_voxel_vtu
    from mcmatlab_py.plotting import plot_na_slices

    from .rundir import atomic_dir, write_json

    t0 = time.perf_counter()
    model = _run_model_mc(args, heat=False)
    G, MC = model.G, model.MC
    import numpy as np

    with atomic_dir(args.out, args.force) as tmp:
        np.savez_compressed(tmp / "NA.npz", NA=MC.NA, NFR=MC.NFR, x=G.x, y=G.y, z=G.z)
        write_voxel_vtu(tmp / "NA.vtu", G, {"NA": MC.NA, "NFR": MC.NFR})
        plot_na_slices(model, tmp / "NA_slices.png")
        extra = _mc_outputs(MC)
        if extra:  # the optional outputs the config asked for, and MCmatlab's figures of them
            np.savez_compressed(tmp / "outputs.npz", **extra)
            model.plot("MC", tmp / "MC.png")
        from mcmatlab_py.config import read_toml

        from .report import manifest

        manifest(tmp / "run.json", command="mc", config=read_toml(args.config),
                 seed=MC.seed_used, timings={"kernel": MC.simulation_time,
                                             "total": time.perf_counter() - t0})
        write_json(tmp / "summary.json", {
            "config": str(Path(args.config)),
            "absorbed_fraction": MC.absorbed_fraction,
            "specular_reflectance": MC.specular_reflectance,
            "escaped": MC.escaped,
            "absorbed_outside_fraction": MC.absorbed_outside_fraction,
            "killed_fraction": MC.killed_fraction,
            "missed_fraction": MC.missed_fraction,
            "roulette_gain_fraction": MC.roulette_gain_fraction,
            "energy_balance": MC.energy_balance,
            "n_photons": MC.n_photons,
            "photons_per_second": MC.photons_per_second,
            "kernel_seconds": MC.simulation_time,
            "wall_seconds": time.perf_counter() - t0,
            "seed": MC.seed_used,
            "grid": {"nx": G.nx, "ny": G.ny, "nz": G.nz, "Lx": G.Lx, "Ly": G.Ly, "Lz": G.Lz},
            **({"collected_fraction": float(np.sum(MC.light_collector.image)),
                "n_photons_collected": MC.n_photons_collected}
               if MC.use_light_collector else {}),
            "outputs": sorted(extra),
        })
    # the result, even with --quiet (it hides the progress bars only)
    print(f"absorbed {MC.absorbed_fraction:.4f}, escaped top {MC.escaped['top']:.4f} "
          f"bottom {MC.escaped['bottom']:.4f} sides {MC.escaped['sides']:.4f}; "
          f"{MC.n_photons} photons at {MC.photons_per_second:.3g}/s -> {args.out}")
    return 0


def _output_names() -> tuple[str, ...]:
    """``MC``'s optional outputs (the maps beyond NA and NFR, their axes, the paths)."""
    from mcmatlab_py.monte_carlo.broadband import AXES, MAPS

    return (*(m for m in MAPS if m not in ("NA", "NFR")), *AXES, "example_paths")


def _mc_outputs(MC) -> dict:
    """The optional outputs of a run as arrays for ``outputs.npz`` (those computed only)."""
    import numpy as np

    out = {k: np.asarray(getattr(MC, k)) for k in _output_names() if getattr(MC, k) is not None}
    if MC.use_light_collector:
        LC = MC.light_collector
        out.update({f"light_collector_{k}": np.asarray(getattr(LC, k))
                    for k in ("image", "X", "Y", "t") if getattr(LC, k) is not None})
    return out


def cmd_heat(args) -> int:
    import numpy as np

    import fem
    from mcmatlab_py.config import read_toml
    from mcmatlab_py.export import write_voxel_vtu
    from mcmatlab_py.plotting import plot_na_slices

    from .report import manifest
    from .rundir import atomic_dir, write_json

    t0 = time.perf_counter()
    model = _run_model_mc(args, heat=True)
    t_mc = time.perf_counter() - t0
    model.simulate_heat_distribution()
    t_heat = time.perf_counter() - t0 - t_mc
    HS, G, MC = model.HS, model.G, model.MC
    with atomic_dir(args.out, args.force) as tmp:
        (tmp / "figures").mkdir()
        (tmp / "fields").mkdir()
        pos = np.asarray(HS.temp_sensor_positions, float).reshape(-1, 3)
        cols = ["time_s"] + [f"T_{x:g}_{y:g}_{z:g}" for x, y, z in pos]
        np.savetxt(tmp / "sensors.csv", np.column_stack([HS.sensor_times, HS.sensor_temps]),
                   delimiter=",", header=",".join(cols), comments="", fmt="%.8g")
        fem.write_vtu(tmp / "fields" / "temperature.vtu", HS.mesh,
                      point_data={"T": HS.T_nodes, "damage_Omega": HS.Omega.ravel()})
        write_voxel_vtu(tmp / "fields" / "absorbed_power.vtu", G, {"NA": MC.NA, "NFR": MC.NFR})
        plot_na_slices(model, tmp / "figures" / "NA_slices.png")
        _plot_sensors(tmp / "figures" / "sensors.png", HS, cols[1:])
        summary = {"absorbed_fraction": MC.absorbed_fraction, "escaped": MC.escaped,
                   "n_photons": MC.n_photons,
                   # the run's peak (any node, any step), not the last field's
                   "T_max": float(np.max(HS.max_media_temps)),
                   "T_final_max": float(HS.T_nodes.max()),
                   "sensor_T_max": {c: float(HS.sensor_temps[:, i].max())
                                    for i, c in enumerate(cols[1:])},
                   "damage_max": float(HS.Omega.max()),
                   "timing_s": {"monte_carlo": t_mc, "heat": t_heat}}
        write_json(tmp / "summary.json", summary)
        manifest(tmp / "run.json", command="heat", config=read_toml(args.config),
                 seed=MC.seed_used, timings={"monte_carlo": t_mc, "heat": t_heat})
    # the result, even with --quiet (it hides the progress bars only)
    print(f"max temperature {summary['T_max']:.2f} deg C during the run "
          f"({summary['T_final_max']:.2f} at the end), max damage "
          f"{summary['damage_max']:.3g} -> {args.out}")
    return 0


def _plot_sensors(path, HS, labels) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    for i, lab in enumerate(labels):
        ax.plot(HS.sensor_times, HS.sensor_temps[:, i], label=lab)
    ax.set(xlabel="time [s]", ylabel="T [$^\\circ$C]", title="temperature at the sensors")
    ax.legend(fontsize=7)
    fig.savefig(path, dpi=110)
    plt.close(fig)
