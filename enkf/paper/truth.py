"""The truths of the paper's experiments: fine-grid Monte Carlo and FEM heat (cached),
the identical twin, and the noisy sensor."""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

import fem
from mcmatlab_py.emulator import default_cache_dir, load_cached, store_atomically, usable_cache_dir

from ..tissue.forward import TissueForwardModel
from ..tissue.parameters import PARAMETER_NAMES
from .filters import filter_setup
from .scenarios import camera_image, mua_ramp, mus_ramp, paper_model, train_optics, true_parameters

__all__ = ["Truth", "TruthConfig", "generate_truth", "noisy_sensor", "twin_truth"]

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
    #: the heat steps' time scheme (0.1 s steps): 0.5 Crank-Nicolson, within 0.06% of the
    #: peak of the solution converged in time (the pixels included) on the constant case;
    #: backward Euler (1) lags by 0.57%, as the filter's own model does with it
    #: (validation/reports/coarse_model_error.md)
    heat_theta: float = 0.5

    def key(self) -> str:
        d = asdict(self)
        d["scenario"] = self.scenario if self.scenario in ("constant", "pulse-train") \
            else "time-varying"
        d["version"] = 1
        if self.camera is None:
            del d["camera"]  # keys of truths without images stay as they were
        if self.heat_theta == 1.0:
            del d["heat_theta"]  # the backward-Euler truths of before keep their keys
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:20]


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
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = cache / f"truth-{cfg.key()}.npz"
    f = load_cached(path, "truth cache")
    if f is not None and {"times", "temps", "wall_seconds"} <= set(f):
        times, temps, wall = f["times"], f["temps"], float(f["wall_seconds"])
        return Truth(times, temps, true_parameters(cfg.scenario, times), wall, f.get("images"))
    path = usable_cache_dir(cache, path.name) / path.name  # checked before hours of work
    t0 = time.perf_counter()
    varying = cfg.scenario != "constant"
    model = paper_model(cfg.grid, cfg.n_photons_per_step if varying else cfg.n_photons_constant,
                        cfg.mc_seed, progress, scenario=cfg.scenario)
    model.HS.theta = cfg.heat_theta
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
    store_atomically(path, "truth cache", times=times, temps=temps, wall_seconds=wall, **extra)
    return Truth(times, temps, true_parameters(cfg.scenario, times), wall, images)


def twin_truth(scenario: str, emulator, like: Truth, coarse=(20, 20, 10),
               theta: float | None = None) -> Truth:
    """The identical-twin truth: the filter's own coarse model run at the true parameters.

    Data drawn from it carry no model error, so a filter that misses a target on them
    misses it for want of information (or by its own approximations), not because the
    coarse model differs from the fine one. ``like`` gives the times; ``theta`` the time
    scheme of the heat steps (None: the filter's default).
    """
    kw = {} if theta is None else {"theta": theta}
    setup = filter_setup(scenario, emulator, n_members=1, coarse=coarse, **kw)  # its laser
    model = TissueForwardModel(setup)
    probes = fem.probe_matrix(model.mesh, setup.sensors.tracked.T)
    times = like.times

    def step(T, t0, t1):
        p = true_parameters(scenario, np.array([0.5 * (t0 + t1)]))
        return model(T, np.array([[p[k][0] for k in PARAMETER_NAMES]]), t0, t1)

    _, temps = fem.march(step, np.full((1, model.mesh.p.shape[1]), setup.T_initial), times,
                         probes)
    return Truth(times, temps[:, 0, :], true_parameters(scenario, times), 0.0)


def noisy_sensor(truth: Truth, seed: int, variance: float = 0.01) -> np.ndarray:
    """The sensor series at (0, 0, 0): truth plus N(0, variance), for t > 0 (n - 1,)."""
    rng = np.random.default_rng([seed, 20230101])
    return truth.temps[1:, 0] + np.sqrt(variance) * rng.standard_normal(truth.temps.shape[0] - 1)
