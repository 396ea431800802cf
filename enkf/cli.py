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


def _client(args):
    """The Dask client of --scheduler / --workers, or None (this machine's threads)."""
    scheduler, workers = getattr(args, "scheduler", None), getattr(args, "workers", None)
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
    p_mc.add_argument("config", help="TOML model file (see examples/)")
    p_mc.add_argument("--photons", type=int, default=None,
                      help="number of photon packets (overrides MC.n_photons_requested)")
    _common(p_mc)
    _dask_options(p_mc)
    p_mc.set_defaults(func=cmd_mc)

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
    return parser


def _apply_threads(threads):
    if threads is not None:
        import numba

        if threads < 1:
            raise ValueError(f"--threads must be >= 1, got {threads}")
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))


def cmd_mc(args) -> int:
    from mcmatlab_py.config import load_model
    from mcmatlab_py.export import write_voxel_vtu
    from mcmatlab_py.plotting import plot_na_slices

    from .rundir import atomic_dir, check_out_dir, write_json

    check_out_dir(args.out, args.force)
    _apply_threads(args.threads)
    model = load_model(args.config)
    if args.seed is not None:
        model.MC.seed = args.seed
    if args.photons is not None:
        model.MC.n_photons_requested = args.photons
    model.MC.progress = not args.quiet
    model.MC.n_threads = args.threads
    model.MC.validate(model.G)
    t0 = time.perf_counter()
    client = _client(args)
    try:
        model.run_monte_carlo(client=client)
    finally:
        _close(client)
    G, MC = model.G, model.MC
    import numpy as np

    with atomic_dir(args.out, args.force) as tmp:
        np.savez_compressed(tmp / "NA.npz", NA=MC.NA, NFR=MC.NFR, x=G.x, y=G.y, z=G.z)
        write_voxel_vtu(tmp / "NA.vtu", G, {"NA": MC.NA, "NFR": MC.NFR})
        plot_na_slices(model, tmp / "NA_slices.png")
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


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
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
