"""``paper``: the paper's experiments and its sensitivity study."""

from __future__ import annotations

import sys

from fem.checks import check_number

from .common import apply_threads, close_client, dask_client
from .config.numbers import LIMITS

__all__ = ["cmd_paper"]

def cmd_paper(args) -> int:
    from .. import paper
    from .rundir import check_out_dir

    check_out_dir(args.out, args.force)
    apply_threads(args.threads)
    if args.members < 2:
        raise ValueError(f"--members must be >= 2, got {args.members}")
    # the limits of the config's keys for the same things (filter.emulator.*)
    check_number("--emulator-photons", args.emulator_photons, integer=True, lo=1,
                 hi=LIMITS["filter.emulator.n_photons"])
    check_number("--emulator-table", args.emulator_table, integer=True, lo=4,
                 hi=LIMITS["filter.emulator.n_mua"])
    verbose = not args.quiet
    client = dask_client(args)
    try:
        return _paper(args, paper, client, verbose)
    finally:
        close_client(client)


def _paper(args, paper, client, verbose) -> int:
    from .rundir import atomic_dir

    if args.scenario == "sensitivity":
        return _sensitivity(args, paper, client, verbose)
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
                               cache_dir=args.cache_dir, progress=verbose, client=client,
                               drift=args.drift)
    with atomic_dir(args.out, args.force) as tmp:
        paper.write_run(run, tmp)
        from .report import manifest

        manifest(tmp / "run.json", command=f"paper {args.scenario}",
                 config={"scenario": args.scenario, "members": args.members,
                         "method": args.method, "fine": list(args.fine),
                         "truth_photons": args.truth_photons,
                         "emulator_photons": args.emulator_photons,
                         "emulator_table": args.emulator_table, "exact": args.exact,
                         "drift": args.drift},
                 seed=run.summary["seed"], timings={"total": run.summary["wall_seconds"],
                                                    **{k: v for k, v in
                                                       run.summary["timing"].items()
                                                       if k.endswith("_s")}})
    # the result, even with --quiet (it hides the progress bars only)
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
    if summary["stopped"]:
        print(f"warning: the filter stopped early: {summary['stopped']} (estimates up to "
              "then are written)", file=sys.stderr)
    return 0


def _sensitivity(args, paper, client, verbose) -> int:
    """The paper's sensitivity study: sensitivity.csv, figures/ and run.json; the peaks."""
    import time

    import numpy as np

    from .report import manifest
    from .rundir import atomic_dir

    t0 = time.perf_counter()
    n_photons = 10**6 if args.truth_photons is None else check_number(
        "--truth-photons", args.truth_photons, integer=True, lo=1)
    seed = 1 if args.seed is None else args.seed  # paper_model's Monte Carlo seed
    res = paper.sensitivity_study(tuple(args.fine), n_photons, progress=verbose,
                                  client=client, seed=seed)
    with atomic_dir(args.out, args.force) as tmp:
        (tmp / "figures").mkdir()
        paper.plot_sensitivity(tmp / "figures" / "sensitivity.png", res)
        cols = [f"T_mua_{v:g}" for v in res["mua"]] + [f"T_mus_{v:g}" for v in res["mus"]]
        np.savetxt(tmp / "sensitivity.csv", np.column_stack(
            [res["times"], *res["mua"].values(), *res["mus"].values()]), delimiter=",",
            header="time_s," + ",".join(cols), comments="", fmt="%.8g")
        manifest(tmp / "run.json", command="paper sensitivity",
                 config={"scenario": "sensitivity", "fine": list(args.fine),
                         "truth_photons": n_photons, "mua": [float(v) for v in res["mua"]],
                         "mus": [float(v) for v in res["mus"]]},
                 seed=seed, timings={"total": time.perf_counter() - t0})
    # the result, even with --quiet (it hides the progress bars only)
    for name, held in (("mua", "mus"), ("mus", "mua")):
        peaks = ", ".join(f"{v:g}: {np.max(T):.2f}" for v, T in res[name].items())
        print(f"peak T at the sensor (deg C) against {name} (cm^-1; {held} = "
              f"{paper.TABLE[held]:g}): {peaks}")
    print(f"-> {args.out}")
    return 0
