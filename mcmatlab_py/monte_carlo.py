"""Python layer of the Monte Carlo: validate once, build arrays, run the kernel in rounds."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numba
import numpy as np

from . import _mc_kernel as K
from ._strict import NotBuiltError
from .media_bins import optical_media_properties
from .progress import Progress

__all__ = [
    "MCResult",
    "batch_range",
    "optical_arrays",
    "run_monte_carlo",
    "simulate",
    "store_results",
]


@dataclass
class MCResult:
    """Raw totals of a Monte Carlo run, before they are written into ``model.MC``.

    ``absorbed`` is (nx, ny, nz) absorbed weight (in launched-packet units), ``tally``
    the fixed-point totals indexed by the ``T_*`` constants of the kernel module.
    """

    absorbed: np.ndarray
    tally: np.ndarray
    n_photons: int
    kernel_seconds: float
    kernel_cpu_seconds: float = 0.0  #: process CPU time spent in the kernel (all threads)


def optical_arrays(media, wavelength: float | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(mua, mus, g, n) arrays of a list of media at ``wavelength`` (nm), float64.

    One value per medium: media that depend on FR, T or FD are binned by
    :func:`mcmatlab_py.media_bins.optical_media_properties` (as ``run_monte_carlo`` does).
    """
    for m in media:
        if m.is_state_dependent:
            raise NotBuiltError(
                f"Medium({m.name!r}) depends on FR, T or FD: only run_monte_carlo splits such "
                "media into sub-media; MCmatlab's coupled FR/T/FD iteration is not built yet")
    return tuple(np.array([m.value(f, wavelength) for m in media], dtype=np.float64)
                 for f in ("mua", "mus", "g", "n"))


def simulate(G, MC, M: np.ndarray, mua, mus, g, nref, *, seed: int, n_photons: int | None,
             time_limit_s: float | None = None, label: str = "Monte Carlo",
             client=None) -> MCResult:
    """Run the kernel on a validated geometry; the medium map and properties are given.

    Exactly one of ``n_photons`` and ``time_limit_s`` is used (``n_photons`` wins). With a
    ``dask.distributed`` ``client`` the photon batches are split into ranges, one task
    each, and the integer tallies summed: the same numbers as here.
    """
    if client is not None:
        return _simulate_distributed(G, MC, M, mua, mus, g, nref, seed=seed,
                                     n_photons=n_photons, client=client, label=label)
    n_threads = min(MC.n_threads or numba.get_num_threads(), numba.config.NUMBA_NUM_THREADS)
    n_slots = n_threads  # one worker per thread, each with its own tally rows
    bs = MC.batch_size
    n_total = n_photons if n_photons is not None else np.iinfo(np.int64).max // 4
    n_batches = -(-n_total // bs) if n_photons is not None else None
    args = _kernel_args(G, MC, M, mua, mus, g, nref, seed, n_total)
    nx, ny, nz = M.shape
    acc = np.zeros((n_slots, args[0].size), dtype=np.int64)
    # rows padded to 512 bytes so that threads do not share cache lines
    tally = np.zeros((n_slots, 64), dtype=np.int64)

    old_threads = numba.get_num_threads()
    numba.set_num_threads(n_threads)
    try:
        K.run_batches(*args, 0, 0, acc, tally)  # compile (or load from cache) outside timing
        total = n_batches if n_batches is not None else time_limit_s
        bar = Progress(total, label, enabled=MC.progress)
        done = 0
        kernel_s = 0.0
        kernel_cpu = 0.0
        per_round = 8 * n_slots
        while True:
            stop = done + per_round if n_batches is None else min(done + per_round, n_batches)
            t0 = time.perf_counter()
            c0 = time.process_time()
            K.run_batches(*args, done, stop, acc, tally)
            dt = time.perf_counter() - t0
            kernel_cpu += time.process_time() - c0
            kernel_s += dt
            n_round = stop - done
            done = stop
            bar.update(done if n_batches is not None else kernel_s,
                       f"{done * bs / max(kernel_s, 1e-9):.3g} photons/s")
            if n_batches is not None and done >= n_batches:
                break
            if n_batches is None and kernel_s >= time_limit_s:
                break
            # aim at rounds of about half a second, to keep the bar and the clock responsive
            rate = n_round / max(dt, 1e-6)  # batches per second
            per_round = int(min(max(n_slots, 0.5 * rate), 50 * per_round))
            per_round = max(n_slots, per_round - per_round % n_slots)
            if n_batches is None:
                remaining = time_limit_s - kernel_s
                per_round = max(n_slots, min(per_round, int(rate * remaining) + n_slots))
        bar.close()
    finally:
        numba.set_num_threads(old_threads)
    n_done = n_photons if n_photons is not None else done * bs
    absorbed = acc.sum(axis=0).reshape(nx, ny, nz) / K.W_ONE
    return MCResult(absorbed=absorbed, tally=tally.sum(axis=0)[: K.N_TALLY], n_photons=int(n_done),
                    kernel_seconds=kernel_s, kernel_cpu_seconds=kernel_cpu)


def _kernel_args(G, MC, M, mua, mus, g, nref, seed, n_total):
    from .light_source import source_arrays
    from .optics import interface_normals, phase_function_tables

    nx, ny, nz = M.shape
    source = source_arrays(MC.light_source, G, getattr(MC, "source_distribution", None))
    phase = phase_function_tables(G.media, _parent_media(G, MC, len(mua)),
                                  getattr(MC, "wavelength", None))
    if np.all(phase[0] < 0):
        phase = (None, phase[1])  # Henyey-Greenstein only: the kernel is compiled without tables
    Mf = np.ascontiguousarray(M, dtype=np.int32).ravel()
    uniform = int(Mf[0]) if np.all(Mf == Mf[0]) else -1
    normals = np.zeros(3, dtype=np.float32)
    smoothing = getattr(MC, "smoothing_length_scale", None)
    use_normals = (not MC.matched_interfaces and smoothing is not None
                   and np.unique(nref[np.unique(Mf)]).size > 1)
    if use_normals:
        normals = interface_normals(np.asarray(M), nref, (G.dx, G.dy, G.dz), smoothing)
    return (Mf, mua, mus, g, nref, uniform, nx, ny, nz, G.dx, G.dy, G.dz,
            int(MC.boundary_type), float(MC.n_outside), bool(MC.matched_interfaces),
            bool(MC.russian_roulette), float(MC.weight_threshold), float(MC.roulette_chance),
            *source, *phase, normals, bool(use_normals), np.uint64(seed), MC.batch_size, n_total)


def _parent_media(G, MC, n_sub: int) -> np.ndarray:
    """(n_sub,) index in ``G.media`` of each (sub-)medium the kernel runs on."""
    if n_sub == len(G.media):
        return np.arange(n_sub)
    props = getattr(MC, "media_properties", None)
    parent = getattr(props, "parent", None)
    if parent is not None and len(parent) == n_sub:
        return np.asarray(parent)
    if any(getattr(m, "custom_phase_func", None) is not None for m in G.media):
        raise ValueError("custom phase functions need the sub-media's parents "
                         "(MC.media_properties) when media are split into sub-media")
    return np.zeros(n_sub, dtype=np.int64)  # Henyey-Greenstein everywhere: parents unused


def batch_range(args: tuple, batches: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, float]:
    """Batches ``[start, stop)`` of a run on this machine's threads: summed absorbed weights
    (nvox,) and tallies (64,), int64 fixed point, and the kernel seconds (a task body)."""
    n_threads = numba.get_num_threads()
    acc = np.zeros((n_threads, args[0].size), dtype=np.int64)
    tally = np.zeros((n_threads, 64), dtype=np.int64)
    K.run_batches(*args, 0, 0, acc, tally)  # compile or load from the cache first
    t0 = time.perf_counter()
    K.run_batches(*args, batches[0], batches[1], acc, tally)
    return acc.sum(axis=0), tally.sum(axis=0), time.perf_counter() - t0


def _simulate_distributed(G, MC, M, mua, mus, g, nref, *, seed, n_photons, client,
                          label) -> MCResult:
    import functools

    from .distributed import run_tasks, split_range

    if n_photons is None:
        raise ValueError("MC.simulation_time_requested cannot be used on a cluster: give "
                         "MC.n_photons_requested")
    n_batches = -(-n_photons // MC.batch_size)
    workers = max(1, len(client.scheduler_info().get("workers", {})))
    ranges = split_range(n_batches, 4 * workers)  # a few tasks per worker: load balance
    args = _kernel_args(G, MC, M, mua, mus, g, nref, seed, n_photons)
    t0 = time.perf_counter()
    parts = run_tasks(functools.partial(batch_range, args), ranges, client=client,
                      progress=MC.progress, label=label)
    wall = time.perf_counter() - t0
    acc = np.sum([p[0] for p in parts], axis=0)
    tally = np.sum([p[1] for p in parts], axis=0)
    return MCResult(absorbed=acc.reshape(M.shape) / K.W_ONE, tally=tally[: K.N_TALLY],
                    n_photons=int(n_photons), kernel_seconds=wall,
                    kernel_cpu_seconds=float(sum(p[2] for p in parts)))


def run_monte_carlo(model, client=None) -> None:
    """Validate ``model.G`` and ``model.MC``, run the Monte Carlo, and fill ``model.MC``."""
    G, MC = model.G, model.MC
    M_raw = G.medium_map()  # validates G
    MC.validate(G)
    # media at MC.wavelength; media depending on FR, T, FD split into sub-media (new M)
    props = optical_media_properties(G.media, M_raw, MC.wavelength, MC.FR, MC.T, MC.FD)
    M, mua, mus, g, nref = props.M, props.mua, props.mus, props.g, props.n
    seed = MC.seed if MC.seed is not None else int(np.random.SeedSequence().entropy % 2**63)
    n_photons = MC.n_photons_requested
    time_limit = None
    if n_photons is None:
        minutes = MC.simulation_time_requested if MC.simulation_time_requested else 0.1
        time_limit = 60.0 * minutes
    MC.media_properties = props  # before the run: the kernel maps sub-media to media with it
    res = simulate(G, MC, M, mua, mus, g, nref, seed=seed, n_photons=n_photons,
                   time_limit_s=time_limit, client=client)
    store_results(MC, res, M, mua, G.dx * G.dy * G.dz)
    MC.seed_used = seed
    MC.M = M


def store_results(MC, res: MCResult, M: np.ndarray, mua: np.ndarray, dV: float) -> None:
    """Normalise the raw totals of ``res`` into the MCmatlab outputs of ``MC``."""
    launched = res.tally[K.T_LAUNCHED] / K.W_ONE  # = n_photons

    def frac(i):
        return float(res.tally[i] / K.W_ONE / launched)

    MC.NA = res.absorbed / (launched * dV)
    mua_map = mua[M]
    with np.errstate(divide="ignore", invalid="ignore"):
        MC.NFR = np.where(mua_map > 0, MC.NA / mua_map, 0.0)
    MC.absorbed_fraction = float(res.absorbed.sum() / launched)
    MC.specular_reflectance = frac(K.T_SPECULAR)
    MC.escaped = {"top": frac(K.T_TOP), "bottom": frac(K.T_BOTTOM), "sides": frac(K.T_SIDES)}
    MC.absorbed_outside_fraction = frac(K.T_OUTSIDE_ABSORBED)
    MC.killed_fraction = frac(K.T_KILLED)
    MC.missed_fraction = frac(K.T_MISSED)
    MC.roulette_gain_fraction = frac(K.T_ROULETTE)
    MC.n_photons = res.n_photons
    MC.simulation_time = res.kernel_seconds
    MC.photons_per_second = res.n_photons / max(res.kernel_seconds, 1e-12)
    # cores actually used by the kernel: below n_threads when the machine is busy
    MC.cores_used = res.kernel_cpu_seconds / max(res.kernel_seconds, 1e-12)
