"""The paper's synthetic experiments (Arnold & Fichera, section "Results"), end to end.

* The truth: the paper's block (0.5 x 0.5 x 0.25 cm, 100 x 100 x 50 voxels, standard
  tissue), a 1 mm top-hat beam of 0.5 W for 5 s then 10 s off, initial temperature
  0 deg C; Monte Carlo for the absorbed power (direct, at every change of the optical
  properties) and FEM heat on the fine mesh. Sensor at (0, 0, 0) read at 10 Hz with
  Gaussian noise of variance 0.01.
* The filter: N = 50 members on the coarse 20 x 20 x 10 model, absorbed power from the
  emulator. The analysis is the deterministic ETKF by default: on the paper's constant
  case it met every target on five seeds of five, the perturbed-observation EnKF of the
  paper (``method="enkf"``, ``--method enkf``) on three (validation/reports/paper_runs.md).

Where the paper is silent we do what MCmatlab does by default, and say so:
matched interfaces (``matchedInterfaces = true``: no Fresnel reflection at the
cuboid faces), boundary type 1 (photons escape through every face), insulating
heat boundaries (``heatBoundaryType = 0``), backward-Euler steps of 0.1 s (one per
sensor reading), and 10^7 photons for a constant-property map, 5 x 10^5 per step
while the properties ramp.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

SCENARIOS = ("constant", "time-varying", "all-params", "pulse-train")
TABLE = {"mua": 1.0, "mus": 100.0, "VHC": 3.76, "TC": 0.0037}  # Table 1 of the paper
TRACKED_DEPTHS = (0.0, 0.1, 0.2)  # cm, below the sensor


def mua_ramp(t):
    """The paper's time-varying absorption (eq. TV_absorption), cm^-1."""
    return 0.6 * t + 1.0 if t <= 5.0 else 4.0


def mus_ramp(t):
    """The paper's time-varying scattering (eq. TV_scattering), cm^-1."""
    return 80.0 * t + 100.0 if t <= 5.0 else 500.0


#: laser of each scenario: (P W, duration_on s, duration_off s, n_pulses). Beyond the paper,
#: "pulse-train" fires three 2 s pulses of 0.75 W, 3 s apart, and the tissue changes
#: while it is heated: mua and mus rise during each pulse and hold between pulses, so
#: each pulse meets different optics (see train_optics)
PULSES = {"constant": (0.5, 5.0, 10.0, 1), "time-varying": (0.5, 5.0, 10.0, 1),
          "all-params": (0.5, 5.0, 10.0, 1), "pulse-train": (0.75, 2.0, 3.0, 3)}


def heating_time(t: float, scenario: str = "pulse-train") -> float:
    """s of laser-on time before ``t``."""
    _, on, off, n = PULSES[scenario]
    period = on + off
    k = min(int(t // period), n)
    return float(k * on + (min(t - k * period, on) if k < n else 0.0))


def train_optics(t: float) -> tuple[float, float]:
    """(mua, mus) cm^-1 of the pulse-train scenario: +0.3 and +40 per second of heating."""
    h = heating_time(t)
    return 1.0 + 0.3 * h, 100.0 + 40.0 * h


def true_parameters(scenario: str, times: np.ndarray) -> dict[str, np.ndarray]:
    """Truth of every parameter at ``times`` (s)."""
    times = np.asarray(times, float)
    if scenario == "constant":
        mua = np.full(times.shape, TABLE["mua"])
        mus = np.full(times.shape, TABLE["mus"])
    elif scenario == "pulse-train":
        optics = np.array([train_optics(t) for t in times]).reshape(-1, 2)
        mua, mus = optics[:, 0], optics[:, 1]
    else:
        mua = np.array([mua_ramp(t) for t in times])
        mus = np.array([mus_ramp(t) for t in times])
    return {"mua": mua, "mus": mus, "VHC": np.full(times.shape, TABLE["VHC"]),
            "TC": np.full(times.shape, TABLE["TC"])}


def paper_model(grid=(100, 100, 50), n_photons: int = 10**7, seed: int = 1, progress=True,
                scenario: str = "constant"):
    """The paper's model (MCmatlab style) on a voxel grid ``(nx, ny, nz)``; the laser of
    ``scenario`` (:data:`PULSES`)."""
    from mcmatlab_py import Medium, Model

    model = Model()
    model.G.nx, model.G.ny, model.G.nz = grid
    model.G.Lx, model.G.Ly, model.G.Lz = 0.5, 0.5, 0.25
    model.G.media = [Medium("standard tissue", mua=TABLE["mua"], mus=TABLE["mus"], g=0.9,
                            n=1.3, VHC=TABLE["VHC"], TC=TABLE["TC"])]
    MC = model.MC
    MC.n_photons_requested = n_photons
    MC.seed = seed
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.progress = progress
    MC.light_source.source_type = "tophat"
    MC.light_source.radius = 0.1
    HS = model.HS
    HS.P, HS.duration_on, HS.duration_off, HS.n_pulses = PULSES[scenario]
    HS.dt = 0.1
    HS.T_initial = 0.0
    HS.heat_boundary_type = 0
    HS.temp_sensor_positions = [(0.0, 0.0, z) for z in TRACKED_DEPTHS]
    HS.progress = progress
    return model


@dataclass
class TruthConfig:
    """What determines the truth (hashed into its cache key)."""

    scenario: str = "constant"
    grid: tuple = (100, 100, 50)
    n_photons_constant: int = 10**7  #: photons of a constant-property map
    n_photons_per_step: int = 500_000  #: photons per step while the properties change
    mc_seed: int = 1
    #: also record a camera's images: (x0, x1, y0, y1, ny, nx, subsamples), see CAMERA
    camera: tuple | None = None

    def key(self) -> str:
        d = asdict(self)
        d["scenario"] = self.scenario if self.scenario in ("constant", "pulse-train") \
            else "time-varying"
        d["version"] = 1
        if self.camera is None:
            del d["camera"]  # keys of truths without images stay as they were
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:20]


#: the camera of the image experiments: 16 x 16 pixels of 250 um over the beam
CAMERA = (-0.2, 0.2, -0.2, 0.2, 16, 16, 4)


def camera_image(camera: tuple):
    """The :class:`enkf.image.ThermalImage` of a ``TruthConfig.camera`` tuple."""
    from .image import ThermalImage

    x0, x1, y0, y1, ny, nx, sub = camera
    return ThermalImage((x0, x1), (y0, y1), (int(ny), int(nx)), subsamples=int(sub))


@dataclass
class Truth:
    """Noise-free truth at 10 Hz: times (n,) s from 0; temps (n, 3) deg C at the depths;
    images (n, n_pixels) deg C when the truth was run with a camera."""

    times: np.ndarray
    temps: np.ndarray
    params: dict
    wall_seconds: float
    images: np.ndarray | None = None


def generate_truth(cfg: TruthConfig, *, cache_dir: str | Path | None = None,
                   progress: bool = True, client=None) -> Truth:
    """Run (or load from the cache) the fine-grid truth of a scenario.

    ``client``: a ``dask.distributed`` client for the Monte Carlo of a constant-property
    truth (photon batches as tasks; the same map as here).
    """
    import time

    from mcmatlab_py.emulator import default_cache_dir

    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = cache / f"truth-{cfg.key()}.npz"
    if path.exists():
        try:
            with np.load(path) as f:
                times, temps, wall = f["times"], f["temps"], float(f["wall_seconds"])
                images = f["images"] if "images" in f.files else None
            return Truth(times, temps, true_parameters(cfg.scenario, times), wall, images)
        except Exception:  # noqa: BLE001 - unreadable cache: recompute
            path.unlink(missing_ok=True)
    t0 = time.perf_counter()
    varying = cfg.scenario != "constant"
    model = paper_model(cfg.grid, cfg.n_photons_per_step if varying else cfg.n_photons_constant,
                        cfg.mc_seed, progress, scenario=cfg.scenario)
    if cfg.scenario == "pulse-train":
        model.HS.mua_t = lambda t: train_optics(t)[0]
        model.HS.mus_t = lambda t: train_optics(t)[1]
    elif varying:
        model.HS.mua_t = mua_ramp
        model.HS.mus_t = mus_ramp
    else:
        model.run_monte_carlo(client=client)
    n_tracked = len(model.HS.temp_sensor_positions)
    if cfg.camera is not None:
        pts = camera_image(cfg.camera).sample_points()
        model.HS.temp_sensor_positions = list(model.HS.temp_sensor_positions) + [
            tuple(p) for p in pts]
    model.simulate_heat_distribution()
    wall = time.perf_counter() - t0
    times = model.HS.sensor_times
    temps = model.HS.sensor_temps[:, :n_tracked]
    extra = {}
    images = None
    if cfg.camera is not None:
        images = camera_image(cfg.camera).average(model.HS.sensor_temps[:, n_tracked:])
        extra["images"] = images
    cache.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, times=times, temps=temps, wall_seconds=wall, **extra)
    tmp.replace(path)
    return Truth(times, temps, true_parameters(cfg.scenario, times), wall, images)


def twin_truth(scenario: str, emulator, like: Truth, coarse=(20, 20, 10)) -> Truth:
    """The identical-twin truth: the filter's own coarse model run at the true parameters.

    Data drawn from it carry no model error, so a filter that misses a target on them
    misses it for want of information (or by its own approximations), not because the
    coarse model differs from the fine one. ``like`` gives the times.
    """
    import fem

    from .tissue import TissueForwardModel

    setup = filter_setup(scenario, emulator, n_members=1, coarse=coarse)  # its laser
    model = TissueForwardModel(setup)
    probes = fem.probe_matrix(model.mesh, setup.tracked_positions.T)
    T = np.full((1, model.mesh.p.shape[1]), setup.T_initial)
    times = like.times
    temps = [probes @ T[0]]
    for t0, t1 in zip(times[:-1], times[1:], strict=True):
        p = true_parameters(scenario, np.array([0.5 * (t0 + t1)]))
        theta = np.array([[p[k][0] for k in ("mua", "mus", "VHC", "TC")]])
        T = model(T, theta, float(t0), float(t1))
        temps.append(probes @ T[0])
    return Truth(times, np.array(temps), true_parameters(scenario, times), 0.0)


def noisy_sensor(truth: Truth, seed: int, variance: float = 0.01) -> np.ndarray:
    """The sensor series at (0, 0, 0): truth plus N(0, variance), for t > 0 (n - 1,)."""
    rng = np.random.default_rng([seed, 20230101])
    return truth.temps[1:, 0] + np.sqrt(variance) * rng.standard_normal(truth.temps.shape[0] - 1)


def filter_setup(scenario: str, absorption, *, seed: int = 0, n_members: int = 50,
                 coarse=(20, 20, 10), method: str = "etkf", **overrides):
    """The filter of a scenario: the coarse model, the paper's priors, our C and E."""
    import fem
    from mcmatlab_py.heat import HeatSimulation

    from .tissue import TissueFilterSetup

    P, on, off, n = PULSES[scenario]
    HS = HeatSimulation(P=P, duration_on=on, duration_off=off, n_pulses=n, dt=0.1)
    estimate = ("mua", "mus", "VHC", "TC") if scenario == "all-params" else ("mua", "mus")
    # constant: parameters believed fixed (small walk). time-varying: they may drift; the
    # paper's ramp moves log mua by up to 0.06 and log mus by up to 0.08 per step, faster
    # than any walk that still averages the noise. On identical-twin data (no model error,
    # so the choice is not tuned to the fine truth) [0.03, 0.10] followed both best: mua
    # RMSE <= 0.18 and mus within 10% at t = 15 s on 4 seeds of 5, against 2 of 5 for
    # [0.03, 0.06] (which let mus lag during the pulse and overshoot after it) and 3 of 5
    # for [0.04, 0.12] (validation/reports/paper_runs.md).
    rw = 0.002 if scenario == "constant" else (
        [0.05, 0.10, 0.01, 0.01] if scenario == "all-params" else [0.03, 0.10])
    if scenario == "all-params":
        # with VHC and TC unknown too, a lagging mua is made up for by a lower TC and a
        # higher VHC (heat kept near the surface): a faster walk on mua (0.05) removes
        # most of the lag. The first reading after the pulse then moves mus by a lot in
        # one linear step (all five seeds stopped there, mean mus beyond 20 x nominal);
        # three smaller steps (one-step ES-MDA, FilterConfig.mda) let every seed through
        # (four did as well, three keeps every step below 100 ms on 2 busy cores).
        # Chosen over seeds 0-4 (validation/reports/paper_runs.md, fine truth and twin).
        overrides.setdefault("mda", 3)
    overrides.setdefault("random_walk_std", rw)
    # optical properties change by heating: when they may drift, hold them still while the
    # laser is off (they no longer act on the forecast then, and a walk only lets them wander)
    overrides.setdefault("random_walk_when_off", 1.0 if scenario == "constant" else 0.0)
    overrides.setdefault("sensor_positions", np.zeros((1, 3)))
    return TissueFilterSetup(
        grid=fem.BoxGrid(*coarse, 0.5, 0.5, 0.25), absorption=absorption,
        power=HS.laser_power, nominal=dict(TABLE), estimate=estimate, sensor_noise_var=0.01,
        tracked_positions=np.array([[0.0, 0.0, z] for z in TRACKED_DEPTHS]),
        T_initial=0.0, n_members=n_members, seed=seed, method=method, **overrides)


def emulator_for(coarse=(20, 20, 10), n_photons: int = 250_000, *, progress=True,
                 cache_dir=None, mc_grid=(100, 100, 50), client=None, **kw):
    """The filter's absorption emulator for the paper's block (cached).

    The Monte Carlo of each table point runs on ``mc_grid`` (the truth's voxels) and
    its absorbed power is integrated exactly against the P1 basis of the filter's
    ``coarse`` mesh: the table holds nodal loads. Averaging NA over 20 x 20 x 10 voxels
    first would smear the steep absorption near the surface and bias the surface
    temperature low (-1.6% at the end of the pulse against -0.8%, measured).
    """
    from mcmatlab_py.emulator import AbsorptionEmulator, EmulatorSpec

    spec = EmulatorSpec.from_model(paper_model(mc_grid, progress=False), n_photons=n_photons,
                                   mesh_divisions=tuple(coarse), **kw)
    return AbsorptionEmulator.build(spec, cache_dir=cache_dir, progress=progress,
                                    out_of_range="clamp", client=client)


@dataclass
class PaperRun:
    """One experiment: the truth, the data, the filter's estimates and the summary."""

    scenario: str
    truth: Truth
    data: np.ndarray
    estimates: object
    summary: dict


def run_experiment(scenario: str, seed: int = 0, *, n_members: int = 50, method: str = "etkf",
                   truth_config: TruthConfig | None = None, emulator_photons: int = 250_000,
                   emulator_table: int = 12, exact: bool = False, cache_dir=None,
                   progress: bool = True, twin: bool = False, client=None,
                   **overrides) -> PaperRun:
    """Truth (cached), noisy data (``seed``), and the filter (``seed``) for one scenario.

    ``twin=True`` replaces the fine-grid truth by the filter's own coarse model at the
    true parameters (:func:`twin_truth`): the identical-twin experiment, free of model
    error. ``client`` (a ``dask.distributed`` client) spreads the emulator table, the
    constant truth's Monte Carlo and the exact mode's members over a cluster.
    ``overrides`` go to :class:`~enkf.tissue.TissueFilterSetup` (e.g. ``model_noise_std``).
    """
    import time

    from mcmatlab_py._progress import Progress

    from .tissue import identify

    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {SCENARIOS}, got {scenario!r}")
    t0 = time.perf_counter()
    tcfg = truth_config or TruthConfig(scenario=scenario)
    tcfg.scenario = scenario
    truth = generate_truth(tcfg, cache_dir=cache_dir, progress=progress, client=client)
    emu = emulator_for(n_photons=emulator_photons, progress=progress, cache_dir=cache_dir,
                       mc_grid=tcfg.grid, n_mua=emulator_table, n_mus=emulator_table,
                       client=client)
    if twin:
        truth = twin_truth(scenario, emu, truth)
    data = noisy_sensor(truth, seed)
    absorption = emu
    if exact:
        from mcmatlab_py.emulator import DirectMonteCarloAbsorption

        absorption = DirectMonteCarloAbsorption(emu.spec, client=client)
    setup = filter_setup(scenario, absorption, seed=seed, n_members=n_members, method=method,
                         **overrides)
    bar = Progress(len(truth.times) - 1, "filter", enabled=progress)
    est = identify(setup, truth.times[1:], data[:, None], callback=lambda r: bar.update(r.step))
    bar.close()
    summary = summarize(scenario, est, truth)
    summary["truth"] = {"grid": list(tcfg.grid), "mc_seed": tcfg.mc_seed,
                        "wall_seconds_when_computed": truth.wall_seconds,
                        "identical_twin": bool(twin)}
    summary["emulator"] = {"n_photons_per_point_at_mus_100": emu.spec.n_photons,
                           "table": [emu.spec.n_mua, emu.spec.n_mus],
                           "build_seconds": emu.build_seconds, "exact_mode": bool(exact)}
    summary["seed"] = seed
    summary["wall_seconds"] = time.perf_counter() - t0
    return PaperRun(scenario, truth, data, est, summary)


def write_run(run: PaperRun, out_dir: Path) -> None:
    """estimates.csv, truth.csv, summary.json and figures/ of a run into ``out_dir``."""
    from .rundir import write_json

    out_dir = Path(out_dir)
    (out_dir / "figures").mkdir(exist_ok=True)
    truth, data = run.truth, run.data
    write_estimates_csv(out_dir / "estimates.csv", run.estimates, truth, data)
    tp = true_parameters(run.scenario, truth.times)
    np.savetxt(out_dir / "truth.csv", np.column_stack(
        [truth.times, truth.temps, np.r_[np.nan, data], *[tp[k] for k in TABLE]]),
        delimiter=",", comments="", fmt="%.8g",
        header="time_s,T_z0.0,T_z0.1,T_z0.2,sensor_data,mua,mus,VHC,TC")
    write_json(out_dir / "summary.json", run.summary)
    plot_results(out_dir / "figures" / "estimates.png", run.scenario, run.estimates, truth, data)
    plot_data(out_dir / "figures" / "data.png", run.scenario, truth, data)


def summarize(scenario: str, est, truth: Truth) -> dict:
    """The ``summary.json`` of a run: final errors, RMSE and coverage of the +-2 sd band."""
    # a filter stopped by its health check has NaN statistics at the failing step: the
    # metrics cover the steps before it, and "diverged" says when and why
    ok = np.all(np.isfinite(est.param_mean), axis=1) & np.all(np.isfinite(est.tracked_mean),
                                                               axis=1)
    k = int(np.argmin(ok)) if not ok.all() else len(est.times)
    params = {}
    tp = true_parameters(scenario, est.times[:k])
    for i, name in enumerate(est.names):
        mean, sd, tru = est.param_mean[:k, i], est.param_std[:k, i], tp[name]
        params[name] = {
            "truth_final": float(tru[-1]), "estimate_final": float(mean[-1]),
            "std_final": float(sd[-1]),
            "relative_error_final": float(abs(mean[-1] - tru[-1]) / tru[-1]),
            "rmse": float(np.sqrt(np.mean((mean[1:] - tru[1:]) ** 2))),
            "coverage_2sd": float(np.mean(np.abs(mean[1:] - tru[1:]) <= 2 * sd[1:])),
        }
    temps = {}
    for j, z in enumerate(TRACKED_DEPTHS):
        mean, sd = est.tracked_mean[1:k, j], est.tracked_std[1:k, j]
        tru = truth.temps[1:k, j]
        temps[f"z={z:.1f}"] = {
            "rmse": float(np.sqrt(np.mean((mean - tru) ** 2))),
            "coverage_2sd": float(np.mean(np.abs(mean - tru) <= 2 * sd)),
            "truth_max": float(tru.max()),
        }
    lat = est.step_latency_s
    return {
        "scenario": scenario, "parameters": params, "temperatures": temps,
        "timing": {"filter_wall_s": est.filter_wall_s,
                   "step_latency_median_s": float(np.median(lat)),
                   "step_latency_max_s": float(np.max(lat)), "steps": int(len(lat)),
                   "ensemble_size": int(est.result.state_ensemble.shape[0])
                   if est.result is not None else None},
        "diverged": est.diverged,
        "final_time": float(est.times[k - 1]),
    }


def write_estimates_csv(path, est, truth: Truth | None = None, data=None) -> None:
    """``estimates.csv``: time; mean and std of each parameter and tracked temperature."""
    cols = ["time_s"]
    arrays = [est.times]
    for i, name in enumerate(est.names):
        cols += [f"{name}_mean", f"{name}_std"]
        arrays += [est.param_mean[:, i], est.param_std[:, i]]
    for j, pos in enumerate(est.tracked_positions):
        tag = f"T_z{pos[2]:.2f}"
        cols += [f"{tag}_mean", f"{tag}_std"]
        arrays += [est.tracked_mean[:, j], est.tracked_std[:, j]]
    if data is not None:
        cols.append("sensor_data")
        arrays.append(np.r_[np.nan, data][: len(est.times)])
    table = np.column_stack(arrays)
    np.savetxt(path, table, delimiter=",", header=",".join(cols), comments="", fmt="%.8g")


def plot_results(path, scenario: str, est, truth: Truth, data: np.ndarray) -> None:
    """The paper's figure: temperature tracks (top) and parameter tracks (bottom)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = est.times
    n_par = len(est.names)
    fig, axes = plt.subplots(2, max(3, n_par), figsize=(4.2 * max(3, n_par), 7.5),
                             constrained_layout=True)
    tp = true_parameters(scenario, t)
    for j, z in enumerate(TRACKED_DEPTHS):
        ax = axes[0, j]
        m, s = est.tracked_mean[:, j], est.tracked_std[:, j]
        _shade_pulses(ax, scenario)
        if j == 0:
            ax.plot(truth.times[1:len(data) + 1], data, "k.", ms=2.5, label="sensor data")
        ax.plot(truth.times[: len(t)], truth.temps[: len(t), j], "k--", lw=1.2, label="truth")
        ax.plot(t, m, "r-", lw=1.4, label="EnKF mean")
        ax.plot(t, m + 2 * s, "r--", lw=0.8, label="$\\pm 2$ sd")
        ax.plot(t, m - 2 * s, "r--", lw=0.8)
        ax.set(title=f"temperature at z = {z:g} cm", xlabel="time [s]", ylabel="T [$^\\circ$C]")
        if j == 0:
            ax.legend(fontsize=8)
    units = {"mua": "cm$^{-1}$", "mus": "cm$^{-1}$", "VHC": "J cm$^{-3}$ K$^{-1}$",
             "TC": "W cm$^{-1}$ K$^{-1}$"}
    labels = {"mua": "$\\mu_a$", "mus": "$\\mu_s$", "VHC": "$c_v$", "TC": "$k$"}
    for i, name in enumerate(est.names):
        ax = axes[1, i]
        m, s = est.param_mean[:, i], est.param_std[:, i]
        _shade_pulses(ax, scenario)
        ax.plot(t, tp[name], "k--", lw=1.2)
        ax.plot(t, m, "r-", lw=1.4)
        ax.plot(t, m + 2 * s, "r--", lw=0.8)
        ax.plot(t, m - 2 * s, "r--", lw=0.8)
        ax.set(title=labels[name], xlabel="time [s]", ylabel=f"{labels[name]} [{units[name]}]")
    for i in range(n_par, axes.shape[1]):
        axes[1, i].axis("off")
    fig.suptitle(f"EnKF, scenario '{scenario}'")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _shade_pulses(ax, scenario: str) -> None:
    """Grey bands where the laser of ``scenario`` is on."""
    _, on, off, n = PULSES.get(scenario, PULSES["constant"])
    for i in range(n):
        ax.axvspan(i * (on + off), i * (on + off) + on, color="0.88", lw=0)


def plot_data(path, scenario: str, truth: Truth, data: np.ndarray) -> None:
    """The paper's data figure: the sensor series (left) and the true parameters (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    for ax in (a, b):
        _shade_pulses(ax, scenario)
    a.plot(truth.times[1:], data, "k.", ms=3)
    a.set(xlabel="time [s]", ylabel="T [$^\\circ$C]", title="sensor data at (0, 0, 0)")
    tp = true_parameters(scenario, truth.times)
    b.plot(truth.times, tp["mua"], "b-", label="$\\mu_a$ [cm$^{-1}$]")
    b2 = b.twinx()
    b2.plot(truth.times, tp["mus"], "g-", label="$\\mu_s$ [cm$^{-1}$]")
    b.set(xlabel="time [s]", ylabel="$\\mu_a$ [cm$^{-1}$]", title="true optical properties")
    b2.set_ylabel("$\\mu_s$ [cm$^{-1}$]")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _sensitivity_na(grid, n_photons: int, coefficients: tuple[float, float]) -> np.ndarray:
    """NA of one sensitivity case (a task body: the same seed on any worker)."""
    m = paper_model(grid, n_photons=n_photons, progress=False)
    m.G.media[0].mua, m.G.media[0].mus = coefficients
    return m.run_monte_carlo().MC.NA


def sensitivity_study(grid=(100, 100, 50), n_photons: int = 10**6, *, progress=True,
                      mua_values=(1.0, 2.0, 3.0, 4.0, 5.0),
                      mus_values=(100.0, 200.0, 300.0, 400.0, 500.0), client=None) -> dict:
    """The paper's sensitivity study (its Fig. "sens"): sensor temperature against mua and mus.

    One Monte Carlo per case on ``grid`` (mus fixed at 100 while mua varies, mua at 1
    while mus varies; one task per case on ``client``, a ``dask.distributed`` client, when
    given), then all cases stepped together as one batch of heat fields.

    Returns ``{"times": (n,), "mua": {value: (n,)}, "mus": {value: (n,)}}`` (deg C).
    """
    import fem

    base = paper_model(grid, n_photons=n_photons, progress=False)
    HS = base.HS
    cases = [("mua", v, v, TABLE["mus"]) for v in mua_values]
    cases += [("mus", v, TABLE["mua"], v) for v in mus_values]
    g = fem.BoxGrid(*grid, 0.5, 0.5, 0.25)
    mesh = g.mesh()
    L = fem.voxel_load_matrix(mesh, g)
    import functools

    from mcmatlab_py.distributed import run_tasks

    maps = run_tasks(functools.partial(_sensitivity_na, tuple(grid), n_photons),
                     [(mua, mus) for _, _, mua, mus in cases], client=client,
                     progress=progress, label="sensitivity: Monte Carlo")
    loads = np.array([L @ na.ravel() for na in maps])
    stepper = fem.HeatStepper(mesh, TABLE["VHC"], TABLE["TC"], HS.dt)
    probe = fem.probe_matrix(mesh, np.zeros((3, 1)))
    T = np.zeros((len(cases), mesh.p.shape[1]))
    times = HS.step_times()
    out = [np.zeros(len(cases))]
    for t in times:
        power = HS.laser_power(t - 0.5 * HS.dt)
        T = stepper.step(T, power * loads if power else None)
        out.append((probe @ T.T)[0])
    out = np.array(out)
    res = {"times": np.r_[0.0, times], "mua": {}, "mus": {}}
    for i, (which, v, _, _) in enumerate(cases):
        res[which][v] = out[:, i]
    return res


def plot_sensitivity(path, res: dict) -> None:
    """Sensor temperature for each mua (left) and each mus (right), pulse shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True, sharey=True)
    for ax, which, label in ((axes[0], "mua", "$\\mu_a$"), (axes[1], "mus", "$\\mu_s$")):
        ax.axvspan(0, 5, color="0.88", lw=0)
        for v, series in res[which].items():
            ax.plot(res["times"], series, label=f"{label} = {v:g} cm$^{{-1}}$")
        ax.set(xlabel="time [s]", title=f"sensitivity to {label}")
        ax.legend(fontsize=8)
    axes[0].set_ylabel("T at (0, 0, 0) [$^\\circ$C]")
    fig.savefig(path, dpi=110)
    plt.close(fig)
