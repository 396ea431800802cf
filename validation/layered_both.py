"""Both layers estimated: the epidermis's optics beside the dermis's.

The block of ``examples/two_layer.toml`` (an 80 micrometre epidermis over the dermis) with
``filter.medium = ["dermis", "epidermis"]``: the filter estimates the dermis's ``mua``,
``mus`` and the epidermis's ``mua2``, ``mus2`` (priors 0.5-2 x (1, 100) and (5, 150)
cm^-1), with :class:`mcmatlab_py.emulator.media.TwoMediaEmulator` (a 4 x 4 grid of the
dermis tables over the epidermis's optics).

1. **Emulator** (``--emulator``): build time from an empty cache, and the relative L2 error
   of the nodal loads against direct Monte Carlo of the layered model (``--ref-photons``)
   at points between the epidermis nodes and at the dermis prior's corners, beside that of
   one direct run with the tables' photons (the Monte Carlo error at equal cost).
2. **What one sensor and a camera can determine**: the Cramér-Rao bound of the four log
   coefficients (the filter's coarse model at the truth, finite-difference Jacobian, the
   uniform prior as a Gaussian of log-sd 0.38, as ``validation/identifiability.py``),
   its correlations, and the bound of the dermis alone under a known epidermis.
3. **Filter (and smoother) on twin truths** over seeds: RMS log error against the bound,
   and the share of seeds whose +-2 sd band holds the truth (targets 1.3x and 90%).
4. **Filter on a fine truth** (``--fine``): the data from direct Monte Carlo (10^6
   photons) of the layered block and the heat simulation on the Monte Carlo's voxels at
   truth A, with the config's structured model error (``validation/layered.py``).

    python validation/layered_both.py --seeds 20 --emulator --smoother 8 --fine
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import shlex
import tempfile
import time
from pathlib import Path

import numpy as np

from enkf.app.config import identify_config_from_dict
from enkf.app.suite import load_script, validation_dir

HERE = Path(__file__).parent
NAMES = ("mua", "mus", "mua2", "mus2")
#: (dermis mua, mus, epidermis mua2, mus2): the priors' centres, and a point off them
TRUTHS = {"A (centre)": dict(zip(NAMES, (1.0, 100.0, 5.0, 150.0), strict=True)),
          "B (off-centre)": dict(zip(NAMES, (1.6, 70.0, 3.5, 220.0), strict=True))}
#: emulator test points: between the epidermis nodes (by default 1.67, 5, 15 x 50, 150,
#: 450 cm^-1: the prior widened 1.5 times each way), at the prior's corners, beyond them,
#: and on the central node
POINTS = [(1.0, 100.0, 3.5, 105.0), (1.0, 100.0, 7.0, 220.0), (0.6, 160.0, 3.5, 220.0),
          (1.6, 60.0, 7.0, 105.0), (0.5, 50.0, 2.5, 300.0), (2.0, 200.0, 10.0, 75.0),
          (1.0, 100.0, 12.0, 380.0), (1.0, 100.0, 2.0, 60.0), (1.0, 100.0, 5.0, 150.0)]


def both_config(layered):
    """``examples/two_layer.toml`` with both layers estimated."""
    import tomllib

    cfg = tomllib.loads(layered.CONFIG.read_text())
    cfg["filter"].update(medium=["dermis", "epidermis"], estimate=list(NAMES))
    cfg.pop("data")
    return identify_config_from_dict(cfg)


def emulator_study(cfg, ref_photons: int) -> list[str]:
    """Build time and load errors of the two-media emulator (section 1)."""
    from mcmatlab_py.emulator import EmulatorSpec
    from mcmatlab_py.emulator.exact import direct_member

    spec = EmulatorSpec.from_model(cfg.model, medium=cfg.medium, mesh_divisions=tuple(cfg.grid),
                                   **cfg.emulator_kw)
    with tempfile.TemporaryDirectory() as tmp:
        c = copy.copy(cfg)
        c.emulator_on_demand = False
        t0 = time.perf_counter()
        emu = c.emulator(cache_dir=tmp, progress=False)
        seconds = time.perf_counter() - t0
    print(f"two-media emulator built in {seconds:.1f} s", flush=True)
    rows = []
    for i, (a, s, a2, s2) in enumerate(POINTS):
        media = list(spec.media)
        media[cfg.second_medium] = (a2, s2, *media[cfg.second_medium][2:])
        at = dataclasses.replace(spec, media=tuple(media), medium_map=spec.medium_map)
        ref = direct_member(dataclasses.replace(at, n_photons=ref_photons,
                                                medium_map=spec.medium_map), 1000 + i,
                            (a, s)).ravel()
        one = direct_member(dataclasses.replace(at, n_photons=spec.photons_at(s),
                                                medium_map=spec.medium_map), 2000 + i,
                            (a, s)).ravel()
        val = emu(np.array([a]), np.array([s]), np.array([a2]), np.array([s2])).ravel()
        err = np.linalg.norm(val - ref) / np.linalg.norm(ref)
        err1 = np.linalg.norm(one - ref) / np.linalg.norm(ref)
        rows.append(f"| ({a:g}, {s:g}) | ({a2:g}, {s2:g}) | {100 * err:.2f}% | {100 * err1:.2f}% |")
        print(rows[-1], flush=True)
    n = cfg.media_nodes["n_nodes"]
    return [
        "## 1. The emulator of both layers", "",
        f"{n} x {n} epidermis nodes over mua2 {[round(v, 3) for v in cfg.media_nodes['mua2_range']]}"
        " x mus2 "
        f"{[round(v, 3) for v in cfg.media_nodes['mus2_range']]} cm^-1 (the prior widened 1.5 "
        f"times each way), each a {spec.n_mua} x "
        f"{spec.n_mus} dermis table (`{emu.tables[0].method}`, {spec.n_photons} photons per "
        f"point at mus = 100); Monte Carlo on {spec.nx} x {spec.ny} x {spec.nz} voxels, nodal "
        f"loads on the {' x '.join(map(str, spec.mesh_divisions))} mesh. Built from an empty "
        f"cache in **{seconds:.1f} s** ({n * n} tables).", "",
        f"Relative L2 error of the nodal loads against direct Monte Carlo of the layered model "
        f"({ref_photons} photons, its own seed per point); 'one direct run': a direct run with "
        "the photons a table spends per point, against the same reference (the Monte Carlo "
        "error at equal cost, the reference's own noise included).", "",
        "| dermis (mua, mus) | epidermis (mua2, mus2) | emulator | one direct run |",
        "|---|---|---|---|", *rows, ""]


def log_fisher(sensor, truth: dict, h: float = 0.01) -> np.ndarray:
    """(n, n) Fisher information of the log parameters (``sensor.setup.parameters.names``)
    from 150 whitened readings: central differences of step ``h`` in log units, all members
    in one batch of the coarse model."""
    names = tuple(sensor.setup.parameters.names)
    x0 = np.log([truth[n] for n in names])
    X = [x0]
    for i in range(len(names)):
        for sgn in (1, -1):
            x = x0.copy()
            x[i] += sgn * h
            X.append(x)
    Y = sensor.readings(np.exp(np.array(X)))  # (steps, p, M)
    Y = Y / np.sqrt(np.asarray(sensor.noise_var, float))[None, :, None]
    Y = Y.reshape(-1, Y.shape[-1])
    J = np.column_stack([(Y[:, 1 + 2 * i] - Y[:, 2 + 2 * i]) / (2 * h) for i in range(len(names))])
    return J.T @ J


def bounds(F: np.ndarray, prior_sd: float) -> np.ndarray:
    """Covariance bound with the prior as a Gaussian of log-sd ``prior_sd`` per parameter."""
    return np.linalg.inv(F + np.eye(len(F)) / prior_sd ** 2)


def prior_draws(setup, seeds) -> list[dict]:
    """One truth per seed drawn from the filter's own prior (uniform in each parameter's
    [lo, hi]): what a calibrated posterior covers on 95% of draws on average."""
    lo, hi = setup.parameters.prior_bounds()
    names = setup.parameters.names
    return [dict(zip(names, lo + (hi - lo) * np.random.default_rng(50_000 + s).uniform(
        size=len(names)), strict=True)) for s in seeds]


def over_prior_draws(layered, cfg, emulator, kind, sensor, seeds, runner, *extra) -> tuple:
    """``runner`` (``layered.run_seeds`` or ``smooth_seeds``) once per seed at that seed's
    prior draw: the results of all seeds, and the root mean square over the draws of each
    draw's own bound (the information of one sensor varies severalfold across the prior,
    and along ridges of different directions)."""
    import contextlib
    import io

    truths = prior_draws(sensor.setup, seeds)
    parts, var = [], 0.0
    for seed, truth in zip(seeds, truths, strict=True):
        clean = layered.twin_data(sensor, truth)
        with contextlib.redirect_stdout(io.StringIO()):  # one line per seed, below
            parts.append(runner(cfg, emulator, kind, truth, clean, [seed], *extra))
        var = var + np.diag(bounds(log_fisher(sensor, truth), 0.38)) / len(seeds)
        r = parts[-1]
        print(f"  {kind} prior draw {seed}: truth {np.round([truth[n] for n in NAMES], 3)} "
              f"log error {np.round(r['err'][0], 3)} covered {r['covered'][0]}", flush=True)
    res = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    return res, np.sqrt(var)


def _row(kind, label, truth, res, crb) -> str:
    rms = np.sqrt(np.mean(res["err"] ** 2, axis=0))
    cov = res["covered"].mean(axis=0)
    cells = []
    for i in range(len(NAMES)):
        cells += [f"{100 * rms[i]:.2f}% ({rms[i] / crb[i]:.2f})", f"{100 * cov[i]:.0f}%"]
    return (f"| {kind} | {label.split()[0]} | {len(res['err'])} | " + " | ".join(cells)
            + f" | {np.median(res['seconds']):.1f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--emulator", action="store_true", help="section 1")
    ap.add_argument("--ref-photons", type=int, default=1_000_000)
    ap.add_argument("--truths", default=",".join(TRUTHS), help="comma-separated labels")
    ap.add_argument("--kinds", default="sensor,camera")
    ap.add_argument("--smoother", type=int, default=0, metavar="N_ITER")
    ap.add_argument("--importance", type=int, default=0, metavar="M",
                    help="the smoother followed by M samples of adaptive importance sampling "
                         "(enkf.importance): the posterior itself")
    ap.add_argument("--modes", type=int, default=0, metavar="P",
                    help="with --importance: P prior points screened for other modes "
                         "(enkf.modes), which seed the sampler beside the ensemble")
    ap.add_argument("--no-filter", action="store_true", help="the smoother's rows only")
    ap.add_argument("--fine", action="store_true",
                    help="also a fine truth at A (direct Monte Carlo and heat on the voxels), "
                         "point sensor, the config's structured model error")
    ap.add_argument("--cache-dir", default=None)
    ap.add_argument("--n-members", type=int, default=None, help="default: the config's (50)")
    ap.add_argument("--out", default=str(HERE / "reports" / "layered_both.md"))
    args = ap.parse_args(argv)
    layered = load_script(validation_dir(), "layered")
    ident = load_script(validation_dir(), "identifiability")
    cfg = both_config(layered)
    cmd = "python validation/layered_both.py " + shlex.join(argv if argv is not None else
                                                            __import__("sys").argv[1:])
    lines = ["# Both layers estimated: the dermis's and the epidermis's optics", "",
             f"Command: `{cmd.strip()}`; config `examples/two_layer.toml` with `filter.medium = "
             "[\"dermis\", \"epidermis\"]` and `estimate = [\"mua\", \"mus\", \"mua2\", "
             "\"mus2\"]` (epidermis 80 um, g 0.8; priors 0.5-2 x (1, 100) and (5, 150) "
             "cm^-1).", ""]
    if args.emulator:
        lines += emulator_study(cfg, args.ref_photons)
    t0 = time.perf_counter()
    emulator = cfg.emulator(cache_dir=args.cache_dir, progress=False)
    print(f"emulator ready in {time.perf_counter() - t0:.1f} s", flush=True)
    kinds = [k for k in args.kinds.split(",") if k]
    truths = {k: TRUTHS[k] for k in args.truths.split(",") if k != "prior"}
    draws = "prior" in args.truths.split(",")
    crb_rows, filt_rows = [], []
    members = {} if args.n_members is None else {"n_members": args.n_members}
    smoother = f"ES-MDA ({args.smoother})" + (
        f" + AMIS ({args.importance})" if args.importance else "") + (
        f" + modes ({args.modes})" if args.modes else "")
    for kind in kinds:
        sensor = ident.ConfigSensor(layered.sensor_setup(cfg, emulator, kind), layered.DT,
                                    layered.N_STEPS)
        for label, truth in truths.items():
            F = log_fisher(sensor, truth)
            cov = bounds(F, ident.PRIOR_LOG_SD)
            crb = np.sqrt(np.diag(cov))
            corr = cov / np.outer(crb, crb)
            known = np.sqrt(np.diag(bounds(F[:2, :2], ident.PRIOR_LOG_SD)))
            crb_rows.append(
                f"| {kind} | {label.split()[0]} | " + " | ".join(f"{100 * v:.2f}%" for v in crb)
                + f" | {corr[0, 1]:+.2f}, {corr[0, 2]:+.2f}, {corr[1, 3]:+.2f}, "
                f"{corr[2, 3]:+.2f} | {100 * known[0]:.2f}%, {100 * known[1]:.2f}% |")
            print(crb_rows[-1], flush=True)
            clean = layered.twin_data(sensor, truth)
            over = {"model_error": "white", **members}
            if args.seeds and not args.no_filter:
                res = layered.run_seeds(cfg, emulator, kind, truth, clean, range(args.seeds),
                                        over)
                filt_rows.append(_row(kind, label, truth, res, crb)
                                 .replace(f"| {args.seeds} |", f"| filter, {args.seeds} |"))
                print(filt_rows[-1], flush=True)
            if args.seeds and args.smoother:
                res = layered.smooth_seeds(cfg, emulator, kind, truth, clean, range(args.seeds),
                                           args.smoother, over, args.importance, args.modes)
                filt_rows.append(_row(kind, label, truth, res, crb).replace(
                    f"| {args.seeds} |", f"| {smoother}, {args.seeds} |"))
                print(filt_rows[-1], flush=True)
            if args.fine and args.seeds and kind == "sensor" and label.startswith("A"):
                # the epidermis of the config is A's: fine_data sets the dermis
                fine = layered.fine_data(cfg, truth)
                res = layered.run_seeds(cfg, emulator, kind, truth, fine, range(args.seeds),
                                        {**members, "model_error": cfg.setup_kw.get("model_error",
                                                                         "white")})
                filt_rows.append(_row(kind, label, truth, res, crb).replace(
                    f"| {args.seeds} |", f"| filter on the fine truth, {args.seeds} |"))
                print(filt_rows[-1], flush=True)
        if draws and args.seeds:
            over = {"model_error": "white", **members}
            runners = [("filter", layered.run_seeds, (over,))][:0 if args.no_filter else 1]
            if args.smoother:
                runners.append((smoother, layered.smooth_seeds,
                                (args.smoother, over, args.importance, args.modes)))
            for label, runner, extra in runners:
                res, crb = over_prior_draws(layered, cfg, emulator, kind, sensor,
                                            range(args.seeds), runner, *extra)
                filt_rows.append(_row(kind, "prior draws", None, res, crb).replace(
                    f"| {args.seeds} |", f"| {label}, {args.seeds} |"))
                crb_rows.append(f"| {kind} | prior draws (RMS of each draw's bound) | "
                                + " | ".join(f"{100 * v:.2f}%" for v in crb) + " | | |")
                print(filt_rows[-1], flush=True)
    if crb_rows:
        lines += [
            "## 2. What one sensor and a camera can determine", "",
            "Lower bound on the sd of log mua, log mus (dermis) and log mua2, log mus2 "
            "(epidermis) of any estimate from 150 readings (noise variance 0.01 per sensor or "
            "pixel), with the filter's coarse model at the truth (central differences of 1% "
            "in log units) and each uniform prior as a Gaussian of log-sd 0.38: a bound near "
            "38% means the data add nothing to the prior. Correlations of (mua, mus), "
            "(mua, mua2), (mus, mus2), (mua2, mus2); last column: the dermis's bound when "
            "the epidermis is known.", "",
            "| observed | truth | mua | mus | mua2 | mus2 | correlations | dermis alone |",
            "|---|---|---|---|---|---|---|---|", *crb_rows, ""]
    if filt_rows:
        lines += [
            "## 3. The filter and the smoother on twin truths", "",
            "Truths A: dermis (1, 100), epidermis (5, 150) cm^-1; B: (1.6, 70), (3.5, 220). "
            "Final estimates at t = 15 s; each cell: RMS of log(estimate / truth) over the "
            "seeds (its ratio to the bound of section 2; target <= 1.3), then the share of "
            "seeds whose +-2 sd band (the ensemble's 2.3-97.7% quantiles) holds the truth "
            "(target >= 90%). N = 50, ETKF, white floor (identical twins).", "",
            "| observed | truth | estimator, seeds | mua | cov. | mus | cov. | mua2 | cov. "
            "| mus2 | cov. | s/run |", "|---|---|---|---|---|---|---|---|---|---|---|---|",
            *filt_rows, ""]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
