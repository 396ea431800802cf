"""``identify --follow``: the filter on a live stream, its outputs written as the data
come (run.json, estimates, a live page and figure)."""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

__all__ = ["OUTPUTS", "follow"]

#: what ``identify`` writes at the top of --out: what ``--follow --force`` clears first
OUTPUTS = ("estimates.csv", "advice.csv", "summary.json", "run.json", "batch.csv", "fields",
           "figures", "live")


def _set_aside_outputs(out: Path) -> Path:
    """Move what ``identify`` writes at the top of ``out`` (and nothing else: the directory
    is written in place, so other files there are left alone) into a hidden
    ``.replaced.PID.old`` inside it, removed once the new run has its run.json (or by the
    next run, if this one is killed first). run.json goes last: while an old output is in
    place, so is the run.json that says whose it is."""
    import os

    trash = out / f".replaced.{os.getpid()}.old"
    trash.mkdir()
    for name in sorted(OUTPUTS, key=lambda n: n == "run.json"):
        p = out / name
        if p.exists() or p.is_symlink():
            os.rename(p, trash / name)
    return trash


#: bad lines of a --follow stream listed in run.json (all are counted)
_LISTED_SKIPS = 100


def follow(args, cfg, absorption, seed, t_emu) -> int:
    """Online mode: --out is written as the data come (not atomically: it is live).

    It holds a run.json from the start (``"running": true``), rewritten when the stream
    ends, whatever ends it: the readings assimilated, the lines skipped, and why it
    stopped (``"interrupted"``, ``"stopped"``: an error, or the filter's health check,
    which ends the run with status 0 as it does on a file). A stream that ends in an error before
    its first reading leaves nothing. With --force the outputs of an earlier run in
    --out are set aside first and removed once the new run.json is written (no old
    summary.json or fields/final.vtu beside the new estimates). Interrupted (Ctrl-C,
    SIGTERM), the estimates so far stay; the exception carries ``outcome``, the line
    that ``main`` prints.
    """
    import shutil

    import numpy as np

    from ..problem import FilterDivergence
    from ..tissue import OnlineIdentifier
    from ..tissue.absorption import fill_prior_points
    from ..tissue.estimates import persistence_summary
    from ..tissue.outputs import readable_stop
    from .readers import follow_csv
    from .report import manifest
    from .rundir import remove_stale_partials, signals_deferred

    out = Path(args.out)
    created = not out.exists()
    # a camera writing frames into a folder (one not there yet: a name without a suffix)
    folder = Path(args.follow).is_dir() or (not Path(args.follow).exists()
                                            and not Path(args.follow).suffix)
    from .follow_file import CAMERA_SUFFIXES  # a camera file that grows (TIFF, HDF5)

    camera_file = not folder and Path(args.follow).suffix.lower() in CAMERA_SUFFIXES
    if (folder or camera_file) and ("image" not in cfg.setup_kw
                                    or len(cfg.setup_kw["sensor_positions"])):
        raise ValueError(f"{args.follow}: camera frames: the config needs [sensors.camera] and "
                         "no point sensors (sensors.positions = [])")
    if cfg.camera_registration is not None and not (folder or camera_file):
        raise ValueError("sensors.camera.spot_center = \"auto\" is estimated from frames: "
                         "follow the camera's folder or file, or give spot_center = "
                         "[column, row]")
    setup = cfg.setup(absorption, seed=seed)
    fill_prior_points(setup)  # before the first reading, not while the stream waits
    ident = OnlineIdentifier(setup, param_bounds=cfg.param_bounds,
                             dt_hint=1.0 / cfg.rate if cfg.rate else 0.1)
    names = list(setup.parameters.names)
    n_off = setup.sensors.n_offsets
    cols = ["time_s"] + [f"{n}_{s}" for n in names for s in ("mean", "std")] + [
        f"sensor{j + 1}_offset_{s}" for j in range(n_off) for s in ("mean", "std")] + [
        f"T{j}_{s}" for j in range(len(setup.sensors.tracked)) for s in ("mean", "std")] + (
        ["drift_weight"] if setup.parameters.drift is not None else []) + (
        ["target_time_median_s"] if cfg.advice is not None else [])
    # [advice]: after each reading, when the target is coagulated (advice.csv, and its
    # median in each line of estimates.csv); the bank's filters mixed by weight
    advisor = None if cfg.advice is None else cfg.advice.advisor(setup)
    advice_rows = []
    skipped = []
    t0 = time.perf_counter()

    def run_json(readings, **extra):
        shown = [{"line": n, "reason": r} for n, r in skipped[:_LISTED_SKIPS]]
        manifest(out / "run.json", command="identify --follow", config=cfg.raw, seed=seed,
                 timings={"emulator": t_emu, "stream": time.perf_counter() - t0},
                 extra={"follow": str(args.follow), "readings": readings,
                        "skipped_lines": len(skipped), "skipped": shown,
                        **_follow_restarts(ident, setup), **extra})

    out.mkdir(parents=True, exist_ok=True)
    remove_stale_partials(out)  # what a killed run set aside
    trash = None
    with signals_deferred():  # the old run whole, or the new one with its run.json
        if args.force:
            trash = _set_aside_outputs(out)
        run_json(0, running=True)
        fh = open(out / "estimates.csv", "w", encoding="utf-8")
        afh = None if advisor is None else open(out / "advice.csv", "w", encoding="utf-8")
    if trash is not None:
        shutil.rmtree(trash, ignore_errors=True)
    fh.write(",".join(cols) + "\n")
    fh.flush()
    last_fig = [0.0]
    recorder = page = None
    if getattr(args, "serve", None) is not None:  # the live page, in a process of its own
        from .live import LiveRecorder, start_page

        recorder = LiveRecorder(out, setup, cfg.model.G.media[cfg.medium])
        page, url = start_page(out, args.serve)
        print(f"live page: {url}", flush=True)

    def on_update(est, line):
        vals = [est.time] + [v for i in range(len(names))
                             for v in (est.param_mean[i], est.param_std[i])]
        vals += [v for j in range(n_off)
                 for v in (est.sensor_offset_mean[j], est.sensor_offset_std[j])]
        vals += [v for j in range(len(est.tracked_mean))
                 for v in (est.tracked_mean[j], est.tracked_std[j])]
        if est.drift_weight is not None:  # which behaviour of the optics the data support
            vals.append(est.drift_weight)
        if advisor is not None:
            from ..tissue.outputs import write_advice_csv

            advice_rows.append(advisor.online(ident))
            vals.append(advice_rows[-1].target_time[0])
            write_advice_csv(afh, advice_rows[-1:], advisor.quantiles, len(advice_rows) == 1)
        fh.write(",".join(f"{v:.8g}" for v in vals) + "\n")
        fh.flush()  # the estimate is on disk before the next frame is read
        if recorder is not None:  # the page draws; the filter only writes the damage
            recorder.reading(est.time, ident)
            return
        now = time.perf_counter()
        if now - last_fig[0] > 2.0:  # the figure, at most every 2 s (it takes ~0.3 s)
            _live_figure(out, ident, setup, advice_rows)
            last_fig[0] = time.perf_counter()

    def start(times, frames, final=False):
        """The identifier, once the first frames are in (they may place the camera)."""
        nonlocal setup, ident
        image = setup.sensors.image
        if frames.shape[1:] != tuple(int(v) for v in image.shape):
            raise ValueError(f"{args.follow}: frames are {frames.shape[1:]} pixels, the camera "
                             f"(sensors.camera.shape) {list(image.shape)}")
        if cfg.camera_registration is None:
            return ident
        image = cfg.camera_registration.estimate(frames, args.follow, complete=final)
        if image is None:
            return None
        cfg.setup_kw["image"] = image
        setup = cfg.setup(absorption, seed=seed)
        fill_prior_points(setup)
        ident = OnlineIdentifier(setup, param_bounds=cfg.param_bounds,
                                 dt_hint=1.0 / cfg.rate if cfg.rate else 0.1)
        if recorder is not None:
            recorder.setup = setup
            recorder.write_meta(setup)
        return ident

    stopped = None
    try:
        if folder:
            from .follow_frames import follow_folder

            n = follow_folder(args.follow, start, on_update, idle_timeout_s=args.idle_timeout,
                              rate=cfg.rate, emissivity=cfg.camera_emissivity, skipped=skipped,
                              on_frame=None if recorder is None else recorder.frame)
        elif camera_file:
            from .follow_file import follow_file

            n = follow_file(args.follow, start, on_update, idle_timeout_s=args.idle_timeout,
                            rate=cfg.rate, skipped=skipped,
                            on_frame=None if recorder is None else recorder.frame)
        else:
            n = follow_csv(args.follow, ident, on_update, idle_timeout_s=args.idle_timeout,
                           columns=None if cfg.data.columns is None
                           else ["time", *cfg.data.columns], skipped=skipped)
    except FilterDivergence as err:  # as for a file: the estimates up to then, exit 0
        n, stopped = len(ident.history), readable_stop(str(err), names)
    except BaseException as exc:
        fh.close()
        if afh is not None:
            afh.close()
        if page is not None:
            page.terminate()
        k = len(ident.history)
        if isinstance(exc, Exception) and k == 0:  # nothing assimilated: nothing left
            for name in OUTPUTS:
                p = out / name
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p, ignore_errors=True)
                elif p.exists() or p.is_symlink():
                    p.unlink()
            if created and not any(out.iterdir()):
                out.rmdir()
            raise
        try:
            if isinstance(exc, Exception):
                first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                run_json(k, stopped=first)
            else:  # Ctrl-C, SIGTERM: what is written stays
                run_json(k, interrupted=True)
        except Exception:  # noqa: BLE001 - the estimates matter; run.json is a bonus
            pass
        if not isinstance(exc, Exception):
            exc.outcome = f"{k} readings assimilated, estimates kept in {out}"
        elif isinstance(exc, ValueError | OSError):  # bad input: one line that says what stays
            raise ValueError(f"{exc} ({k} readings assimilated before it: estimates kept in "
                             f"{out})") from exc
        raise
    finally:
        fh.close()
        if afh is not None:
            afh.close()
    _live_figure(out, ident, setup, advice_rows)
    persistence = persistence_summary(ident)
    drift = {}
    if setup.parameters.drift is not None and ident.history:
        w = ident.history[-1].drift_weight
        drift = {"drift": {"behaviour": "drifting" if w >= 0.5 else "still", "weight_final": w}}
        print(f"optics {drift['drift']['behaviour']} while heated (P(drift) = {w:.2g})")
    if advice_rows:
        from ..tissue.advice import advice_line, advice_summary

        drift["advice"] = advice_summary(advisor, advice_rows)
        print(advice_line(drift["advice"]))
    lat = np.array([h.latency_s for h in ident.history])
    step_s = {"step_s": {"mean": float(lat.mean()), "p95": float(np.percentile(lat, 95)),
                         "max": float(lat.max())}} if lat.size else {}
    run_json(n, innovation_persistence=persistence, **drift, **cfg.camera_record(), **step_s,
             **({"stopped": stopped} if stopped else {}))
    if stopped:
        print(f"warning: {args.follow}: the filter stopped early: {stopped} (estimates up to "
              "then are written)", file=sys.stderr)
    if persistence["flagged"]:
        warnings.warn(persistence["advice"], RuntimeWarning, stacklevel=2)
    if skipped:
        print(f"warning: {len(skipped)} line{'s' * (len(skipped) > 1)} of {args.follow} "
              f"skipped (listed in {out / 'run.json'})", file=sys.stderr)
    # the result, even with --quiet (it hides the progress bars only)
    print(f"{n} readings assimilated -> {out}")
    if page is not None:
        _keep_page(page, url, recorder)
    return 0


def _keep_page(page, url: str, recorder) -> None:
    """The finished run's page stays until Ctrl-C (or a terminating signal), which closes
    it: the run is complete, the status stays 0."""
    recorder.write_risk()
    print(f"the live page stays at {url} with the final estimate: Ctrl-C closes it",
          flush=True)
    try:
        page.wait()
    except BaseException:  # noqa: BLE001 - Ctrl-C, SIGTERM: the page was what was left
        pass
    finally:
        page.terminate()
        page.wait()


def _follow_restarts(ident, setup) -> dict:
    """run.json's ``smoother_restarts`` of a --follow run (summary.json's shape, without
    the wall time): the time of each restart and the readings it used."""
    if not setup.restarts.times and setup.parameters.drift is None:
        return {}
    times = [h.time for h in ident.history]
    return {"smoother_restarts": [{"time_s": t, "readings": times.index(t) + 1}
                                  for t in ident.restart_times]}


def _live_figure(out, ident, setup, advice=None) -> None:
    import numpy as np

    from ..tissue import TissueEstimates
    from ..tissue.estimates import persistence_summary
    from .report import plot_identification

    h = ident.history
    if not h:
        return
    est = TissueEstimates(
        times=np.array([e.time for e in h]), names=setup.parameters.names,
        param_mean=np.array([e.param_mean for e in h]), param_std=np.array([e.param_std for e in h]),
        tracked_positions=setup.sensors.tracked,
        tracked_mean=np.array([e.tracked_mean for e in h]),
        tracked_std=np.array([e.tracked_std for e in h]),
        analysed=np.array([e.analysed for e in h]),
        step_latency_s=np.array([e.latency_s for e in h]), filter_wall_s=0.0,
        drift_weight=None if setup.parameters.drift is None else np.array([e.drift_weight for e in h]))
    (Path(out) / "figures").mkdir(exist_ok=True)
    tmp = Path(out) / "figures" / ".estimates.png.tmp.png"
    # the caution when the innovations persist, from the identifier's own record
    plot_identification(tmp, est, None, None, setup.power,
                        persistence=persistence_summary(ident), advice=advice)
    tmp.replace(Path(out) / "figures" / "estimates.png")  # a viewer never sees half a file
