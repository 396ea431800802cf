"""The heat simulation front end (MCmatlab's ``model.HS``), on the finite elements of :mod:`fem`.

MCmatlab follows its Monte Carlo with a voxel finite-difference heat solver; here
the absorbed power ``P * NA`` (W/cm^3) is moved onto a tetrahedral mesh (by
default with its nodes at the voxel corners) and the heat equation

.. math:: c_v \\partial_t T = \\nabla \\cdot (k \\nabla T) + P\\,A

(Arnold & Fichera, eq. 1-2) is stepped with an implicit theta-scheme.

A run is MCmatlab's: ``n_pulses`` pulses of ``duration_on`` (laser on) and
``duration_off`` (off), then ``duration_end`` of cooling; ``n_updates`` times per pulse
the state is reported (slice plots, movie frames) and, every
``media_prop_recalc_period`` updates, media that depend on fluence rate, temperature
or damage are re-evaluated (the Monte Carlo re-run when their optics change, see
:mod:`mcmatlab_py.frt`). A second call continues from where the first ended (the
final temperatures, damage and clock; MCmatlab's Example 11); :meth:`HeatSimulation.reset`
starts afresh. The time step is ``dt`` when given, else chosen from the mesh and media
(:func:`auto_dt`, see ``docs/heat.md``), and chosen again (steps cut into sub-steps) when
VHC or TC that depend on temperature or damage change.

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

from fem.checks import check_number

from .._strict import StrictAttributes
from ..geometry.media import LIMITS, check_positive
from ..geometry.media_bins import state_field

__all__ = ["HeatSimulation", "Schedule", "T_INITIAL_RANGE", "auto_dt"]

#: MCmatlab's step is 1.5 times the explicit (forward Euler) stability limit 2 / lambda_max
#: of its voxel scheme, 15 times with ``largeTimeSteps``: lambda_max dt = 3 (or 30)
MCMATLAB_STEP_FACTOR = 3.0
LARGE_STEP_FACTOR = 10.0  #: ``large_time_steps``: MCmatlab's 15 / 1.5
#: deg C: the start temperatures accepted, from absolute zero to far above anything tissue
#: reaches before it vaporises (the range of the filter's health check, whose run would
#: otherwise stop at step 0)
T_INITIAL_RANGE = (-273.15, 1.0e4)


def auto_dt(spacing, vhc, tc, theta: float = 1.0, large_time_steps: bool = False) -> float:
    r"""The automatic time step (s) of the theta scheme on a box mesh.

    The stiffest mode of the lumped P1 (Kuhn mesh: the 7-point) operator decays at

    .. math:: \lambda_{max} = 4 \max(k / c_v) \sum_i h_i^{-2},

    and one theta step multiplies a mode by :math:`R(z) = (1 - (1-\theta) z)/(1 + \theta z)`,
    :math:`z = \lambda \Delta t`. The step is the largest with :math:`R(z) \ge 0` for every
    mode (no spurious oscillation: :math:`z \le 1/(1-\theta)`, 2 for Crank-Nicolson) and
    at most MCmatlab's step, :math:`z = 3` (1.5 times the explicit limit; 30 with
    ``large_time_steps``, MCmatlab's ``largeTimeSteps``). See ``docs/heat.md``.

    Parameters
    ----------
    spacing : (3,) cm
        Mesh spacing ``(hx, hy, hz)``.
    vhc, tc : arrays (n,)
        J cm^-3 K^-1 and W cm^-1 K^-1, of the elements or media (NaN entries ignored);
        TC = 0 (an insulator) sets no bound, and a ``ValueError`` asks for ``HS.dt`` when
        every TC is 0.
    theta : float
        The scheme's implicitness, in [0.5, 1].
    large_time_steps : bool
        Ten times longer steps (less accurate on the voxel scale).
    """
    alpha = np.asarray(tc, float) / np.asarray(vhc, float)
    alpha = alpha[np.isfinite(alpha)]
    if alpha.size == 0 or alpha.max() <= 0:
        raise ValueError("HS.dt = None, but every medium has TC = 0: the automatic time step "
                         "needs some TC > 0 (perfect insulators have no time scale); set HS.dt "
                         "(s)")
    lam = 4.0 * float(alpha.max()) * sum(1.0 / float(h) ** 2 for h in spacing)
    z = MCMATLAB_STEP_FACTOR
    if theta < 1.0:
        z = min(z, 1.0 / (1.0 - theta))
    if large_time_steps:
        z *= LARGE_STEP_FACTOR
    return z / lam


@dataclass
class Schedule:
    """The steps of one heat run, in the run's own clock (0 at its start).

    ``times`` (n_steps + 1,) s; ``updates`` (n_updates,) int: the steps (1-based) after
    which the state is reported (plots, movie, media recalculation); ``dt`` (n_steps,) s.
    """

    times: np.ndarray
    updates: np.ndarray

    @property
    def dt(self) -> np.ndarray:
        return np.diff(self.times)


@dataclass
class HeatSimulation(StrictAttributes):
    """Heat simulation settings and results (MCmatlab's ``model.HS``).

    Results (filled by :meth:`Model.simulate_heat_distribution`; a later call appends):

    * ``sensor_times``: (n_times,) s, 0 and the end of every step (of all chained runs).
    * ``sensor_temps``: (n_times, n_sensors) deg C at ``temp_sensor_positions``.
    * ``T``: final temperature, deg C, on the mesh nodes: (nx+1, ny+1, nz+1) for the
      default mesh whose nodes are the voxel corners (``T_nodes`` is the flat (npoints,)).
      Set before a run, it is the start temperature, as MCmatlab's ``HS.T``: a number or
      (nx, ny, nz) on the voxels (or this shape on the nodes); before a first run it
      becomes ``T_initial`` too, and one of its own that differs raises a ``ValueError``.
    * ``Omega``: Arrhenius damage integral, same shape as ``T`` (0 where E, A not given).
    * ``T_voxels``, ``Omega_voxels``: the same at the voxel centres, (nx, ny, nz)
      (MCmatlab's ``HS.T`` and ``HS.Omega``): ``T_voxels`` the P1 field evaluated there;
      ``Omega_voxels`` integrated at every step from those temperatures with the voxel's
      own medium's E and A (a node on an interface takes the most damageable medium, so
      interpolating ``Omega`` would spread damage into the neighbouring voxels).
    * ``max_media_temps``: (n_media,) deg C, the highest temperature each medium of
      ``G.media`` reached at a node of its elements (``-inf`` for a medium on no voxel).
    * ``media_properties``, ``M``: the thermal sub-media and their voxel map
      (:class:`mcmatlab_py.geometry.media_bins.ThermalMediaProperties`) at the end of the run.
    * ``mesh``: the scikit-fem ``MeshTet`` used; ``snapshots``: list of (t, T_nodes).
    * ``movie_frames``: (n, h, w, 3) uint8 frames kept by ``defer_movie_write``.
    """

    P: float | Callable = 1.0  #: W, laser power, or a function P(t) of time (s)
    duration_on: float = 0.1  #: s, laser on in each pulse
    duration_off: float = 0.0  #: s, then off
    duration_end: float = 0.0  #: s, cooling after the last pulse (MCmatlab's durationEnd)
    n_pulses: int = 1
    dt: float | None = None  #: s, time step; None: chosen automatically (``step_control``)
    #: with ``dt = None``: "accuracy" (steps from a local error estimate against ``rtol``,
    #: :mod:`mcmatlab_py.heat.steps`) or "stability" (MCmatlab's rule, :func:`auto_dt`)
    step_control: str = "accuracy"
    rtol: float = 1e-3  #: "accuracy": local error per step, of the run's temperature rise
    #: "accuracy": the integrator of the error-controlled steps: "implicit" (TR-BDF2,
    #: :mod:`mcmatlab_py.heat.steps`), "rkc" (explicit Runge-Kutta-Chebyshev,
    #: :mod:`mcmatlab_py.heat.rkc`; needs ``mass = "lumped"``) or "auto" (RKC where a cost
    #: model finds it cheaper: phases not much longer than the explicit stability bound,
    #: short pulses; implicit otherwise, and with ``mass = "averaged"`` or ``use_gpu``)
    integrator: str = "auto"
    #: s, "accuracy": sensor readings at the multiples of this (the steps land on them);
    #: None: at the end of every step, as MCmatlab's
    sensor_interval: float | None = None
    #: "accuracy": end a step at every update (``n_updates`` per pulse) even where nothing
    #: reads the state there. False (default): only where something does (live plot, movie,
    #: snapshots, media that follow T or FD, fluorescence, a power ``P(t)``) and at the
    #: phases' edges, so that the steps grow as the field settles (MCmatlab's Example 4 held
    #: at its 450 updates took 450 steps, free 62, 3.6 times faster)
    steps_at_updates: bool = False
    large_time_steps: bool = False  #: with ``step_control = "stability"``: ten times longer steps
    #: the heat capacity's matrix: "lumped" (a discrete maximum principle: no node colder
    #: than the coldest start or boundary, as MCmatlab's finite volumes) or "averaged" (the
    #: mean of the lumped and the consistent mass: fourth-order modes, several times more
    #: accurate per node; docs/heat.md)
    mass: str = "lumped"
    #: deg C: a number, or an (nx, ny, nz) array on the voxels (MCmatlab's 3-D ``HS.T``)
    T_initial: float | np.ndarray = 37.0
    heat_boundary_type: int = 0  #: 0 insulating, 1 constant temperature, 2 convective
    heat_transfer_coefficient: float = 1e-3  #: W cm^-2 K^-1 (type 2)
    T_ambient: float = 20.0  #: deg C (type 2)
    temp_sensor_positions: list = field(default_factory=list)  #: [(x, y, z)] cm
    theta: float = 1.0  #: 1 backward Euler, 0.5 Crank-Nicolson
    mesh_divisions: tuple | None = None  #: (nx, ny, nz) of the FEM mesh; None: the voxels
    #: the implicit solves on an NVIDIA GPU (MCmatlab's useGPU; the ``gpu`` extra):
    #: Jacobi-preconditioned CG with the matrices on the device (:mod:`fem.gpu`)
    use_gpu: bool = False
    gpu_device: int = 0  #: index of the CUDA device used with ``use_gpu`` (MCmatlab's GPUdevice)
    n_updates: int = 10  #: reports (plots, frames) per pulse; at least one per phase
    #: every this many updates, re-evaluate FR-, T-, FD-dependent media (0: never)
    media_prop_recalc_period: int = 0
    #: relative (x, y, z) of the temperature slices, 0..1 (figures, live plot, movie); None:
    #: through the hottest voxel (of the rise above ``T_initial``; the damage figures:
    #: through the most damaged voxel), the middle when nothing heated. MCmatlab's default
    #: (0.5, 1, 1) puts the xy and xz slices on the bottom and back walls of its 3-D view;
    #: this port's flat layout of three panels would show those faces, most often unheated.
    slice_positions: tuple | None = None
    plot_temp_limits: tuple = (math.nan, math.nan)  #: deg C colour range (NaN: the data's)
    live_plot: bool = False  #: draw the temperature slices at every update (this port's)
    make_movie: bool = False  #: write the update frames as an MP4 (imageio-ffmpeg)
    movie_path: str = "heat_simulation.mp4"  #: where ``make_movie`` writes
    defer_movie_write: bool = False  #: keep the frames in ``movie_frames``, write later
    # time-varying tissue (beyond MCmatlab)
    mua_t: Callable | None = None  #: mua(t), cm^-1
    mus_t: Callable | None = None  #: mus(t), cm^-1
    VHC_t: Callable | None = None  #: VHC(t), J cm^-3 K^-1
    TC_t: Callable | None = None  #: TC(t), W cm^-1 K^-1
    varying_medium: int = 0  #: the medium that the ``*_t`` functions replace
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
    T_voxels: np.ndarray | None = None
    Omega_voxels: np.ndarray | None = None
    max_media_temps: np.ndarray | None = None
    media_properties: object = None
    M: np.ndarray | None = None
    mesh: object = None
    snapshots: list | None = None
    movie_frames: np.ndarray | None = None
    mc_runs: int = 0
    dt_used: np.ndarray | None = None  #: s, the distinct step lengths of the last run (sub-steps too)
    #: (accepted, rejected) steps of the last run (rejected: retaken shorter, "accuracy")
    steps_taken: tuple | None = None
    integrator_used: str | None = None  #: "implicit" or "rkc": the last run's (``integrator``)

    _owner_label = "HS"
    _renamed = {"Tinitial": "T_initial", "sensorsTimeVector": "sensor_times",
                "silentMode": "progress (= not silentMode)"}
    _not_built = ("useAllCPUs",)

    def validate(self, G) -> None:
        if not callable(self.P):
            self.P = check_positive("HS", "P", self.P, allow_zero=True)
        for name in ("duration_on", "duration_off", "duration_end"):
            setattr(self, name, check_positive("HS", name, getattr(self, name), allow_zero=True))
        if self.duration_on + self.duration_off <= 0:
            raise ValueError("HS.duration_on + HS.duration_off must be > 0, got "
                             f"{self.duration_on} + {self.duration_off}")
        for name in ("n_pulses", "n_updates"):
            setattr(self, name, check_number(f"HS.{name}", getattr(self, name), integer=True,
                                             lo=1, hi=10**7))
        self.media_prop_recalc_period = check_number(
            "HS.media_prop_recalc_period", self.media_prop_recalc_period, integer=True, lo=0,
            hi=10**7)
        if self.step_control not in ("accuracy", "stability"):
            raise ValueError(f"HS.step_control must be 'accuracy' or 'stability', got "
                             f"{self.step_control!r}")
        self.rtol = check_number("HS.rtol", self.rtol, lo=1e-9, hi=0.5)
        if self.integrator not in ("auto", "implicit", "rkc"):
            raise ValueError(f"HS.integrator must be 'auto', 'implicit' or 'rkc', got "
                             f"{self.integrator!r}")
        if self.mass not in ("lumped", "averaged"):
            raise ValueError(f"HS.mass must be 'lumped' or 'averaged', got {self.mass!r}")
        if self.integrator == "rkc" and self.mass != "lumped":
            raise ValueError("HS.integrator = 'rkc' needs HS.mass = 'lumped' (its stages divide "
                             f"by a diagonal heat capacity), got HS.mass = {self.mass!r}")
        if not isinstance(self.use_gpu, bool | np.bool_):
            raise ValueError(f"HS.use_gpu must be True or False, got {self.use_gpu!r}")
        self.gpu_device = int(check_number("HS.gpu_device", self.gpu_device, integer=True, lo=0,
                                           hi=1024))
        if not isinstance(self.steps_at_updates, bool | np.bool_):
            raise ValueError(f"HS.steps_at_updates must be True or False, got "
                             f"{self.steps_at_updates!r}")
        if self.sensor_interval is not None:
            self.sensor_interval = check_positive("HS", "sensor_interval", self.sensor_interval)
        if self.dt is not None:
            self.dt = check_positive("HS", "dt", self.dt)
            if self.dt > self.total_duration:
                raise ValueError(f"HS.dt = {self.dt!r} s is longer than the whole run (n_pulses "
                                 f"* (duration_on + duration_off) = {self.total_duration} s)")
        self._validate_initial(G)
        if self.heat_boundary_type not in (0, 1, 2):
            raise ValueError(f"HS.heat_boundary_type must be 0, 1 or 2, got "
                             f"{self.heat_boundary_type!r}")
        if self.heat_boundary_type == 2:
            check_positive("HS", "heat_transfer_coefficient", self.heat_transfer_coefficient)
        if isinstance(self.theta, bool) or not isinstance(self.theta, (int, float)) \
                or not (0.5 <= float(self.theta) <= 1.0):
            raise ValueError(f"HS.theta must be in [0.5, 1] (implicit), got {self.theta!r}")
        self._validate_sensors(G)
        self._validate_plotting()
        for name in ("VHC", "TC"):
            for i, m in enumerate(G.media):
                if getattr(m, name) is None and getattr(self, f"{name}_t") is None:
                    raise ValueError(f"G.media[{i}].{name} is needed by the heat simulation, "
                                     "got None")
        if not (self.absorption == "monte_carlo" or callable(self.absorption)):
            raise ValueError("HS.absorption must be 'monte_carlo' or a callable (mua, mus) -> "
                             f"NA, got {self.absorption!r}")

    def _validate_initial(self, G) -> None:
        T0 = self.T_initial
        if np.ndim(T0) == 0 and (isinstance(T0, bool) or not isinstance(T0, (int, float, np.number))
                                 or not math.isfinite(T0)):
            raise ValueError(f"HS.T_initial must be a finite number (deg C), got {T0!r}")
        self.T_initial = state_field("HS.T_initial", T0, (G.nx, G.ny, G.nz),
                                     lower=T_INITIAL_RANGE[0], upper=T_INITIAL_RANGE[1])

    def _validate_sensors(self, G) -> None:
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

    def _validate_plotting(self) -> None:
        if self.slice_positions is not None:
            try:
                s = np.asarray(self.slice_positions, dtype=float)
            except (TypeError, ValueError):
                s = np.full(0, np.nan)
            if s.shape != (3,) or not np.all((s >= 0) & (s <= 1)):
                raise ValueError("HS.slice_positions must be three numbers in [0, 1] (or None: "
                                 f"through the hottest voxel), got {self.slice_positions!r}")
        lim = np.asarray(self.plot_temp_limits, dtype=float)
        if lim.shape != (2,) or np.any(np.isinf(lim)) or (
                not np.isnan(lim).any() and lim[1] <= lim[0]):
            raise ValueError("HS.plot_temp_limits must be (low, high) deg C with high > low "
                             f"(NaN: from the data), got {self.plot_temp_limits!r}")

    @property
    def total_duration(self) -> float:
        """s: ``n_pulses * (duration_on + duration_off)`` (the pulse train, without the end)."""
        return self.n_pulses * (self.duration_on + self.duration_off)

    def reset(self) -> None:
        """Forget the results, so that the next run starts at ``T_initial`` at t = 0."""
        for name in ("sensor_times", "sensor_temps", "T", "T_nodes", "Omega", "T_voxels",
                     "Omega_voxels", "max_media_temps", "media_properties", "M", "mesh",
                     "snapshots", "movie_frames", "dt_used"):
            setattr(self, name, None)
        self.mc_runs = 0

    def phases(self) -> list[tuple[float, float, int]]:
        """MCmatlab's phases of a run: ``(start s, duration s, n_updates)``, in order.

        Each pulse has an illumination phase of ``round(n_updates * on / (on + off))``
        updates (at least 1) and a diffusion phase with the rest (at least 1); the end
        phase has ``round(n_updates * end / (on + off))`` (at least 1). Phases of zero
        duration are left out.
        """
        on, off, end = self.duration_on, self.duration_off, self.duration_end
        period = on + off
        n_on = max(1, round(self.n_updates * on / period)) if on > 0 else 0
        n_off = max(1, self.n_updates - n_on) if off > 0 else 0
        out = []
        for i in range(self.n_pulses):
            if on > 0:
                out.append((i * period, on, n_on))
            if off > 0:
                out.append((i * period + on, off, n_off))
        if end > 0:
            out.append((self.n_pulses * period, end, max(1, round(self.n_updates * end / period))))
        return out

    def schedule(self, dt_max: float | None = None) -> Schedule:
        """The steps of a run (its own clock).

        With ``dt`` given, steps of ``dt`` over the pulse train and over the end phase (as
        before ``duration_end`` existed), and the updates at the steps nearest MCmatlab's
        update times. Without, MCmatlab's: every update of a phase is split into
        ``ceil(length / dt_max)`` equal steps, so that each phase ends on a step.
        """
        phases = self.phases()
        if self.dt is not None:
            n_train = int(round(self.total_duration / self.dt))
            n_end = int(round(self.duration_end / self.dt))
            times = self.dt * np.arange(n_train + n_end + 1)
            marks = [start + length * (j + 1) / n for start, length, n in phases
                     for j in range(n)]
            updates = np.unique(np.clip(np.round(np.array(marks) / self.dt).astype(int),
                                        1, times.size - 1))
            return Schedule(times, updates)
        if dt_max is None or not dt_max > 0:
            raise ValueError("HS.schedule needs dt_max (s) when HS.dt is None")
        pieces, updates, n_done = [np.zeros(1)], [], 0
        for start, length, n in phases:
            per = max(1, math.ceil(length / n / dt_max - 1e-9))
            k = np.arange(1, n * per + 1)
            pieces.append(start + length * k / (n * per))
            updates.extend(n_done + per * np.arange(1, n + 1))
            n_done += n * per
        return Schedule(np.concatenate(pieces), np.asarray(updates, dtype=int))

    def step_times(self, dt_max: float | None = None) -> np.ndarray:
        """(n_steps,) s: the end time of every step of a run."""
        return self.schedule(dt_max).times[1:]

    def laser_power(self, t: float) -> float:
        """W delivered at time ``t`` (s): ``P`` (or ``P(t)``) while a pulse is on, else 0.

        Pulse ``i`` (0-based) is on during ``[i T, i T + duration_on)`` with period
        ``T = duration_on + duration_off``, MCmatlab's meaning of ``n_pulses``.
        """
        period = self.duration_on + self.duration_off
        if t < 0 or t >= self.n_pulses * period or (t % period) >= self.duration_on:
            return 0.0
        return self.peak_power(t)

    def mean_laser_power(self, t0: float, t1: float) -> float:
        """W averaged over ``[t0, t1)`` (s): :meth:`laser_power` integrated over the pulses'
        on-times in the interval, over its length. A step that a pulse starts or ends in
        gets the energy the laser delivers in it, not the power at its middle (which was
        up to half a step of power off at each edge). Within one pulse or one pause, the
        power at the middle, ``laser_power(t0 + (t1 - t0) / 2)``; a callable ``P`` is taken
        at the middle of each on-time."""
        t0, t1 = float(t0), float(t1)
        if not t1 > t0:
            return self.laser_power(t0)
        period = self.duration_on + self.duration_off
        first = max(0, math.floor(t0 / period))
        last = min(self.n_pulses - 1, math.floor(t1 / period))
        windows = [(max(t0, i * period), min(t1, i * period + self.duration_on))
                   for i in range(first, last + 1)]
        windows = [(a, b) for a, b in windows if b > a]
        if not windows:
            return 0.0
        if windows == [(t0, t1)]:
            return self.laser_power(t0 + 0.5 * (t1 - t0))
        energy = sum((b - a) * self.peak_power(a + 0.5 * (b - a)) for a, b in windows)
        return energy / (t1 - t0)

    def peak_power(self, t: float) -> float:
        """W of the laser when on at ``t`` (s): what FR-dependent media see (MCmatlab's MC.P).

        A callable ``P`` is checked at every call (a NaN would turn every temperature to
        NaN without a word): a value that is not a finite number in [0, 1e6] W raises
        ValueError naming ``HS.P``, the time and the value."""
        if not callable(self.P):
            return float(self.P)
        value = self.P(t)
        if isinstance(value, np.ndarray) and value.shape == ():  # np.interp of a scalar
            value = value.item()
        try:
            return check_number(f"HS.P(t) at t = {t:g} s", value, lo=0.0, hi=LIMITS["P"])
        except ValueError as err:
            raise ValueError(f"{err} (HS.P is a function of time: it must return W)") from None
