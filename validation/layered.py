"""Identification under a known epidermis: emulator, Cramér-Rao bounds, filter.

The block of ``examples/two_layer.toml``: an 80 micrometre epidermis (mua 5, mus 150 cm^-1,
g 0.8, known) over the dermis (the paper's tissue: mua 1, mus 100 cm^-1, g 0.9), whose
mua and mus the filter estimates; one laser pulse of 0.5 W for 5 s, 150 readings at 10 Hz.

1. **Emulator** (``--emulator``): the layered table built both ways from an empty cache,
   one direct Monte Carlo run per point (``table``) and one white run per dermis mus
   (``white``), timed in this process; the relative L2 error of their nodal loads against
   a direct Monte Carlo reference of the layered model at off-grid points and at the
   corners of the prior, beside that of one direct run with the emulator's photons (the
   Monte Carlo error at equal cost).
2. **Cramér-Rao bounds** (``validation/identifiability.py``, :class:`ConfigSensor`): what
   one surface sensor and what a 16 x 16 camera over the beam can determine about the
   dermis's mua and mus, with the filter's own coarse model at the truth.
3. **Filter on twin truths**: the data are the filter's own model at the truth plus noise
   (variance 0.01); one run per seed (the noise and the filter's seed): final error of
   log mua and log mus against the bound, and how often the +-2 sd band (the ensemble's
   2.3-97.7% quantiles) covers the truth. No model error by construction: the filter's
   model error is the white floor (``model_error = "white"``, as ``docs/enkf.md`` says for
   identical twins). ``--smoother N``: also the ES-MDA smoother over the whole window
   (:func:`enkf.tissue.smooth.smooth_constant`, N updates) from the same prior and data.
4. **Filter on a fine truth** (``--fine``): the data from direct Monte Carlo (10^6
   photons) of the layered block and the heat simulation on the Monte Carlo's voxels, for
   the point sensor, with the config's model error (``structured``: data from another
   model) and, for comparison, the white floor; ``--fine-smoother``: the smoother on it too.
   With ``--kinds camera`` the camera's frames of the same run, the filter with the
   config's model error and the camera's (``--fine-camera-error``, default 0.04), its
   ratio to the bound that this error allows (section 2: the camera's model error added to
   the pixels' noise, ``ConfigSensor.with_error``). The fine truths are cached
   (``--cache-dir``, ``layered-fine/``).
   ``--grid``, ``--emulator-photons`` and ``--fine-photons`` change the filter's FEM, its
   emulator's photons and the fine truth's photons: how much of the fine truth's error is
   the coarse model's (``docs/layered.md``).

5. **What the model can say about the fine truth** (``--pseudo-true``): the filter's coarse
   model fitted by least squares to the noise-free fine-truth trace or frames (the "pseudo-true"
   optics an efficient estimator with this model converges to). Its distance from the
   truth is the model error's share of the error, which no filter setting removes: an
   estimator's RMS error is at least ``sqrt(bias^2 + CRB^2)``, so a bias above 0.83 CRB
   puts the 1.3 x CRB target out of reach on that truth.

    python validation/layered.py --seeds 20 --emulator --fine --smoother 8 --pseudo-true
"""

from __future__ import annotations

import argparse
import copy
import shlex
import tempfile
import time
from pathlib import Path

import numpy as np

from enkf.app.config import load_identify
from enkf.app.suite import load_script, validation_dir

HERE = Path(__file__).parent
CONFIG = HERE.parent / "examples" / "two_layer.toml"
#: the dermis's true optics: the prior's centre, and a point off it
TRUTHS = {"A (centre)": {"mua": 1.0, "mus": 100.0}, "B (off-centre)": {"mua": 1.6, "mus": 70.0}}
#: emulator test points (dermis mua, mus): off-grid inside, and the corners of the prior
POINTS = [(1.0, 100.0), (0.7, 150.0), (1.6, 60.0), (0.5, 50.0), (2.0, 200.0), (0.5, 200.0),
          (2.0, 50.0)]
DT, N_STEPS = 0.1, 150
#: the fine truth's heat steps (DT): Crank-Nicolson. Backward Euler (1) lags the
#: epidermis's fast rise: the camera's best fit of the filter's model moves by 2.8% in mus
#: between truths stepped by it at 0.1 s and at 0.05 s
FINE_THETA = 0.5


def camera(model_error_rel_std: float = 0.0):
    """The 16 x 16 camera over [-0.2, 0.2]^2 cm (pixel noise variance 0.01) with the model
    error ``model_error_rel_std`` (0: identical twins, the filter's model is the truth's)."""
    from enkf.tissue.image import ThermalImage

    return ThermalImage((-0.2, 0.2), (-0.2, 0.2), (16, 16), noise_var=0.01,
                        model_error_rel_std=model_error_rel_std)


def sensor_setup(cfg, absorption, kind: str, seed: int = 0, camera_error: float = 0.0,
                 **overrides):
    """The config's filter setup with its point sensor (``"sensor"``) or :func:`camera`
    and no point sensor (``"camera"``, its model error ``camera_error``); ``overrides``:
    other :class:`~enkf.tissue.TissueFilterSetup` settings."""
    cfg = copy.copy(cfg)
    cfg.setup_kw = {**cfg.setup_kw, **overrides}
    if kind == "camera":
        cfg.setup_kw["sensor_positions"] = np.zeros((0, 3))
        cfg.setup_kw["image"] = camera(camera_error)
    return cfg.setup(absorption, seed=seed)


def emulator_study(cfg, photons: int, ref_photons: int) -> list[str]:
    """Build times and load errors of the two build methods (section 1)."""
    from mcmatlab_py.emulator import AbsorptionEmulator, EmulatorSpec, table_point, table_row
    from mcmatlab_py.emulator.exact import direct_member
    from mcmatlab_py.emulator.white import white_column

    spec = EmulatorSpec.from_model(cfg.model, medium=cfg.medium, mesh_divisions=tuple(cfg.grid),
                                   **{**cfg.emulator_kw, "n_photons": photons})
    table_row(spec, np.zeros((spec.nx, spec.ny, spec.nz)))  # the voxel -> node operator
    tiny = EmulatorSpec(**{**{k: getattr(spec, k) for k in ("Lx", "Ly", "Lz", "g", "n",
                                                              "source_type", "radius")},
                           "nx": 4, "ny": 4, "nz": 2, "n_photons": 100})
    table_point(tiny, (0, 0))  # compile both kernels outside the timings
    white_column(tiny, 0)
    emus, seconds = {}, {}
    for method in ("white", "table"):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            emus[method] = AbsorptionEmulator.build(spec, cache_dir=tmp, progress=False,
                                                    method=method)
            seconds[method] = time.perf_counter() - t0
        print(f"build {method}: {seconds[method]:.1f} s", flush=True)
    ref_spec = EmulatorSpec(**{**{k: getattr(spec, k) for k in spec.__dataclass_fields__},
                               "n_photons": ref_photons})
    rows = []
    for i, (a, s) in enumerate(POINTS):
        ref = direct_member(ref_spec, 1000 + i, (a, s)).ravel()
        # one direct run with the photons the tables spend at this mus (another seed)
        one = direct_member(EmulatorSpec(**{**{k: getattr(spec, k)
                                               for k in spec.__dataclass_fields__},
                                            "n_photons": spec.photons_at(s)}), 2000 + i,
                            (a, s)).ravel()
        err = {m: float(np.linalg.norm(e(a, s).ravel() - ref) / np.linalg.norm(ref))
               for m, e in emus.items()}
        err["direct"] = float(np.linalg.norm(one - ref) / np.linalg.norm(ref))
        rows.append(f"| ({a:g}, {s:g}) | {100 * err['white']:.2f}% | {100 * err['table']:.2f}% "
                    f"| {100 * err['direct']:.2f}% |")
        print(rows[-1], flush=True)
    return [
        "## 1. The layered emulator: white against table", "",
        f"Table {spec.n_mua} x {spec.n_mus} over dermis mua {list(spec.mua_range)}, mus "
        f"{list(spec.mus_range)} cm^-1; Monte Carlo on {spec.nx} x {spec.ny} x {spec.nz} voxels "
        f"(two layers), nodal loads on the {' x '.join(map(str, spec.mesh_divisions))} mesh; "
        f"{photons} photons per point at mus = 100 (`n_photons`).", "",
        "| build from an empty cache | seconds |", "|---|---|",
        f"| white (one run per dermis mus, {spec.n_mus} runs) | {seconds['white']:.1f} |",
        f"| table (one direct run per point, {spec.n_mua * spec.n_mus} runs) | "
        f"{seconds['table']:.1f} |",
        f"| ratio | {seconds['table'] / seconds['white']:.1f}x |", "",
        f"Relative L2 error of the nodal loads against direct Monte Carlo of the layered model "
        f"({ref_photons} photons, its own seed per point); 'one direct run': a direct run with "
        "the photons the table spends per point, against the same reference (the Monte Carlo "
        "error at equal cost, the reference's own noise included).", "",
        "| dermis (mua, mus) | white | table | one direct run |", "|---|---|---|---|", *rows, ""]


def twin_data(sensor, truth: dict) -> np.ndarray:
    """(N_STEPS, p) the noise-free readings of the filter's own model at ``truth``."""
    theta = np.array([[truth[n] for n in sensor.setup.parameters.names]])
    return sensor.readings(theta)[:, :, 0]


def fine_data(cfg, truth: dict, photons: int = 10**6, seed: int = 4242) -> np.ndarray:
    """(N_STEPS, 1) the surface sensor of :func:`fine_truth`."""
    return fine_truth(cfg, truth, photons, seed)["sensor"]


def fine_truth(cfg, truth: dict, photons: int = 10**6, seed: int = 4242,
               cache_dir=None, theta: float = FINE_THETA) -> dict:
    """The surface sensor (``"sensor"``, (N_STEPS, 1)) and the frames of :func:`camera`
    (``"camera"``, (N_STEPS, 256), each pixel the mean of its 4 x 4 probes) from direct
    Monte Carlo (``photons``, ``seed``) and the heat simulation on the Monte Carlo's voxels,
    with the dermis at ``truth``; kept in ``cache_dir`` (default: the emulators' cache,
    ``layered-fine/``) under a key of the config file and these settings."""
    import hashlib
    import os

    from mcmatlab_py.emulator import default_cache_dir

    parts = (CONFIG.read_bytes(), cfg.medium, truth["mua"], truth["mus"], int(photons), seed,
             camera(), N_STEPS, DT)
    if theta != 1.0:  # the backward-Euler truths of before keep their keys
        parts = (*parts, theta)
    key = hashlib.sha256(repr(parts).encode()).hexdigest()[:20]
    path = Path(cache_dir or default_cache_dir()) / "layered-fine" / f"fine-{key}.npz"
    if path.exists():
        with np.load(path) as f:
            return {"sensor": f["sensor"], "camera": f["camera"]}
    out = _run_fine_truth(cfg, truth, photons, seed, theta)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
    np.savez(tmp, **out)
    os.replace(tmp, path)
    return out


def _run_fine_truth(cfg, truth: dict, photons: int, seed: int, theta: float = FINE_THETA
                    ) -> dict:
    model = copy.deepcopy(cfg.model)
    m = model.G.media[cfg.medium]
    m.mua, m.mus = truth["mua"], truth["mus"]
    model.MC.n_photons_requested = int(photons)
    model.MC.seed = seed
    model.HS.theta = theta
    points = np.asarray(cfg.setup_kw["sensor_positions"], float).reshape(-1, 3)
    probes = camera().sample_points()
    model.HS.temp_sensor_positions = [tuple(p) for p in np.vstack([points, probes])]
    model.MC.progress = model.HS.progress = False
    model.run_monte_carlo().simulate_heat_distribution()
    t, T = model.HS.sensor_times, model.HS.sensor_temps
    want = np.round(np.arange(1, N_STEPS + 1) * DT, 10)
    T = np.column_stack([np.interp(want, t, T[:, j]) for j in range(T.shape[1])])
    return {"sensor": T[:, :len(points)], "camera": camera().average(T[:, len(points):])}


def _over_seeds(cfg, emulator, kind: str, truth: dict, clean: np.ndarray, seeds, overrides,
                estimate, label: str = "") -> dict:
    """Final estimates over seeds (the noise and the estimator's seed): ``estimate(setup,
    times, data) -> (names, mean, sd, lo, hi, seconds, stopped)``."""
    times = np.round(np.arange(1, N_STEPS + 1) * DT, 10)
    out = {"err": [], "sd": [], "covered": [], "seconds": []}
    for seed in seeds:
        setup = sensor_setup(cfg, emulator, kind, seed=seed, **(overrides or {}))
        rng = np.random.default_rng(10_000 + seed)
        data = clean + np.sqrt(0.01) * rng.standard_normal(clean.shape)
        names, mean, sd, lo, hi, seconds, stopped = estimate(setup, times, data)
        true = np.array([truth[n] for n in names])
        out["err"].append(np.log(mean / true))
        out["sd"].append(sd / mean)
        out["covered"].append((lo <= true) & (true <= hi))
        out["seconds"].append(seconds)
        print(f"  {kind}{label} seed {seed}: mean {np.round(mean, 4)} sd {np.round(sd, 4)} "
              f"covered {out['covered'][-1]} {seconds:.1f} s"
              + (f" stopped: {stopped}" if stopped else ""), flush=True)
    return {k: np.array(v) for k, v in out.items()}


def run_seeds(cfg, emulator, kind: str, truth: dict, clean: np.ndarray, seeds,
              overrides=None) -> dict:
    """Final estimates of the filter over seeds (noise and filter seed)."""
    from enkf.tissue import identify

    def estimate(setup, times, data):
        t0 = time.perf_counter()
        est = identify(setup, times, data)
        seconds = time.perf_counter() - t0
        n = len(setup.parameters.names)
        lo = np.array([est.param_band(i)[0][-1] for i in range(n)])
        hi = np.array([est.param_band(i)[1][-1] for i in range(n)])
        return (setup.parameters.names, est.param_mean[-1], est.param_std[-1], lo, hi, seconds,
                est.diverged)

    return _over_seeds(cfg, emulator, kind, truth, clean, seeds, overrides, estimate)


def least_squares_seeds(cfg, emulator, kind: str, truth: dict, clean: np.ndarray, seeds,
                        overrides=None) -> dict:
    """As :func:`run_seeds`, the least-squares fit of the same data with the filter's own
    model (no prior), its band +-2 sd of the Gauss-Newton covariance at the fit: what an
    efficient estimator does with exactly these noise draws."""
    ident = load_script(validation_dir(), "identifiability")

    def estimate(setup, times, data):
        t0 = time.perf_counter()
        sensor = ident.ConfigSensor(setup, DT, N_STEPS)
        sd_noise = np.sqrt(np.broadcast_to(np.asarray(sensor.noise_var, float),
                                           (data.shape[1],)))
        fit = _fit(sensor, data, np.log([truth[n] for n in setup.parameters.names]),
                   sd_noise, diff_step=1e-4, xtol=1e-12, ftol=1e-12, x_scale=1e-3)
        sd = np.sqrt(np.diag(np.linalg.inv(fit.jac.T @ fit.jac)))
        mean = np.exp(fit.x)
        return (setup.parameters.names, mean, sd * mean, np.exp(fit.x - 2 * sd),
                np.exp(fit.x + 2 * sd), time.perf_counter() - t0, None)

    return _over_seeds(cfg, emulator, kind, truth, clean, seeds, overrides, estimate,
                       " least squares")


def smooth_seeds(cfg, emulator, kind: str, truth: dict, clean: np.ndarray, seeds, n_iter: int,
                 overrides=None, importance: int = 0, mode_search: int = 0) -> dict:
    """As :func:`run_seeds`, the estimates of the ES-MDA smoother over the whole window
    (:func:`enkf.tissue.smooth.smooth_constant`) from the same data; with ``importance``
    samples of adaptive importance sampling after it (the posterior itself)."""
    from enkf.tissue.smooth import smooth_constant

    def estimate(setup, times, data):
        est = smooth_constant(setup, times, data, n_iter=n_iter, importance=importance,
                              mode_search=mode_search)
        bands = np.array([est.band(i) for i in range(len(est.names))])
        return est.names, est.mean, est.std, bands[:, 0], bands[:, 1], est.wall_s, None

    return _over_seeds(cfg, emulator, kind, truth, clean, seeds, overrides, estimate,
                       " ES-MDA" + (f" + AMIS ({importance})" if importance else "")
                       + (f" + modes ({mode_search})" if mode_search else ""))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--emulator", action="store_true", help="section 1 (build both ways)")
    ap.add_argument("--photons", type=int, default=100_000, help="emulator photons (section 1)")
    ap.add_argument("--ref-photons", type=int, default=1_000_000)
    ap.add_argument("--fine", action="store_true",
                    help="section 4 (fine truth: the point sensor, and the camera with its "
                         "model error --fine-camera-error)")
    ap.add_argument("--truths", default=",".join(TRUTHS), help="comma-separated labels")
    ap.add_argument("--kinds", default="sensor,camera")
    ap.add_argument("--cache-dir", default=None)
    ap.add_argument("--model-noise-std", type=float, default=None,
                    help="deg C per step (default: the config's)")
    ap.add_argument("--n-members", type=int, default=None)
    ap.add_argument("--mda", type=int, default=None)
    ap.add_argument("--restarts", default=None, metavar="WHEN",
                    help="the filter restarts from the smoother (smoother_restarts): "
                         "'laser_off' or comma-separated times in s")
    ap.add_argument("--restart-discrepancy", type=float, default=0.0,
                    help="the restarts' smoother's model discrepancy (relative sd; a config's "
                         "default for point sensors: 0.01)")
    ap.add_argument("--smoother", type=int, default=0, metavar="N_ITER",
                    help="also the ES-MDA smoother with N_ITER updates on the twins (section 3)")
    ap.add_argument("--importance", type=int, default=0, metavar="M",
                    help="the smoother followed by M samples of adaptive importance sampling")
    ap.add_argument("--no-filter", action="store_true", help="the smoother's rows only")
    ap.add_argument("--first-seed", type=int, default=0,
                    help="seeds first_seed .. first_seed + seeds - 1")
    ap.add_argument("--least-squares", action="store_true",
                    help="also the least-squares fit of each twin's data with the filter's "
                         "model (the efficient estimator on the same noise draws)")
    ap.add_argument("--no-twin", action="store_true",
                    help="no twin rows (the fine truth's only, with --fine)")
    ap.add_argument("--pseudo-true", action="store_true",
                    help="section 5 (the coarse model's best fit to the fine truth)")
    ap.add_argument("--grid", type=int, nargs=3, default=None, metavar=("NX", "NY", "NZ"),
                    help="the filter's FEM divisions (default: the config's 20 20 10)")
    ap.add_argument("--emulator-photons", type=int, default=None,
                    help="the filter's emulator photons at mus = 100 (default: the config's)")
    ap.add_argument("--emulator-table", type=float, nargs=6, default=None,
                    metavar=("MUA_LO", "MUA_HI", "N_MUA", "MUS_LO", "MUS_HI", "N_MUS"),
                    help="the emulator's table (default: the config's)")
    ap.add_argument("--heat-operator", choices=["kronecker", "p1"], default=None,
                    help="the filter's heat operator (default: the config's, kronecker with "
                         "the averaged mass; p1: the fine truth's, with the lumped mass)")
    ap.add_argument("--fine-photons", type=int, default=10**6,
                    help="photons of the fine truth's direct Monte Carlo (sections 4-5)")
    ap.add_argument("--emulator-seed", type=int, default=None,
                    help="the emulator's Monte Carlo seed (default: the config's)")
    ap.add_argument("--fine-seed", type=int, default=4242,
                    help="the fine truth's Monte Carlo seed")
    ap.add_argument("--fine-model-error", nargs="+", default=None,
                    choices=["structured", "white"],
                    help="the filter's model error on the fine truth (default: the config's, "
                         "then white)")
    ap.add_argument("--fine-camera-error", type=float, default=0.04,
                    help="the camera's model error on the fine truth (model_error_rel_std; "
                         "default: ThermalImage's, 0.04)")
    ap.add_argument("--fine-smoother", action="store_true",
                    help="with --fine and --smoother: the smoother on the fine truth too")
    ap.add_argument("--theta", type=float, default=None,
                    help="the filter's time scheme (TissueFilterSetup.theta; default the "
                         "config's, Crank-Nicolson; 1: backward Euler)")
    ap.add_argument("--fine-theta", type=float, default=FINE_THETA,
                    help="the fine truth's time scheme (1: backward Euler)")
    ap.add_argument("--out", default=str(HERE / "reports" / "layered.md"))
    args = ap.parse_args(argv)
    ident = load_script(validation_dir(), "identifiability")
    cfg = load_identify(CONFIG)
    cfg = model_config(cfg, args.grid, args.emulator_photons, args.emulator_seed,
                       args.emulator_table)
    if args.theta is not None:
        cfg.setup_kw = {**cfg.setup_kw, "theta": args.theta}
    if args.heat_operator is not None:
        cfg.setup_kw = {**cfg.setup_kw, "heat_operator": args.heat_operator,
                        "heat_mass": "lumped" if args.heat_operator == "p1" else "averaged"}
    cmd = "python validation/layered.py " + shlex.join(argv if argv is not None else
                                                       __import__("sys").argv[1:])
    lines = ["# Identification under a known epidermis (two layers)", "",
             f"Command: `{cmd.strip()}`; config `examples/two_layer.toml` (epidermis 80 um: "
             "mua 5, mus 150 cm^-1, g 0.8; dermis estimated, prior 0.5-2 x (1, 100) cm^-1; "
             "emulator `method = \"white\"`" + "".join(f"; {v}" for v in _changes(args, cfg))
             + ").", ""]
    if args.emulator:
        lines += emulator_study(cfg, args.photons, args.ref_photons)
    t0 = time.perf_counter()
    emulator = cfg.emulator(cache_dir=args.cache_dir, progress=False)
    print(f"emulator ({cfg.emulator_method}) ready in {time.perf_counter() - t0:.1f} s",
          flush=True)
    kinds = [k for k in args.kinds.split(",") if k]  # --kinds "": the emulator section only
    truths = {k: TRUTHS[k] for k in args.truths.split(",")}
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    restarts = None if args.restarts is None else (
        args.restarts if args.restarts == "laser_off"
        else tuple(float(v) for v in args.restarts.split(",")))
    overrides = {k: v for k, v in (("model_noise_std", args.model_noise_std),
                                   ("n_members", args.n_members), ("mda", args.mda),
                                   ("smoother_restarts", restarts))
                 if v is not None}
    if restarts is not None:
        overrides["smoother_restart_discrepancy"] = args.restart_discrepancy
    tag = "" if restarts is None else f", restarts ({args.restarts}" + (
        f", discrepancy {args.restart_discrepancy:g})" if args.restart_discrepancy else ")")
    crb_rows, filt_rows, pseudo_rows = [], [], []
    fines = {}  # one fine truth per truth, for sections 4 and 5

    def fine_of(truth):
        key = (truth["mua"], truth["mus"])
        if key not in fines:
            fines[key] = fine_truth(cfg, truth, args.fine_photons, args.fine_seed,
                                    args.cache_dir, args.fine_theta)
        return fines[key]

    for kind in kinds:
        sensor = ident.ConfigSensor(sensor_setup(cfg, emulator, kind), DT, N_STEPS)
        for label, truth in truths.items():
            cov = ident.config_bound(sensor, truth)
            crb = np.sqrt(np.diag(cov))
            crb_rows.append(_crb_row(kind, label, truth, cov))
            print(crb_rows[-1], flush=True)
            fine_here = args.fine and label == next(iter(truths))
            if fine_here and kind == "camera":
                # the bound that the filter's error model allows on the fine truth: the
                # camera's model error added to the pixels' noise
                err_sensor = ident.ConfigSensor(
                    sensor_setup(cfg, emulator, kind, camera_error=args.fine_camera_error),
                    DT, N_STEPS).with_error(truth)
                err_cov = ident.config_bound(err_sensor, truth)
                err_crb = np.sqrt(np.diag(err_cov))
                crb_rows.append(_crb_row(f"camera, model error {args.fine_camera_error:g}",
                                         label, truth, err_cov))
                print(crb_rows[-1], flush=True)
            if args.pseudo_true and (kind == "sensor" or fine_here):
                pseudo_rows.append(_pseudo_row(f"{kind}, {label}", truth,
                                               pseudo_true(sensor, fine_of(truth)[kind], truth),
                                               crb))
                print(pseudo_rows[-1], flush=True)
            if args.pseudo_true and fine_here and kind == "camera":
                # the fit the camera's error model asks for (its covariance at the truth)
                pseudo_rows.append(_pseudo_row(
                    f"camera with model error {args.fine_camera_error:g}, {label}", truth,
                    pseudo_true(err_sensor, fine_of(truth)[kind], truth), crb))
                print(pseudo_rows[-1], flush=True)
            if not len(seeds):
                continue
            if not (args.no_filter or args.no_twin):
                res = run_seeds(cfg, emulator, kind, truth, twin_data(sensor, truth), seeds,
                                {"model_error": "white", **overrides})
                filt_rows.append(_filter_row(kind, "twin" + tag, label, truth, res, crb))
                print(filt_rows[-1], flush=True)
            if args.least_squares and not args.no_twin:
                res = least_squares_seeds(cfg, emulator, kind, truth, twin_data(sensor, truth),
                                          seeds, {"model_error": "white", **overrides})
                filt_rows.append(_filter_row(kind, "twin, least squares", label, truth, res,
                                             crb))
                print(filt_rows[-1], flush=True)
            if args.smoother and not args.no_twin:
                res = smooth_seeds(cfg, emulator, kind, truth, twin_data(sensor, truth), seeds,
                                   args.smoother, {"model_error": "white", **overrides},
                                   args.importance)
                name = f"twin, ES-MDA ({args.smoother})" + (
                    f" + AMIS ({args.importance})" if args.importance else "")
                filt_rows.append(_filter_row(kind, name, label, truth, res, crb))
                print(filt_rows[-1], flush=True)
            if fine_here and kind == "camera":
                for me in dict.fromkeys(args.fine_model_error or (
                        cfg.setup_kw.get("model_error", "white"),)):
                    res = run_seeds(cfg, emulator, kind, truth, fine_of(truth)[kind], seeds,
                                    {"model_error": me, "camera_error": args.fine_camera_error,
                                     **overrides})
                    filt_rows.append(_filter_row(
                        kind, f"fine, {me}, camera error {args.fine_camera_error:g}{tag} "
                        "(ratio: to its bound)", label, truth, res, err_crb))
                    print(filt_rows[-1], flush=True)
            if fine_here and kind == "sensor":
                fine = fine_of(truth)["sensor"]
                for me in dict.fromkeys(args.fine_model_error or (
                        cfg.setup_kw.get("model_error", "white"), "white")):
                    res = run_seeds(cfg, emulator, kind, truth, fine, seeds,
                                    {"model_error": me, **overrides})
                    filt_rows.append(_filter_row(kind, f"fine, {me}{tag}", label, truth, res,
                                                 crb))
                    print(filt_rows[-1], flush=True)
                if args.smoother and args.fine_smoother:
                    res = smooth_seeds(cfg, emulator, kind, truth, fine, seeds, args.smoother,
                                       {"model_error": "white", **overrides}, args.importance)
                    filt_rows.append(_filter_row(kind, f"fine, ES-MDA ({args.smoother})",
                                                 label, truth, res, crb))
                    print(filt_rows[-1], flush=True)
    if kinds:
        lines += [
            "## 2. What one sensor and a camera can determine (Cramér-Rao bounds)", "",
            "Lower bound on the relative sd (1 sd, log units) of any unbiased estimate of the "
            "dermis's mua and mus from 150 readings (noise variance 0.01 per sensor or pixel), "
            "the epidermis known, with the filter's own coarse model at the truth and the "
            "uniform prior 0.5-2 x nominal as a Gaussian of log-sd 0.38 "
            "(`validation/identifiability.py`, `ConfigSensor`, `config_bound`); rho: the "
            "correlation of the two errors.", "",
            "| observed | truth (mua, mus) | mua | mus | rho |", "|---|---|---|---|---|",
            *crb_rows, ""]
    if filt_rows:
        lines += [
            "## 3-4. The filter over seeds", "",
            f"Seeds {args.first_seed}-{args.first_seed + args.seeds - 1} (noise and filter "
            "seed); final estimates at t = 15 s. "
            "RMS error: root mean square of log(estimate / truth) over the seeds; ratio: that over "
            "the bound (target <= 1.3); coverage: seeds whose +-2 sd band (the ensemble's 2.3% "
            "and 97.7% quantiles) holds the truth (target >= 90%); sd: the filter's mean "
            "relative spread.", "",
            "| observed | truth | data | seeds | mua RMS error | ratio | mua coverage | mua sd "
            "| mus RMS error | ratio | mus coverage | mus sd | bias mua, mus | filter s/run |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|", *filt_rows, ""]
    if pseudo_rows:
        lines += [
            "## 5. What the filter's model can say about the fine truth (pseudo-true optics)",
            "", "The filter's coarse model (the emulator's layered loads on the "
            f"{_grid(cfg.grid)} FEM) fitted by least squares (weighed by the pixels' or the "
            "sensor's noise alone, or, 'with model error', by the camera's error covariance "
            "at the truth, frames independent, as the filter reads them) to the noise-free "
            "surface trace or frames "
            f"of the fine truth (direct Monte Carlo of {_photons(args.fine_photons)} photons "
            "and the heat simulation on the Monte "
            "Carlo's voxels; section 4). An estimator using this model converges to the fit, "
            "so its RMS error is at least sqrt(bias^2 + CRB^2) (bias: the fit's log error; "
            "CRB: section 2): the last columns are that floor over the CRB, against the "
            "target of 1.3.", "",
            "| truth | pseudo-true (mua, mus) | bias mua | bias mus | rms residual (deg C) "
            "| floor / CRB mua | floor / CRB mus |", "|---|---|---|---|---|---|---|",
            *pseudo_rows, ""]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


def model_config(cfg, grid=None, photons: int | None = None, seed: int | None = None,
                 table=None):
    """A copy of the config with the filter's FEM divisions, its emulator's photons, seed
    and table (``(mua_lo, mua_hi, n_mua, mus_lo, mus_hi, n_mus)``) replaced where given
    (None: the config's)."""
    cfg = copy.copy(cfg)
    if grid is not None:
        cfg.grid = tuple(grid)
    kw = {"n_photons": photons, "seed": seed}
    if table is not None:
        kw.update(mua_range=(table[0], table[1]), n_mua=int(table[2]),
                  mus_range=(table[3], table[4]), n_mus=int(table[5]))
    cfg.emulator_kw = {**cfg.emulator_kw, **{k: v for k, v in kw.items() if v is not None}}
    return cfg


def _changes(args, cfg) -> list[str]:
    """What the command line changed of the config's model and of the fine truth."""
    out = []
    if args.grid is not None:
        out.append(f"filter grid {_grid(cfg.grid)}")
    if args.emulator_photons is not None:
        out.append(f"emulator {args.emulator_photons:,} photons")
    if args.emulator_seed is not None:
        out.append(f"emulator seed {args.emulator_seed}")
    if args.theta is not None:
        out.append(f"filter heat steps theta = {args.theta:g}")
    if args.heat_operator is not None:
        out.append(f"filter heat operator {args.heat_operator}")
    if args.emulator_table is not None:
        t = args.emulator_table
        out.append(f"emulator table mua {t[0]:g}-{t[1]:g} ({t[2]:g} points), mus "
                   f"{t[3]:g}-{t[4]:g} ({t[5]:g} points)")
    if args.fine_photons != 10**6:
        out.append(f"fine truth {_photons(args.fine_photons)} photons")
    if args.fine_seed != 4242:
        out.append(f"fine truth seed {args.fine_seed}")
    if args.fine_theta != FINE_THETA:
        out.append(f"fine truth's heat steps theta = {args.fine_theta:g}")
    return out


def _grid(grid) -> str:
    return " x ".join(str(n) for n in grid)


def _photons(n: int) -> str:
    return "10^6" if n == 10**6 else f"{n:,}"


def _fit(sensor, data: np.ndarray, x0: np.ndarray, noise_sd, **options):
    """``scipy.optimize.least_squares`` of the log parameters: the readings of ``sensor``
    (:class:`ConfigSensor`) against ``data`` (N_STEPS, p), each whitened by ``noise_sd``,
    or each frame by ``sensor.factors`` where :meth:`ConfigSensor.with_error` set them."""
    from scipy.optimize import least_squares

    def residual(x):
        r = sensor.readings(np.exp(x)[None, :])[:, :, 0] - data
        if sensor.factors is not None:
            return sensor.whiten(r[:, :, None]).ravel()
        return (r / noise_sd).ravel()

    return least_squares(residual, x0, **options)


def pseudo_true(sensor, clean: np.ndarray, truth: dict) -> dict:
    """The coarse model's least-squares fit of (mua, mus) to the noise-free readings
    ``clean`` (N_STEPS, p), from the truth: {"mua", "mus", "rms"} (cm^-1, deg C; rms: of
    the readings' residual). The readings weigh as their noise alone, or as the camera's
    model error says where ``sensor`` has it (:meth:`ConfigSensor.with_error`)."""
    names = tuple(sensor.setup.parameters.names)
    fit = _fit(sensor, clean, np.log([truth[n] for n in names]), 0.1, diff_step=1e-3,
               xtol=1e-8, ftol=1e-10)
    out = dict(zip(names, np.exp(fit.x), strict=True))
    r = sensor.readings(np.exp(fit.x)[None, :])[:, :, 0] - clean
    out["rms"] = float(np.sqrt(np.mean(r ** 2)))
    return out


def pseudo_floor(fit: dict, truth: dict, crb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pseudo-true fit's log error (mua, mus) and the floor sqrt(bias^2 + CRB^2) / CRB
    that it puts under any estimator's RMS error with this model."""
    bias = np.array([np.log(fit[n] / truth[n]) for n in ("mua", "mus")])
    return bias, np.sqrt(bias ** 2 + crb ** 2) / crb


def _crb_row(kind, label, truth, cov) -> str:
    crb = np.sqrt(np.diag(cov))
    rho = cov[0, 1] / (crb[0] * crb[1])
    return (f"| {kind} | {label}: ({truth['mua']:g}, {truth['mus']:g}) | {100 * crb[0]:.2f}% "
            f"| {100 * crb[1]:.2f}% | {rho:+.2f} |")


def _pseudo_row(label, truth, fit, crb) -> str:
    bias, floor = pseudo_floor(fit, truth, crb)
    return (f"| {label}: ({truth['mua']:g}, {truth['mus']:g}) | ({fit['mua']:.4g}, "
            f"{fit['mus']:.4g}) | {100 * bias[0]:+.2f}% | {100 * bias[1]:+.2f}% | "
            f"{fit['rms']:.3f} | {floor[0]:.2f} | {floor[1]:.2f} |")


def _filter_row(kind, data, label, truth, res, crb) -> str:
    rms = np.sqrt(np.mean(res["err"] ** 2, axis=0))
    cov = res["covered"].mean(axis=0)
    sd = res["sd"].mean(axis=0)
    bias = res["err"].mean(axis=0)
    cells = []
    for i in range(2):
        cells += [f"{100 * rms[i]:.2f}%", f"{rms[i] / crb[i]:.2f}", f"{100 * cov[i]:.0f}%",
                  f"{100 * sd[i]:.2f}%"]
    return (f"| {kind} | {label.split()[0]} ({truth['mua']:g}, {truth['mus']:g}) | {data} | "
            f"{len(res['err'])} | " + " | ".join(cells)
            + f" | {100 * bias[0]:+.2f}%, {100 * bias[1]:+.2f}% | "
            f"{np.median(res['seconds']):.1f} |")


if __name__ == "__main__":
    main()
