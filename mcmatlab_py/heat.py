"""The heat simulation front end (MCmatlab's ``model.HS``), on the finite elements of :mod:`fem`.

MCmatlab follows its Monte Carlo with a voxel finite-difference heat solver; here
the absorbed power ``P * NA`` (W/cm^3) is moved onto a tetrahedral mesh (by
default with its nodes at the voxel corners) and the heat equation

.. math:: c_v \\partial_t T = \\nabla \\cdot (k \\nabla T) + P\\,A

(Arnold & Fichera, eq. 1-2) is stepped with an implicit theta-scheme.

Beyond MCmatlab, the tissue may change while it is heated: ``HS.mua_t``,
``HS.mus_t``, ``HS.VHC_t`` and ``HS.TC_t`` are functions of time (s) that replace the
properties of medium ``HS.varying_medium``. The absorbed power map then follows
them: recomputed by direct Monte Carlo whenever the optical properties change,
or taken from an emulator (``HS.absorption = emulator``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ._strict import NotBuiltError, StrictAttributes
from .media import check_positive
from .progress import Progress

__all__ = ["HeatSimulation", "simulate_heat_distribution"]


@dataclass
class HeatSimulation(StrictAttributes):
    """Heat simulation settings and results (MCmatlab's ``model.HS``).

    Results (filled by :meth:`Model.simulate_heat_distribution`):

    * ``sensor_times``: (n_times,) s, 0 and the end of every step.
    * ``sensor_temps``: (n_times, n_sensors) deg C at ``temp_sensor_positions``.
    * ``T``: final temperature, deg C, on the mesh nodes: (nx+1, ny+1, nz+1) for the
      default mesh whose nodes are the voxel corners (``T_nodes`` is the flat (npoints,)).
    * ``Omega``: Arrhenius damage integral, same shape as ``T`` (0 where E, A not given).
    * ``mesh``: the scikit-fem ``MeshTet`` used; ``snapshots``: list of (t, T_nodes).
    """

    P: float | Callable = 1.0  #: W, laser power, or a function P(t) of time (s)
    duration_on: float = 0.1  #: s, laser on in each pulse
    duration_off: float = 0.0  #: s, then off
    n_pulses: int = 1
    dt: float = 0.01  #: s, time step
    T_initial: float = 37.0  #: deg C
    heat_boundary_type: int = 0  #: 0 insulating, 1 constant temperature, 2 convective
    heat_transfer_coefficient: float = 1e-3  #: W cm^-2 K^-1 (type 2)
    T_ambient: float = 20.0  #: deg C (type 2)
    temp_sensor_positions: list = field(default_factory=list)  #: [(x, y, z)] cm
    theta: float = 1.0  #: 1 backward Euler, 0.5 Crank-Nicolson
    mesh_divisions: tuple | None = None  #: (nx, ny, nz) of the FEM mesh; None: the voxels
    # time-varying tissue (beyond MCmatlab)
    mua_t: Callable | None = None  #: mua(t), cm^-1
    mus_t: Callable | None = None  #: mus(t), cm^-1
    VHC_t: Callable | None = None  #: VHC(t), J cm^-3 K^-1
    TC_t: Callable | None = None  #: TC(t), W cm^-1 K^-1
    varying_medium: int = 0  #: the medium that the *_t functions replace
    #: "monte_carlo" (direct MC when the optics change) or a callable (mua, mus) -> NA
    absorption: str | Callable = "monte_carlo"
    n_snapshots: int = 0  #: temperature fields to keep (evenly spaced), for VTU series
    progress: bool = True

    # results
    sensor_times: np.ndarray | None = None
    sensor_temps: np.ndarray | None = None
    T: np.ndarray | None = None
    T_nodes: np.ndarray | None = None
    Omega: np.ndarray | None = None
    mesh: object = None
    snapshots: list | None = None
    mc_runs: int = 0

    _owner_label = "HS"
    _renamed = {"Tinitial": "T_initial", "sensorsTimeVector": "sensor_times",
                "silentMode": "progress (= not silentMode)"}
    _not_built = ("useGPU", "useAllCPUs", "makeMovie", "deferMovieWrite", "largeTimeSteps",
                  "durationEnd", "plotTempLimits", "nUpdates", "mediaPropRecalcPeriod",
                  "slicePositions", "maxMediaTemps", "movieFrames", "mediaProperties", "M")

    def validate(self, G) -> None:
        if not callable(self.P):
            self.P = check_positive("HS", "P", self.P, allow_zero=True)
        self.duration_on = check_positive("HS", "duration_on", self.duration_on, allow_zero=True)
        self.duration_off = check_positive("HS", "duration_off", self.duration_off,
                                           allow_zero=True)
        if self.duration_on + self.duration_off <= 0:
            raise ValueError("HS.duration_on + HS.duration_off must be > 0, got "
                             f"{self.duration_on} + {self.duration_off}")
        if isinstance(self.n_pulses, bool) or not isinstance(self.n_pulses, (int, np.integer)) \
                or self.n_pulses < 1:
            raise ValueError(f"HS.n_pulses must be an integer >= 1, got {self.n_pulses!r}")
        self.dt = check_positive("HS", "dt", self.dt)
        if self.dt > self.total_duration:
            raise ValueError(f"HS.dt = {self.dt!r} s is longer than the whole run "
                             f"(n_pulses * (duration_on + duration_off) = {self.total_duration} s)")
        if isinstance(self.T_initial, bool) or not isinstance(self.T_initial, (int, float)) \
                or not math.isfinite(self.T_initial):
            raise ValueError(f"HS.T_initial must be a finite number (deg C), got "
                             f"{self.T_initial!r}")
        if self.heat_boundary_type not in (0, 1, 2):
            raise ValueError(f"HS.heat_boundary_type must be 0, 1 or 2, got "
                             f"{self.heat_boundary_type!r}")
        if self.heat_boundary_type == 2:
            check_positive("HS", "heat_transfer_coefficient", self.heat_transfer_coefficient)
        if isinstance(self.theta, bool) or not isinstance(self.theta, (int, float)) \
                or not (0.5 <= float(self.theta) <= 1.0):
            raise ValueError(f"HS.theta must be in [0.5, 1] (implicit), got {self.theta!r}")
        if not isinstance(self.temp_sensor_positions, (list, tuple, np.ndarray)):
            raise ValueError(f"HS.temp_sensor_positions must be a list of (x, y, z), got "
                             f"{self.temp_sensor_positions!r}")
        for i, pos in enumerate(self.temp_sensor_positions):
            try:
                p = np.asarray(pos, dtype=float)
            except (TypeError, ValueError):
                p = np.full(0, np.nan)
            if p.shape != (3,) or not np.all(np.isfinite(p)):
                raise ValueError(f"HS.temp_sensor_positions[{i}] must be (x, y, z), got {pos!r}")
            tol = 1e-9 * max(G.Lx, G.Ly, G.Lz)
            if (abs(p[0]) > G.Lx / 2 + tol or abs(p[1]) > G.Ly / 2 + tol
                    or p[2] < -tol or p[2] > G.Lz + tol):
                raise ValueError(f"HS.temp_sensor_positions[{i}] = {tuple(pos)} cm is outside "
                                 f"the tissue [-{G.Lx / 2}, {G.Lx / 2}] x [-{G.Ly / 2}, "
                                 f"{G.Ly / 2}] x [0, {G.Lz}]")
        for name in ("VHC", "TC"):
            for i, m in enumerate(G.media):
                if getattr(m, name) is None and getattr(self, f"{name}_t") is None:
                    raise ValueError(f"G.media[{i}].{name} is needed by the heat simulation, "
                                     "got None")
                if callable(getattr(m, name)):
                    raise NotBuiltError(
                        f"G.media[{i}].{name} is a function of (T, FD): MCmatlab's heat "
                        "simulation with temperature- or damage-dependent media is not built "
                        "yet (mcmatlab_py.media_bins.thermal_media_properties evaluates them)")
        if not (self.absorption == "monte_carlo" or callable(self.absorption)):
            raise ValueError("HS.absorption must be 'monte_carlo' or a callable (mua, mus) -> "
                             f"NA, got {self.absorption!r}")

    @property
    def total_duration(self) -> float:
        """s: ``n_pulses * (duration_on + duration_off)``."""
        return self.n_pulses * (self.duration_on + self.duration_off)

    def step_times(self) -> np.ndarray:
        """(n_steps,) s: the end time of every step."""
        n = int(round(self.total_duration / self.dt))
        return self.dt * np.arange(1, n + 1)

    def laser_power(self, t: float) -> float:
        """W delivered at time ``t`` (s): ``P`` (or ``P(t)``) while a pulse is on, else 0.

        Pulse ``i`` (0-based) is on during ``[i T, i T + duration_on)`` with period
        ``T = duration_on + duration_off``, MCmatlab's meaning of ``n_pulses``.
        """
        period = self.duration_on + self.duration_off
        if t < 0 or t >= self.n_pulses * period or (t % period) >= self.duration_on:
            return 0.0
        return float(self.P(t)) if callable(self.P) else float(self.P)


def _value(f, t):
    v = float(f(t))
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"a time-varying property returned {v!r} at t = {t} s")
    return v


def simulate_heat_distribution(model) -> None:
    """Run ``model.HS`` on ``model.G`` with the absorption of ``model.MC`` (see module doc)."""
    import fem

    from .monte_carlo import optical_arrays, simulate, store_results

    G, MC, HS = model.G, model.MC, model.HS
    M = G.medium_map()
    HS.validate(G)
    varying_optics = HS.mua_t is not None or HS.mus_t is not None
    if MC.NA is None and not varying_optics and not callable(HS.absorption):
        raise ValueError("MC.NA is empty: run model.run_monte_carlo() before the heat "
                         "simulation (or give time-varying optics)")
    media = G.media
    vm = HS.varying_medium
    if not 0 <= vm < len(media):
        raise ValueError(f"HS.varying_medium must index G.media, got {vm!r}")

    grid = fem.BoxGrid(G.nx, G.ny, G.nz, G.Lx, G.Ly, G.Lz)
    if HS.mesh_divisions is None:
        mesh_grid = grid
    else:
        nxm, nym, nzm = HS.mesh_divisions
        mesh_grid = fem.BoxGrid(nxm, nym, nzm, G.Lx, G.Ly, G.Lz)
    mesh = mesh_grid.mesh()
    L = fem.voxel_load_matrix(mesh, grid)  # (npoints, nvox): W per node from W/cm^3
    # media per element: the voxel that holds the element's centroid
    elem_medium = M.ravel()[fem.element_voxel_index(mesh, grid)]

    def props(t):
        vhc = np.array([m.VHC if m.VHC is not None else np.nan for m in media], float)
        tc = np.array([m.TC if m.TC is not None else np.nan for m in media], float)
        if HS.VHC_t is not None:
            vhc[vm] = _value(HS.VHC_t, t)
        if HS.TC_t is not None:
            tc[vm] = _value(HS.TC_t, t)
        return vhc, tc

    vhc0, tc0 = props(0.0)
    boundary = fem.HeatBoundary.from_mcmatlab(
        HS.heat_boundary_type,
        temperature=None if HS.heat_boundary_type != 2 else HS.T_ambient,
        h=HS.heat_transfer_coefficient if HS.heat_boundary_type == 2 else 0.0)
    stepper = fem.HeatStepper(mesh, vhc0[elem_medium], tc0[elem_medium], HS.dt,
                              theta=HS.theta, boundary=boundary)
    probes = fem.probe_matrix(mesh, np.asarray(HS.temp_sensor_positions, float)
                              .reshape(-1, 3).T) if len(HS.temp_sensor_positions) else None
    single_thermal = len(media) == 1

    mua, mus, g, nref = optical_arrays(media, MC.wavelength)
    current_optics = None
    NA = MC.NA

    def absorption_at(t):
        nonlocal current_optics, NA
        if not varying_optics:
            if callable(HS.absorption) and NA is None:
                NA = HS.absorption(np.array([mua[vm]]), np.array([mus[vm]]))[0]
            return NA
        a = _value(HS.mua_t, t) if HS.mua_t is not None else mua[vm]
        s = _value(HS.mus_t, t) if HS.mus_t is not None else mus[vm]
        if current_optics == (a, s):
            return NA
        current_optics = (a, s)
        if callable(HS.absorption):
            NA = HS.absorption(np.array([a]), np.array([s]))[0]
        else:
            mua_now, mus_now = mua.copy(), mus.copy()
            mua_now[vm], mus_now[vm] = a, s
            res = simulate(G, MC, M, mua_now, mus_now, g, nref,
                           seed=(MC.seed or 0) + HS.mc_runs, n_photons=MC.n_photons_requested
                           or 10**6)
            HS.mc_runs += 1
            store_results(MC, res, M, mua_now, G.dx * G.dy * G.dz)
            NA = MC.NA
        return NA

    times = np.r_[0.0, HS.step_times()]
    T0 = np.full(mesh.p.shape[1], float(HS.T_initial))
    Omega = np.zeros_like(T0)
    E_node, A_node = _damage_parameters(mesh, elem_medium, media)
    snap_every = max(1, (len(times) - 1) // HS.n_snapshots) if HS.n_snapshots else 0
    HS.snapshots = [(0.0, T0.copy())] if snap_every else []
    HS.mc_runs = 0
    bar = Progress(len(times) - 1, "heat", enabled=HS.progress)

    def step(T, t0, t1):
        nonlocal stepper
        t_mid = t1 - 0.5 * HS.dt  # sources and properties at mid-step
        scales = {}
        if HS.VHC_t is not None or HS.TC_t is not None:
            vhc, tc = props(t_mid)
            if single_thermal:
                scales = dict(vhc_scale=np.array([vhc[0] / vhc0[0]]),
                              tc_scale=np.array([tc[0] / tc0[0]]))
            else:
                stepper = fem.HeatStepper(mesh, vhc[elem_medium], tc[elem_medium], HS.dt,
                                          theta=HS.theta, boundary=boundary)
        power = HS.laser_power(t_mid)
        load = L @ (power * absorption_at(t_mid)).ravel() if power != 0 else None  # W
        if scales:
            return stepper.step(T[None, :], None if load is None else load[None, :],
                                **scales)[0]
        return stepper.step(T, load)

    def on_step(k, t1, T_old, T_new):
        if E_node is not None:
            fem.advance_damage(Omega, T_old, T_new, HS.dt, E_node, A_node)
        if snap_every and k % snap_every == 0:
            HS.snapshots.append((t1, T_new.copy()))
        bar.update(k)

    T, sensor = fem.march(step, T0, times, probes, on_step)
    bar.close()
    HS.sensor_times = times
    HS.sensor_temps = sensor if sensor is not None else np.empty((len(times), 0))
    HS.mesh = mesh
    HS.T_nodes = T
    shape = tuple(n + 1 for n in mesh_grid.shape)
    HS.T = T.reshape(shape)
    HS.Omega = Omega.reshape(shape)


def _damage_parameters(mesh, elem_medium, media):
    """Per-node Arrhenius E (J/mol) and A (1/s), from the media of the elements around it.

    A node between media takes the most damageable of them (the largest ``A``, then ``E``),
    as ``fem.element_to_node(..., how="max")``, so that a node touching damageable tissue
    can be damaged; E and A come from that one medium, never a mix of two.
    """
    import fem

    if all(m.E is None or m.A is None for m in media):
        return None, None
    E = np.array([m.E if m.E is not None else 0.0 for m in media])
    A = np.array([m.A if m.A is not None else 0.0 for m in media])
    order = np.lexsort((E, A))  # media from the least to the most damageable
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    node_medium = order[fem.element_to_node(mesh, rank[elem_medium], "max").astype(int)]
    return E[node_medium], A[node_medium]
