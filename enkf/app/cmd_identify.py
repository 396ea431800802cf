"""``identify``: the filter on measured data (one file, a batch, or a live stream)."""

from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path

from .cmd_follow import follow
from .common import apply_threads, close_client, dask_client, shorten

__all__ = ["EXIT_BATCH_FAILED", "cmd_identify"]

EXIT_BATCH_FAILED = 1  #: every file of a batch failed (batch.csv says why)

def _smoother_summary(setup, times, data, n_iter: int, options: dict, quiet: bool) -> dict:
    """summary.json's ``smoother``: ES-MDA over the whole window, for constant optics
    (``knots`` 1) or optics drifting while heated (``knots`` >= 2; the estimates are those
    at the window's end, and the knots' values are listed)."""
    from mcmatlab_py.progress import Progress

    from ..tissue import smooth_constant, smooth_drifting

    opts = dict(options or {})
    knots = int(opts.pop("knots", 1))
    bar = Progress(1.0, "smoother", enabled=not quiet)
    kw = {**opts, "n_iter": n_iter, "callback": bar.update}
    try:
        if knots > 1:
            est = smooth_drifting(setup, times, data, knots=knots, **kw)
        else:
            est = smooth_constant(setup, times, data, **kw)
    finally:
        bar.close()
    if not quiet:
        imp = "" if est.weights is None else f", importance sampling: ESS {est.ess:.0f}"
        if est.n_modes is not None:
            imp += f", {est.n_modes} mode{'s' * (est.n_modes > 1)}"
        print(f"smoother (ES-MDA, {n_iter} updates{imp}, {est.wall_s:.1f} s): " + ", ".join(
            f"{n} {m:.4g} +- {s:.2g}" for n, m, s in zip(est.names, est.mean, est.std,
                                                          strict=True)), file=sys.stderr)
    out = {"method": "ES-MDA + AMIS" if est.weights is not None else "ES-MDA",
           "iterations": n_iter, "knots": knots, **opts, "wall_s": est.wall_s,
           "parameters": {n: {"estimate": float(est.mean[i]), "std": float(est.std[i]),
                              "band_2sd": list(est.band(i))}
                          for i, n in enumerate(est.names)}}
    if knots > 1:
        out["knot_times_heated_s"] = est.knot_times.tolist()
        knots = est.knot_mean()
        out["knot_estimates"] = {n: knots[:, i].tolist() for i, n in enumerate(est.names)}
    if est.weights is not None:
        out["effective_sample_size"] = float(est.ess)
    if est.n_modes is not None:
        out["modes_found"] = int(est.n_modes)
    return out


def _check_smoother_size(cfg, data, data_path) -> None:
    """The smoother's discrepancy needs a dense covariance of every reading: refuse a data
    file too long for it before the filter runs."""
    import numpy as np

    from ..tissue.smooth import check_discrepancy_size

    if cfg.smoother_iterations or cfg.setup_kw.get("smoother_restarts"):
        check_discrepancy_size(np.isfinite(data).sum(),
                               (cfg.smoother_options or {}).get("discrepancy", 0.0),
                               f"{data_path}: filter.smoother_")


def _identify_one(cfg, absorption, seed, data_path, out_dir, quiet=True) -> dict:
    """Run the filter on one data file and write its outputs into ``out_dir`` (a task)."""
    from mcmatlab_py.progress import Progress

    from ..tissue import identify
    from ..tissue.absorption import fill_prior_points
    from .report import write_identify_outputs
    from .rundir import write_json

    times, data = cfg.read_data(data_path)  # first: it may register the camera
    setup = cfg.setup(absorption, seed=seed)
    _check_smoother_size(cfg, data, data_path)  # before the filter, not after it
    fill_prior_points(setup)  # an on-demand emulator: the prior's points before the filter
    # [advice]: each member forecast to the target after each reading (enkf.tissue.advice)
    advisor = None if cfg.advice is None else cfg.advice.advisor(setup)
    medium = cfg.model.G.media[cfg.medium]  # the estimated medium's damage law
    risks = {}  # one tracker per filter (a drift bank runs several)
    n_filters = 1 if setup.parameters.drift is None else len(setup.parameters.drift.restart_knots) + 1
    bar = Progress(len(times) * n_filters, "filter", enabled=not quiet)
    seen = {}  # the bank's filters run one after the other

    def callback(rep):
        if medium.E and medium.A:  # MCmatlab's damage model: the risk of injury per node
            from ..tissue.risk import RiskTracker

            if rep.component not in risks:
                risks[rep.component] = RiskTracker(E=medium.E, A=medium.A, record_every=10)
            risks[rep.component](rep)  # a restart's replay from step 0 recomputes the damage
        if advisor is not None:
            advisor(rep)
        if not rep.replayed:
            bar.update(rep.step + len(times) * seen.setdefault(rep.component, len(seen)))

    t0 = time.perf_counter()
    try:
        est = identify(setup, times, data, callback=callback, param_bounds=cfg.param_bounds)
    finally:
        bar.close()
    # the risk maps of the filter the data support at the end (a bank's mixture weighs
    # the optics; each filter's damage follows its own members)
    risk = risks.get(est.leading_component)
    media = cfg.model.G.media
    names = None
    if len(media) > 1:  # whose optics each parameter is (VHC and TC: the whole block's)
        names = {"mua": media[cfg.medium].name, "mus": media[cfg.medium].name}
        if cfg.second_medium is not None:
            names.update(mua2=media[cfg.second_medium].name, mus2=media[cfg.second_medium].name)
    summary = write_identify_outputs(Path(out_dir), setup, est, times, data,
                                     absorption=absorption, risk=risk, media=names,
                                     advisor=advisor)
    if cfg.smoother_iterations:
        summary["smoother"] = _smoother_summary(setup, times, data, cfg.smoother_iterations,
                                                cfg.smoother_options, quiet)
        write_json(Path(out_dir) / "summary.json", summary)
    if cfg.camera_record():  # where the camera's frames put the spot
        summary.update(cfg.camera_record())
        write_json(Path(out_dir) / "summary.json", summary)
    summary["data"] = str(data_path)
    summary["wall_s"] = time.perf_counter() - t0
    return summary


def cmd_identify(args) -> int:
    from .config import load_identify
    from .report import manifest
    from .rundir import atomic_dir, check_out_dir, write_json

    if not (math.isfinite(args.idle_timeout) and args.idle_timeout > 0):
        raise ValueError(f"--idle-timeout must be a finite number of seconds > 0, got "
                         f"{shorten(args.idle_timeout)}")
    check_out_dir(args.out, args.force, whole=args.follow is None)
    apply_threads(args.threads)
    cfg = load_identify(args.config)
    if args.data is None and args.follow is None and cfg.data.file is not None:
        args.data = [str(cfg.data.file)]
    if (args.data is None) == (args.follow is None):
        raise ValueError("give --data FILE [FILE ...] or --follow FILE (or data.file in the "
                         "config)")
    if getattr(args, "serve", None) is not None:
        from .cmd_replay import check_port

        check_port("--serve", args.serve)
        if args.follow is None:
            raise ValueError("--serve shows a --follow stream; for a finished run: "
                             "tissue-enkf replay RUN_DIR")
    if args.follow is not None and cfg.smoother_iterations:
        raise ValueError("filter.smoother_iterations is not used with --follow (the smoother "
                         "needs the whole window): run identify --data on the finished file")
    if args.follow is not None and cfg.data.time_offset is not None:
        raise ValueError("data.time_offset is not supported with --follow: write the times "
                         "from the laser's start")
    if cfg.second_medium is not None and "image" not in cfg.setup_kw:
        warnings.warn("both layers from point sensors: one surface sensor hardly determines the "
                      "second medium's optics, and the bands were too narrow on twin runs with "
                      "truths away from the prior's centre (docs/layered.md, 'Both layers'); a "
                      "camera ([sensors.camera]) determines all four", RuntimeWarning,
                      stacklevel=2)
    seed = args.seed if args.seed is not None else cfg.setup_kw.get("seed", 0)
    files = [Path(f) for f in (args.data or [])]
    if len(files) == 1:  # one dataset: bad data is bad input (exit 2, nothing written);
        # in a batch a bad file is reported in batch.csv and the others go on
        cfg.read_data(files[0])
    t0 = time.perf_counter()
    client = dask_client(args, cfg.raw)
    try:
        absorption = cfg.emulator(cache_dir=args.cache_dir, progress=not args.quiet,
                                  client=client)
        t_emu = time.perf_counter() - t0
        if args.follow is not None:
            return follow(args, cfg, absorption, seed, t_emu)
        with atomic_dir(args.out, args.force) as tmp:
            if len(files) == 1:
                summary = _identify_one(cfg, absorption, seed, files[0], tmp, args.quiet)
                rows = [summary]
            else:
                rows = _identify_batch(cfg, absorption, seed, files, tmp, client, args.quiet)
            extra = {"data": [str(f) for f in files]}
            have = getattr(absorption, "have", None)
            if have is not None:  # the emulator's table points built so far (on demand)
                extra["emulator_points"] = {"built": int(have.sum()), "table": int(have.size)}
            manifest(tmp / "run.json", command="identify", config=cfg.raw, seed=seed,
                     timings={"emulator": t_emu, "total": time.perf_counter() - t0},
                     extra=extra)
            if len(files) > 1:
                write_json(tmp / "summary.json", {"runs": rows})
    finally:
        close_client(client)
    for r in rows:
        if r.get("stopped"):
            print(f"warning: {r['data']}: the filter stopped early: {r['stopped']} (estimates "
                  "up to then are written)", file=sys.stderr)
    if len(files) > 1 and all("error" in r for r in rows):
        for r in rows:
            print(f"{r['data']}: failed: {r['error']}", file=sys.stderr)
        print(f"error: all {len(rows)} data files failed (see {Path(args.out) / 'batch.csv'})",
              file=sys.stderr)
        return EXIT_BATCH_FAILED
    # the result, even with --quiet (it hides the progress bars only)
    from ..tissue.advice import advice_line

    for r in rows:
        if "error" in r:
            print(f"{r['data']}: failed: {r['error']}", file=sys.stderr)
            continue
        par = ", ".join(f"{k} {v['estimate_final']:.4g} +- {v['std_final']:.2g}"
                        for k, v in r["parameters"].items())
        for j, o in enumerate(r.get("sensor_offsets") or []):
            par += f", sensor {j + 1} offset {o['estimate_final']:+.3f} +- {o['std_final']:.2g} deg C"
        stop = f" (stopped: {r['stopped']})" if r["stopped"] else ""
        drift = r.get("drift")
        if drift:
            par += (f"; optics {drift['behaviour']} while heated (P(drift) = "
                    f"{drift['weight_final']:.2g})")
        print(f"{r['data']}: {par}{stop}")
        if r.get("advice"):
            print(f"{r['data']}: {advice_line(r['advice'])}")
    print(f"-> {args.out}")
    return 0


def _identify_batch(cfg, absorption, seed, files, tmp, client, quiet) -> list:
    import functools
    import shutil

    from mcmatlab_py.distributed import TaskError, run_tasks

    from ..tissue.absorption import fill_prior_points

    names = []
    for f in files:  # one sub-directory per file, unique names
        base, k = f.stem, 1
        while base in names:
            k += 1
            base = f"{f.stem}-{k}"
        names.append(base)
    for n in names:
        (tmp / n).mkdir()
    # an on-demand emulator: the points of the prior's optics here (with the cluster),
    # before it travels, not once per worker
    fill_prior_points(cfg.setup(absorption))
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
    _write_batch_csv(tmp / "batch.csv", rows)
    return rows


def _write_batch_csv(path: Path, rows: list) -> None:
    """One row per data file: data, dir, status (ok, stopped, error), then the final mean
    and std of each parameter, and a message (the error, or why the filter stopped).

    The csv module quotes a path or a message holding commas, quotes or line breaks."""
    import csv

    keys = list(next((r["parameters"] for r in rows if "parameters" in r), {}))
    with open(path, "w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["data", "dir", "status", *(f"{k}_{s}" for k in keys for s in ("mean", "std")),
                    "message"])
        for r in rows:
            if "error" in r:
                w.writerow([r["data"], r["dir"], "error", *([""] * (2 * len(keys))), r["error"]])
                continue
            vals = [f"{r['parameters'][k][f]:.6g}" for k in keys
                    for f in ("estimate_final", "std_final")]
            w.writerow([r["data"], r["dir"], "stopped" if r["stopped"] else "ok", *vals,
                        r["stopped"] or ""])


def _batch_task(cfg, absorption, seed, item):
    data_path, out_dir = item
    return _identify_one(cfg, absorption, seed, data_path, out_dir)
