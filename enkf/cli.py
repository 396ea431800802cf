"""The ``tissue-enkf`` command line (an edge module).

Every subcommand validates its input first; a problem with the input prints one
line ``error: ...`` naming it and exits with status 2, writing nothing.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

EXIT_BAD_INPUT = 2
EXIT_CHECK_FAILED = 1  #: validate: a check failed (its report is still written)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, help="output directory (created; must be new or empty)")
    p.add_argument("--force", action="store_true", help="replace a non-empty --out")
    p.add_argument("--seed", type=int, default=None, help="random seed (overrides the config)")
    p.add_argument("--threads", type=int, default=None, help="numba threads (default: all cores)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _dask_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("Dask (pip install \"tissue-enkf[dist]\")")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the Monte Carlo tasks on an existing Dask cluster "
                        "(e.g. tcp://10.0.0.5:8786)")
    g.add_argument("--workers", type=int, default=None, metavar="N",
                   help="run them on a new local Dask cluster of N single-threaded workers")


def _client(args, config: dict | None = None):
    """The Dask client of --scheduler / --workers (or the config's [run] table), or None."""
    scheduler, workers = getattr(args, "scheduler", None), getattr(args, "workers", None)
    if scheduler is None and workers is None and config is not None:
        from .config import run_table

        scheduler, workers = run_table(config)
    if scheduler is None and workers is None:
        return None
    if scheduler is not None and workers is not None:
        raise ValueError("give --scheduler or --workers, not both")
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    from mcmatlab_py.distributed import connect

    return connect(scheduler, n_workers=workers)


def _close(client) -> None:
    if client is not None:
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None:
            cluster.close()


def _model_command(p: argparse.ArgumentParser, config_help: str, func) -> None:
    """The arguments of the commands that run a TOML model (mc, heat)."""
    p.add_argument("config", help=config_help)
    p.add_argument("--photons", type=int, default=None,
                   help="number of photon packets (overrides MC.n_photons_requested)")
    _common(p)
    _dask_options(p)
    p.set_defaults(func=func)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tissue-enkf",
        description="Monte Carlo light transport, FEM heat and ensemble Kalman filtering "
                    "for laser-irradiated tissue.")
    sub = parser.add_subparsers(dest="command", required=True)
    p_mc = sub.add_parser("mc", help="run the Monte Carlo of a TOML model",
                          description="Run MCmatlab-style Monte Carlo light transport for the "
                                      "model in CONFIG and write NA/NFR (.npz, .vtu), "
                                      "summary.json and a PNG of NA slices.")
    _model_command(p_mc, "TOML model file (see examples/)", cmd_mc)

    p_paper = sub.add_parser(
        "paper", help="run one of the paper's experiments end to end",
        description="Fine-grid truth (Monte Carlo + FEM heat), noisy sensor data, and the "
                    "EnKF on the coarse model with the absorption emulator; writes "
                    "estimates.csv, truth.csv, summary.json and figures/.")
    p_paper.add_argument("scenario", choices=("constant", "time-varying", "all-params",
                                              "pulse-train", "sensitivity"),
                         help="an experiment ('pulse-train': three pulses, optics that change "
                              "while heated, beyond the paper), or 'sensitivity' for the "
                              "paper's sensitivity study")
    p_paper.add_argument("--members", type=int, default=50, help="ensemble size N (default 50)")
    p_paper.add_argument("--method", choices=("enkf", "etkf"), default="etkf",
                         help="analysis: deterministic ETKF (default) or the paper's EnKF "
                              "with perturbed observations")
    p_paper.add_argument("--fine", type=int, nargs=3, default=(100, 100, 50),
                         metavar=("NX", "NY", "NZ"), help="truth grid (default 100 100 50)")
    p_paper.add_argument("--truth-photons", type=int, default=None,
                         help="photons of the truth's Monte Carlo (per step when the optics "
                              "change; default 1e7 constant, 5e5 per step)")
    p_paper.add_argument("--emulator-photons", type=int, default=250_000,
                         help="photons per emulator table point at mus = 100 (default 2.5e5)")
    p_paper.add_argument("--emulator-table", type=int, default=12, metavar="N",
                         help="N x N log-spaced (mua, mus) table points (default 12)")
    p_paper.add_argument("--exact", action="store_true",
                         help="direct Monte Carlo per member and step instead of the emulator "
                              "(slow: for checking)")
    p_paper.add_argument("--cache-dir", default=None,
                         help="where emulator tables and truths are cached "
                              "(default $TISSUE_ENKF_CACHE or ~/.cache/tissue-enkf)")
    _common(p_paper)
    _dask_options(p_paper)
    p_paper.set_defaults(func=cmd_paper)
    p_heat = sub.add_parser(
        "heat", help="Monte Carlo plus heat: sensor series and volume fields",
        description="Run the Monte Carlo of the model in CONFIG, then the heat simulation of "
                    "its [HS] table (laser pulses, boundaries, sensors); write sensors.csv "
                    "(temperature at HS.temp_sensor_positions), summary.json, figures/ and "
                    "fields/*.vtu (temperature, damage on the mesh; NA, NFR on the voxels).")
    _model_command(p_heat, "TOML model file with [G], [MC] and [HS] (see examples/)", cmd_heat)

    p_id = sub.add_parser(
        "identify", help="the filter on measured data",
        description="Estimate the optical properties (and the temperatures below the "
                    "surface) from measured temperatures: the model, sensors and filter come "
                    "from CONFIG, the data from a CSV (a header; time in s, then one column "
                    "per sensor in deg C in the order of sensors.positions, or the columns "
                    "named by data.columns; irregular times; gaps empty or nan) or an NPZ "
                    "thermal image series (times, frames; with [sensors.camera]). Writes "
                    "estimates.csv, summary.json, "
                    "figures/, fields/final.vtu and run.json. Several --data files run as a "
                    "batch (one Dask task each with --workers/--scheduler) and add batch.csv. "
                    "Exit status 0 (also when the filter's health check stopped a run: "
                    "summary.json says when and why, the estimates up to then are written), "
                    "2 for bad input.")
    p_id.add_argument("config", help="TOML file: [G], [MC], [HS], [sensors], [filter], [data] "
                                      "(see examples/own_data.toml, docs/cli.md)")
    p_id.add_argument("--data", nargs="+", default=None, metavar="FILE",
                      help="measured data: CSV or NPZ file(s) (default: data.file of the config)")
    p_id.add_argument("--follow", default=None, metavar="FILE",
                      help="online: read FILE as the acquisition appends to it, write each "
                           "estimate before the next frame (stops at '# end' or when idle)")
    p_id.add_argument("--idle-timeout", type=float, default=10.0,
                      help="--follow: stop after this many seconds without a new line")
    p_id.add_argument("--cache-dir", default=None, help="emulator cache directory")
    _common(p_id)
    _dask_options(p_id)
    p_id.set_defaults(func=cmd_identify)

    p_val = sub.add_parser(
        "validate", help="run the validation suite and write a Markdown report",
        description="Run the validation scripts of the source tree (validation/*.py), each "
                    "in its own process, and collect their reports and figures into "
                    "--out/report.md. --quick (default) runs small versions in a few "
                    "minutes; --full the published sizes (hours). Exit status 0 when every "
                    "check ran, 1 when one failed (the report says which), 2 for bad input.")
    size = p_val.add_mutually_exclusive_group()
    size.add_argument("--quick", dest="full", action="store_false",
                      help="small versions, a few minutes (default)")
    size.add_argument("--full", dest="full", action="store_true",
                      help="the published sizes (can take hours)")
    p_val.add_argument("--only", nargs="+", default=None, metavar="CHECK",
                       help="run only these checks (names of validation/*.py, or "
                            "'sensitivity')")
    p_val.set_defaults(full=False)
    _common(p_val)
    p_val.set_defaults(func=cmd_validate)
    return parser


def _apply_threads(threads):
    if threads is not None:
        import numba

        if threads < 1:
            raise ValueError(f"--threads must be >= 1, got {threads}")
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))


def _run_model_mc(args, heat: bool):
    """Load CONFIG with the common overrides, validate, run its Monte Carlo; the model."""
    from mcmatlab_py.config import model_from_config, read_toml

    from .config import check_identify_keys
    from .rundir import check_out_dir

    check_out_dir(args.out, args.force)
    _apply_threads(args.threads)
    raw = read_toml(args.config)
    model = model_from_config(raw)
    check_identify_keys(raw)  # unused here, but a typo there is still an error
    if args.seed is not None:
        model.MC.seed = args.seed
    if args.photons is not None:
        model.MC.n_photons_requested = args.photons
    model.MC.progress = model.HS.progress = not args.quiet
    model.MC.n_threads = args.threads
    model.MC.validate(model.G)
    if heat:
        model.HS.validate(model.G)
        if not model.HS.temp_sensor_positions:
            model.HS.temp_sensor_positions = [(0.0, 0.0, 0.0)]
    client = _client(args, raw)
    try:
        model.run_monte_carlo(client=client)
    finally:
        _close(client)
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
        })
    if not args.quiet:
        print(f"absorbed {MC.absorbed_fraction:.4f}, escaped top {MC.escaped['top']:.4f} "
              f"bottom {MC.escaped['bottom']:.4f} sides {MC.escaped['sides']:.4f}; "
              f"{MC.n_photons} photons at {MC.photons_per_second:.3g}/s -> {args.out}")
    return 0


def cmd_paper(args) -> int:
    from . import paper
    from .rundir import check_out_dir

    check_out_dir(args.out, args.force)
    _apply_threads(args.threads)
    if args.members < 2:
        raise ValueError(f"--members must be >= 2, got {args.members}")
    verbose = not args.quiet
    client = _client(args)
    try:
        return _paper(args, paper, client, verbose)
    finally:
        _close(client)


def _paper(args, paper, client, verbose) -> int:
    from .rundir import atomic_dir

    if args.scenario == "sensitivity":
        res = paper.sensitivity_study(tuple(args.fine), args.truth_photons or 10**6,
                                      progress=verbose, client=client)
        with atomic_dir(args.out, args.force) as tmp:
            (tmp / "figures").mkdir()
            paper.plot_sensitivity(tmp / "figures" / "sensitivity.png", res)
            cols = [f"T_mua_{v:g}" for v in res["mua"]] + [f"T_mus_{v:g}" for v in res["mus"]]
            import numpy as np

            np.savetxt(tmp / "sensitivity.csv", np.column_stack(
                [res["times"], *res["mua"].values(), *res["mus"].values()]), delimiter=",",
                header="time_s," + ",".join(cols), comments="", fmt="%.8g")
        return 0
    tcfg = paper.TruthConfig(scenario=args.scenario, grid=tuple(args.fine))
    if args.truth_photons is not None:
        if args.truth_photons < 1:
            raise ValueError(f"--truth-photons must be >= 1, got {args.truth_photons}")
        tcfg.n_photons_constant = tcfg.n_photons_per_step = args.truth_photons
    if verbose:
        print(f"truth on {tcfg.grid} voxels, emulator on the 20 x 20 x 10 filter grid "
              "(both cached after the first run) ...", file=sys.stderr)
    run = paper.run_experiment(args.scenario, 0 if args.seed is None else args.seed,
                               n_members=args.members, method=args.method, truth_config=tcfg,
                               emulator_photons=args.emulator_photons,
                               emulator_table=args.emulator_table, exact=args.exact,
                               cache_dir=args.cache_dir, progress=verbose, client=client)
    with atomic_dir(args.out, args.force) as tmp:
        paper.write_run(run, tmp)
        from .report import manifest

        manifest(tmp / "run.json", command=f"paper {args.scenario}",
                 config={"scenario": args.scenario, "members": args.members,
                         "method": args.method, "fine": list(args.fine),
                         "truth_photons": args.truth_photons,
                         "emulator_photons": args.emulator_photons,
                         "emulator_table": args.emulator_table, "exact": args.exact},
                 seed=run.summary["seed"], timings={"total": run.summary["wall_seconds"],
                                                    **{k: v for k, v in
                                                       run.summary["timing"].items()
                                                       if k.endswith("_s")}})
    if verbose:
        summary = run.summary
        for name, p in summary["parameters"].items():
            print(f"{name}: final {p['estimate_final']:.4g} +- {p['std_final']:.2g} "
                  f"(truth {p['truth_final']:.4g}, rel. error {p['relative_error_final']:.3f})")
        for name, p in summary["temperatures"].items():
            print(f"T at {name}: rmse {p['rmse']:.3f} deg C, coverage {p['coverage_2sd']:.2f}")
        tm = summary["timing"]
        print(f"filter {tm['filter_wall_s']:.2f} s for {tm['steps']} steps, median step "
              f"{1e3 * tm['step_latency_median_s']:.1f} ms, max "
              f"{1e3 * tm['step_latency_max_s']:.1f} ms -> {args.out}")
        if summary["diverged"]:
            print(f"warning: {summary['diverged']}", file=sys.stderr)
    return 0


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
                   "n_photons": MC.n_photons, "T_max": float(HS.T_nodes.max()),
                   "sensor_T_max": {c: float(HS.sensor_temps[:, i].max())
                                    for i, c in enumerate(cols[1:])},
                   "damage_max": float(HS.Omega.max()),
                   "timing_s": {"monte_carlo": t_mc, "heat": t_heat}}
        write_json(tmp / "summary.json", summary)
        manifest(tmp / "run.json", command="heat", config=read_toml(args.config),
                 seed=MC.seed_used, timings={"monte_carlo": t_mc, "heat": t_heat})
    if not args.quiet:
        print(f"max temperature {summary['T_max']:.2f} deg C, max damage "
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


def _identify_one(cfg, absorption, seed, data_path, out_dir, quiet=True) -> dict:
    """Run the filter on one data file and write its outputs into ``out_dir`` (a task)."""
    from mcmatlab_py._progress import Progress

    from .report import write_identify_outputs
    from .tissue import identify

    setup = cfg.setup(absorption, seed=seed)
    times, data = cfg.read_data(data_path)
    medium = cfg.model.G.media[0]
    risk = None
    if medium.E and medium.A:  # MCmatlab's damage model: the risk of injury per node
        from .risk import RiskTracker

        risk = RiskTracker(E=medium.E, A=medium.A, record_every=10)
    bar = Progress(len(times), "filter", enabled=not quiet)

    def callback(rep):
        if risk is not None:
            risk(rep)
        bar.update(rep.step)

    t0 = time.perf_counter()
    try:
        est = identify(setup, times, data, callback=callback, param_bounds=cfg.param_bounds)
    finally:
        bar.close()
    summary = write_identify_outputs(Path(out_dir), setup, est, times, data,
                                     absorption=absorption, risk=risk)
    summary["data"] = str(data_path)
    summary["wall_s"] = time.perf_counter() - t0
    return summary


def cmd_identify(args) -> int:
    from .config import load_identify
    from .report import manifest
    from .rundir import atomic_dir, check_out_dir, write_json

    check_out_dir(args.out, args.force)
    _apply_threads(args.threads)
    cfg = load_identify(args.config)
    if args.data is None and args.follow is None and cfg.data.file is not None:
        args.data = [str(cfg.data.file)]
    if (args.data is None) == (args.follow is None):
        raise ValueError("give --data FILE [FILE ...] or --follow FILE (or data.file in the "
                         "config)")
    if args.follow is not None and cfg.data.time_offset is not None:
        raise ValueError("data.time_offset is not supported with --follow: write the times "
                         "from the laser's start")
    seed = args.seed if args.seed is not None else cfg.setup_kw.get("seed", 0)
    files = [Path(f) for f in (args.data or [])]
    if len(files) == 1:  # one dataset: bad data is bad input (exit 2, nothing written);
        # in a batch a bad file is reported in batch.csv and the others go on
        cfg.read_data(files[0])
    t0 = time.perf_counter()
    client = _client(args, cfg.raw)
    try:
        absorption = cfg.emulator(cache_dir=args.cache_dir, progress=not args.quiet,
                                  client=client)
        t_emu = time.perf_counter() - t0
        if args.follow is not None:
            return _follow(args, cfg, absorption, seed, t_emu)
        with atomic_dir(args.out, args.force) as tmp:
            if len(files) == 1:
                summary = _identify_one(cfg, absorption, seed, files[0], tmp, args.quiet)
                rows = [summary]
            else:
                rows = _identify_batch(cfg, absorption, seed, files, tmp, client, args.quiet)
            manifest(tmp / "run.json", command="identify", config=cfg.raw, seed=seed,
                     timings={"emulator": t_emu, "total": time.perf_counter() - t0},
                     extra={"data": [str(f) for f in files]})
            if len(files) > 1:
                write_json(tmp / "summary.json", {"runs": rows})
    finally:
        _close(client)
    for r in rows:
        if r.get("stopped"):
            print(f"warning: {r['data']}: the filter stopped early: {r['stopped']} (estimates "
                  "up to then are written)", file=sys.stderr)
    if not args.quiet:
        for r in rows:
            if "error" in r:
                print(f"{r['data']}: failed: {r['error']}", file=sys.stderr)
                continue
            par = ", ".join(f"{k} {v['estimate_final']:.4g} +- {v['std_final']:.2g}"
                            for k, v in r["parameters"].items())
            stop = f" (stopped: {r['stopped']})" if r["stopped"] else ""
            print(f"{r['data']}: {par}{stop}")
        print(f"-> {args.out}")
    return 0


def _identify_batch(cfg, absorption, seed, files, tmp, client, quiet) -> list:
    import functools
    import shutil

    from mcmatlab_py.distributed import TaskError, run_tasks

    names = []
    for f in files:  # one sub-directory per file, unique names
        base, k = f.stem, 1
        while base in names:
            k += 1
            base = f"{f.stem}-{k}"
        names.append(base)
    for n in names:
        (tmp / n).mkdir()
    # the emulator travels once per task (tens of MB at most); results are small dicts
    task = functools.partial(_batch_task, cfg, absorption, seed)
    results = run_tasks(task, [(str(f), str(tmp / n)) for f, n in zip(files, names, strict=True)],
                        client=client, errors="return", retries=1, progress=not quiet,
                        label="identify")
    rows = []
    for f, n, r in zip(files, names, results, strict=True):
        if isinstance(r, TaskError):
            rows.append({"data": str(f), "dir": "", "error": str(r.error)})
            shutil.rmtree(tmp / n, ignore_errors=True)
        else:
            rows.append({**r, "dir": n})
    keys = list(next((r["parameters"] for r in rows if "parameters" in r), {}))
    lines = ["data,dir,status," + ",".join(f"{k}_mean,{k}_std" for k in keys) + ",message"]
    for r in rows:
        if "error" in r:
            vals = ",".join("," for _ in keys)
            lines.append(f"{r['data']},{r['dir']},error,{vals},\"{r['error']}\"")
        else:
            vals = ",".join(f"{r['parameters'][k]['estimate_final']:.6g},"
                            f"{r['parameters'][k]['std_final']:.6g}" for k in keys)
            status = "stopped" if r["stopped"] else "ok"
            lines.append(f"{r['data']},{r['dir']},{status},{vals},\"{r['stopped'] or ''}\"")
    (tmp / "batch.csv").write_text("\n".join(lines) + "\n")
    return rows


def _batch_task(cfg, absorption, seed, item):
    data_path, out_dir = item
    return _identify_one(cfg, absorption, seed, data_path, out_dir)


def _follow(args, cfg, absorption, seed, t_emu) -> int:
    """Online mode: --out is written as the data come (not atomically: it is live)."""
    from .report import manifest
    from .stream import follow_csv
    from .tissue import OnlineIdentifier

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    setup = cfg.setup(absorption, seed=seed)
    ident = OnlineIdentifier(setup, param_bounds=cfg.param_bounds,
                             dt_hint=1.0 / cfg.rate if cfg.rate else 0.1)
    names = list(setup.estimate)
    cols = ["time_s"] + [f"{n}_{s}" for n in names for s in ("mean", "std")] + [
        f"T{j}_{s}" for j in range(len(setup.tracked_positions)) for s in ("mean", "std")]
    fh = open(out / "estimates.csv", "w", encoding="utf-8")
    fh.write(",".join(cols) + "\n")
    fh.flush()
    last_fig = [0.0]

    def on_update(est, line):
        vals = [est.time] + [v for i in range(len(names))
                             for v in (est.param_mean[i], est.param_std[i])]
        vals += [v for j in range(len(est.tracked_mean))
                 for v in (est.tracked_mean[j], est.tracked_std[j])]
        fh.write(",".join(f"{v:.8g}" for v in vals) + "\n")
        fh.flush()  # the estimate is on disk before the next frame is read
        now = time.perf_counter()
        if now - last_fig[0] > 2.0:  # the figure, at most every 2 s (it takes ~0.3 s)
            _live_figure(out, ident, setup)
            last_fig[0] = time.perf_counter()

    t0 = time.perf_counter()
    try:
        n = follow_csv(args.follow, ident, on_update, idle_timeout_s=args.idle_timeout,
                       columns=None if cfg.data.columns is None else ["time", *cfg.data.columns])
    finally:
        fh.close()
    _live_figure(out, ident, setup)
    manifest(out / "run.json", command="identify --follow", config=cfg.raw, seed=seed,
             timings={"emulator": t_emu, "stream": time.perf_counter() - t0},
             extra={"follow": str(args.follow), "readings": n})
    if not args.quiet:
        print(f"{n} readings assimilated -> {out}")
    return 0


def _live_figure(out, ident, setup) -> None:
    import numpy as np

    from .report import plot_identification
    from .tissue import TissueEstimates

    h = ident.history
    if not h:
        return
    est = TissueEstimates(
        times=np.array([e.time for e in h]), names=setup.estimate,
        param_mean=np.array([e.param_mean for e in h]), param_std=np.array([e.param_std for e in h]),
        tracked_positions=setup.tracked_positions,
        tracked_mean=np.array([e.tracked_mean for e in h]),
        tracked_std=np.array([e.tracked_std for e in h]),
        analysed=np.array([e.analysed for e in h]),
        step_latency_s=np.array([e.latency_s for e in h]), filter_wall_s=0.0)
    (Path(out) / "figures").mkdir(exist_ok=True)
    tmp = Path(out) / "figures" / ".estimates.png.tmp.png"
    plot_identification(tmp, est, None, None, setup.power)
    tmp.replace(Path(out) / "figures" / "estimates.png")  # a viewer never sees half a file


def cmd_validate(args) -> int:
    from .report import manifest
    from .rundir import atomic_dir, check_out_dir
    from .suite import run_suite, select, validation_dir

    check_out_dir(args.out, args.force)
    _apply_threads(args.threads)
    validation_dir()
    names = select(args.full, args.only)
    seed = 0 if args.seed is None else args.seed
    t0 = time.perf_counter()
    with atomic_dir(args.out, args.force) as tmp:
        res = run_suite(tmp, full=args.full, only=names, seed=seed, threads=args.threads,
                        progress=not args.quiet)
        manifest(tmp / "run.json", command="validate",
                 config={"full": args.full, "checks": names}, seed=seed,
                 timings={"total": time.perf_counter() - t0,
                          **{n: r["seconds"] for n, r in res.items()}},
                 extra={"status": {n: r["status"] for n, r in res.items()}})
    failed = [n for n, r in res.items() if r["status"] != "ok"]
    if not args.quiet or failed:
        print(f"report -> {Path(args.out) / 'report.md'}"
              + (f"; failed: {', '.join(failed)}" if failed else ""), file=sys.stderr)
    return EXIT_CHECK_FAILED if failed else 0


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from . import report

    report.command_line = ["tissue-enkf", *(sys.argv[1:] if argv is None else argv)]
    try:
        if getattr(args, "seed", None) is not None and args.seed < 0:
            raise ValueError(f"--seed must be >= 0, got {args.seed}")
        return args.func(args)
    except KeyboardInterrupt:
        print("interrupted: nothing written", file=sys.stderr)
        return 130
    except (ValueError, OSError) as err:
        msg = str(err).splitlines()[0] if str(err) else type(err).__name__
        print(f"error: {msg}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
