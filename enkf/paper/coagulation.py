r"""Beyond the paper: tissue whose optics follow its thermal damage (issue #21).

The scenario is the hot one of ``validation/risk_calibration.py``: the paper's block at
body temperature (37 deg C) under a 1 mm top-hat beam of 1.0 W (1.5 W there: the
coagulated surface scatters more light back into the first 100 um and passes 110 deg C,
where water would boil; 1.2 W still gave 107 deg C on the fine grid), so that the
surface passes 60 deg C within about 2 s and a lens of tissue coagulates (MCmatlab's
Arrhenius E and A). Two
lasers: one 5 s pulse then 10 s off (``"coagulation"``), and three 2 s pulses 3 s apart
(``"coagulation-train"``).

**The damage truth** (:func:`damage_truth`): the optics of every voxel follow its own
fractional damage :math:`FD = 1 - e^{-\Omega}`, ``mua = 1 + 0.5 FD``, ``mus = 100 + 200 FD``
cm^-1 (native Table 1 tissue; coagulated 1.5 and 300 cm^-1), as MCmatlab's thermally
induced scattering (its Example 15): the medium is a function of FD split into
``n_bins`` sub-media, and every ``recalc_every`` s of the heat simulation the media are
re-evaluated on the voxels' damage and the Monte Carlo is re-run on them
(:class:`mcmatlab_py.frt.MediaCoupling`). Monte Carlo on 100 x 100 x 50 voxels, FEM
heat on the fine mesh; the temperature is read at every step at the nodes of the
filter's 20 x 20 x 10 mesh (which are fine nodes) and at the tracked points. Cached.

**The effective truth**: no single (mua, mus) describes tissue whose optics vary from
voxel to voxel. We compare the filters with the optics of the damage model at the
truth's own damage: ``F_true(t)``, the coagulated fraction of
:func:`enkf.tissue.coagulation.coagulated_fraction` of the truth's damage at the coarse
nodes (integrated from its temperatures like the filter's members) with the filter's
default weights (the square of the absorbed power of the true native optics), and
``mua_eff = 1 + 0.5 F_true``,
``mus_eff = 100 + 200 F_true``.

**The ramp truths** (:func:`ramp_twin_truth`): optics that follow a prescribed ramp in
time, not the damage: the paper's (``"time-varying"``: 0 deg C, 0.5 W, mua 1 -> 4 and
mus 100 -> 500 over the pulse, no damage at all) and a hot ramp (``"hot-ramp"``: this
scenario's laser with mua 1 -> 1.5, mus 100 -> 300 linearly over the 5 s pulse, the
coagulated values reached on a schedule the damage does not set), run with the filter's
own coarse model (identical twin).
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

import fem
from mcmatlab_py.emulator import default_cache_dir, load_cached, store_atomically, usable_cache_dir
from mcmatlab_py.heat import HeatSimulation

from ..tissue.coagulation import Coagulation, coagulated_fraction
from ..tissue.forward import TissueForwardModel
from ..tissue.parameters import ESTIMATES, tracked_points
from ..tissue.risk import MCMATLAB_A, MCMATLAB_E
from ..tissue.setup import TissueFilterSetup
from .scenarios import TABLE, mua_ramp, mus_ramp, paper_model

__all__ = ["COAGULATED", "COAG_PULSES", "CoagulationTruth", "CoagulationTruthConfig",
           "T_INITIAL", "coagulation_setup", "damage_truth", "effective_truth",
           "ramp_twin_truth", "twin_damage_truth"]

T_INITIAL = 37.0  #: deg C, body temperature
#: laser of each scenario: (P W, duration_on s, duration_off s, n_pulses)
COAG_PULSES = {"coagulation": (1.0, 5.0, 10.0, 1), "coagulation-train": (1.0, 2.0, 3.0, 3),
               "hot-ramp": (1.0, 5.0, 10.0, 1), "time-varying": (0.5, 5.0, 10.0, 1)}
#: cm^-1, the coagulated optics of the truth (native: Table 1's mua 1, mus 100)
COAGULATED = {"mua_coag": 1.5, "mus_coag": 300.0}
E_TRUE, A_TRUE = MCMATLAB_E, MCMATLAB_A  #: J/mol, 1/s


def laser(scenario: str) -> HeatSimulation:
    """The heat simulation holding the laser of ``scenario`` (its ``laser_power``)."""
    P, on, off, n = COAG_PULSES[scenario]
    return HeatSimulation(P=P, duration_on=on, duration_off=off, n_pulses=n, dt=0.1)


def start_temperature(scenario: str) -> float:
    return 0.0 if scenario == "time-varying" else T_INITIAL


def hot_ramp(t: float) -> tuple[float, float]:
    """(mua, mus) cm^-1 of the hot ramp: linear from native to coagulated over 0-5 s."""
    s = min(max(t, 0.0), 5.0) / 5.0
    return (TABLE["mua"] + s * (COAGULATED["mua_coag"] - TABLE["mua"]),
            TABLE["mus"] + s * (COAGULATED["mus_coag"] - TABLE["mus"]))


# ---------------------------------------------------------------------------- truths
@dataclass
class CoagulationTruthConfig:
    """What determines a damage truth (hashed into its cache key)."""

    scenario: str = "coagulation"  #: "coagulation" or "coagulation-train"
    grid: tuple = (100, 100, 50)  #: the Monte Carlo's voxels (and the fine heat mesh)
    coarse: tuple = (20, 20, 10)  #: the filter's grid, whose nodes are read
    n_photons: int = 300_000  #: per Monte Carlo run
    mc_seed: int = 1
    n_bins: int = 16  #: sub-media of the damage-dependent medium
    recalc_every: float = 0.5  #: s between re-evaluations of the media (MC re-runs)

    def key(self) -> str:
        d = asdict(self)
        d.update(version=1, native=[TABLE["mua"], TABLE["mus"]], coag=COAGULATED,
                 E=E_TRUE, A=A_TRUE, T0=T_INITIAL, laser=COAG_PULSES[self.scenario])
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:20]


@dataclass
class CoagulationTruth:
    """A truth at 10 Hz: ``times`` (n,) s; ``temps`` (n, 3) deg C at the tracked depths;
    ``nodes`` (n, n_coarse) deg C at the filter's nodes; ``optics`` (n, 2) the true (or,
    for a damage truth, effective) mua and mus cm^-1; ``F`` (n,) the coagulated fraction
    behind them (zeros for a ramp); ``wall_seconds`` to compute; ``mc_runs``."""

    scenario: str
    times: np.ndarray
    temps: np.ndarray
    nodes: np.ndarray
    optics: np.ndarray
    F: np.ndarray
    wall_seconds: float = 0.0
    mc_runs: int = 0
    kind: str = "damage"  #: "damage" (fine grid), "twin-damage", "ramp"


def _fd_optics(native: float, coag: float):
    def f(wavelength, FR, T, FD):  # MCmatlab's signature of a state-dependent property
        return native + (coag - native) * FD
    return f


def damage_truth(cfg: CoagulationTruthConfig, emulator, *, cache_dir=None,
                 progress: bool = False) -> CoagulationTruth:
    """The fine-grid truth whose voxels' optics follow their damage (cached; module doc).

    ``emulator``: the filter's absorption emulator, for the weights of the effective optics.
    """
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = cache / f"coag-truth-{cfg.key()}.npz"
    f = load_cached(path, "truth cache")
    if f is not None and {"times", "temps", "nodes", "wall_seconds", "mc_runs"} <= set(f):
        return effective_truth(cfg.scenario, f["times"], f["temps"], f["nodes"], emulator,
                               float(f["wall_seconds"]), int(f["mc_runs"]))
    path = usable_cache_dir(cache, path.name) / path.name  # checked before hours of work
    tic = time.perf_counter()
    P, on, off, n = COAG_PULSES[cfg.scenario]
    model = paper_model(cfg.grid, cfg.n_photons, cfg.mc_seed, progress, scenario="constant")
    model.G.media = [replace(m, mua=_fd_optics(TABLE["mua"], COAGULATED["mua_coag"]),
                             mus=_fd_optics(TABLE["mus"], COAGULATED["mus_coag"]),
                             E=E_TRUE, A=A_TRUE, n_bins=cfg.n_bins) for m in model.G.media]
    model.MC.T = T_INITIAL
    HS = model.HS
    HS.P, HS.duration_on, HS.duration_off, HS.n_pulses = P, on, off, n
    HS.T_initial = T_INITIAL
    HS.n_updates = max(1, round((on + off) / cfg.recalc_every))  # per pulse
    HS.media_prop_recalc_period = 1
    coarse = fem.BoxGrid(*cfg.coarse, 0.5, 0.5, 0.25).mesh()
    tracked = [tuple(p) for p in tracked_points()]
    HS.temp_sensor_positions = tracked + [tuple(p) for p in coarse.p.T]
    model.run_monte_carlo()
    model.simulate_heat_distribution()
    wall = time.perf_counter() - tic
    times = HS.sensor_times
    temps = HS.sensor_temps[:, :len(tracked)]
    nodes = HS.sensor_temps[:, len(tracked):]
    runs = int(HS.mc_runs) + 1
    store_atomically(path, "truth cache", times=times, temps=temps,
                     nodes=nodes.astype(np.float32), wall_seconds=wall, mc_runs=runs)
    return effective_truth(cfg.scenario, times, temps, nodes, emulator, wall, runs)


def true_damage(times: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """(n, n_coarse) the damage integral at the nodes from their temperatures (trapezoid,
    as the filter's members)."""
    omega = np.zeros((1, nodes.shape[1]))
    out = [omega[0].copy()]
    for k in range(1, len(times)):
        fem.advance_damage(omega, nodes[k - 1][None, :].astype(float),
                           nodes[k][None, :].astype(float), float(times[k] - times[k - 1]),
                           E_TRUE, A_TRUE, rule="trapezoid")
        out.append(omega[0].copy())
    return np.array(out)


def native_weights(emulator) -> np.ndarray:
    """(n_coarse,) the weights of F: the filter's default (:class:`Coagulation`) on the nodal
    loads per W of the true native optics."""
    vals = emulator.unique(np.array([TABLE["mua"]]), np.array([TABLE["mus"]]))
    return Coagulation().weights(vals[0][emulator.inverse])


def effective_truth(scenario, times, temps, nodes, emulator, wall=0.0, runs=0,
                    kind="damage") -> CoagulationTruth:
    """A damage truth with its effective optics (module doc)."""
    F = coagulated_fraction(true_damage(times, nodes), native_weights(emulator))
    optics = np.column_stack([TABLE["mua"] + F * (COAGULATED["mua_coag"] - TABLE["mua"]),
                              TABLE["mus"] + F * (COAGULATED["mus_coag"] - TABLE["mus"])])
    return CoagulationTruth(scenario, np.asarray(times), np.asarray(temps),
                            np.asarray(nodes, float), optics, F, wall, runs, kind)


def _march_twin(setup, model, theta_of, times) -> tuple[np.ndarray, np.ndarray]:
    """One member through ``times``: ((n, 3) tracked, (n, n_nodes) nodes) deg C."""
    T = np.full((1, model.mesh.p.shape[1]), setup.T_initial)
    out = [T[0].copy()]
    for t0, t1 in zip(times[:-1], times[1:], strict=True):
        T = model(T, theta_of(0.5 * (t0 + t1)), float(t0), float(t1))
        out.append(T[0].copy())
    nodes = np.array(out)
    P_track = fem.probe_matrix(model.mesh, setup.sensors.tracked.T)
    return (P_track @ nodes.T).T, nodes


def twin_damage_truth(scenario: str, emulator, times=None) -> CoagulationTruth:
    """The identical twin of a damage truth: the filter's own damage-driven coarse model at
    the true native and coagulated optics (no model error)."""
    from ..tissue.coagulation import CoagulationForwardModel

    times = np.round(np.arange(0, 15.0 + 1e-9, 0.1), 10) if times is None else times
    setup = coagulation_setup(scenario, emulator, "coagulation", n_members=2)
    model = CoagulationForwardModel(TissueForwardModel(setup), setup.parameters.coagulation,
                                    setup.parameters.names)
    th = np.array([[TABLE["mua"], TABLE["mus"], COAGULATED["mua_coag"],
                    COAGULATED["mus_coag"]]])
    temps, nodes = _march_twin(setup, model, lambda t: th, times)
    return effective_truth(scenario, times, temps, nodes, emulator, kind="twin-damage")


def ramp_twin_truth(scenario: str, emulator, times=None) -> CoagulationTruth:
    """Optics on a prescribed ramp (``"time-varying"``: the paper's; ``"hot-ramp"``),
    run with the filter's own coarse model (module doc)."""
    times = np.round(np.arange(0, 15.0 + 1e-9, 0.1), 10) if times is None else times
    setup = coagulation_setup(scenario, emulator, "random_walk", n_members=2)
    model = TissueForwardModel(setup)
    ramp = hot_ramp if scenario == "hot-ramp" else (lambda t: (mua_ramp(t), mus_ramp(t)))
    temps, nodes = _march_twin(setup, model, lambda t: np.array([ramp(t)]), times)
    optics = np.array([ramp(t) for t in times])
    return CoagulationTruth(scenario, times, temps, nodes, optics, np.zeros(len(times)),
                            kind="ramp")


# ---------------------------------------------------------------------------- filters
def coagulation_setup(scenario: str, absorption, model: str = "coagulation", *,
                      seed: int = 0, n_members: int = 50, coarse=(20, 20, 10),
                      **overrides) -> TissueFilterSetup:
    """The filter of a scenario of this module: the paper's coarse model and priors, at the
    scenario's start temperature and laser.

    ``model``: ``"coagulation"`` (optics driven by each member's damage; native and
    coagulated values estimated, the coagulated prior [0.5, 2] times (1.5, 3) times the
    native nominal, a walk of 0.005 per step with the laser on: the values are constants,
    the walk only lets the model's approximations be absorbed), or ``"random_walk"`` (the
    project's walk for drifting optics, [0.03, 0.10] per step with the laser on, as
    :func:`enkf.paper.filter_setup` for the paper's time-varying case).
    """
    if model not in ("coagulation", "random_walk"):
        raise ValueError(f"model must be 'coagulation' or 'random_walk', got {model!r}")
    overrides.setdefault("random_walk_std", 0.005 if model == "coagulation" else [0.03, 0.10])
    overrides.setdefault("random_walk_when_off", 0.0)
    overrides.setdefault("sensor_positions", np.zeros((1, 3)))
    if model == "coagulation":
        overrides.setdefault("coagulation", Coagulation(E=E_TRUE, A=A_TRUE))
    return TissueFilterSetup.build(
        grid=fem.BoxGrid(*coarse, 0.5, 0.5, 0.25), absorption=absorption,
        power=laser(scenario).laser_power, nominal=dict(TABLE), estimate=ESTIMATES[0],
        sensor_noise_var=0.01, tracked_positions=tracked_points(),
        T_initial=start_temperature(scenario), n_members=n_members, seed=seed,
        parameter_model=model, **overrides)
