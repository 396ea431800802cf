"""Python layer of the Monte Carlo: validate once, build arrays, run the kernel in rounds."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np

from . import _mc_kernel as K
from . import _mc_outputs as KO
from ._mc_tally import fluence_scale
from ._strict import NotBuiltError
from .broadband import is_broadband, run_broadband
from .budget import warn_long_run
from .mc_outputs import OutputSpec, output_spec, store_outputs
from .media_bins import optical_media_properties
from .model import MAX_PHOTONS
from .progress import Progress
from .safety import medium_kinds, safety_distances

__all__ = [
    "FLUSH_PHOTONS",
    "HostRun",
    "MCResult",
    "THIN",
    "WideSums",
    "batch_range",
    "gpu_available",
    "kernel_safety",
    "optical_arrays",
    "run_monte_carlo",
    "run_simulation",
    "run_validated",
    "simulate",
    "store_results",
    "track_media",
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
    spec: OutputSpec | None = None  #: the optional outputs requested
    ext: np.ndarray | None = None  #: (n_ext,) their fixed-point tallies, summed over workers
    paths: np.ndarray | None = None  #: example paths (n_paths, PATH_LEN, 4), local cm
    path_n: np.ndarray | None = None  #: vertices per example path
    #: (n_media,) bool: the media whose fluence rate comes from the track length, or None
    track: np.ndarray | None = None
    #: (nx, ny, nz) weight x cm (launched-packet units) travelled in each voxel of those media
    track_length: np.ndarray | None = None


#: packets between two moves of the kernels' int64 fixed-point sums into :class:`WideSums`.
#: int64 holds 2^63 / W_ONE = 2^27 (1.3e8) launched packets of weight ``W_ONE = 2^36``;
#: moving every 2^25 keeps what accumulates (at most twice that) 4x below the limit
FLUSH_PHOTONS = 2**25
_LOW = np.int64(2**32 - 1)


class WideSums:
    """Exact totals of int64 fixed-point arrays past int64's range (long runs: a GPU passes
    2^27 packets in about a second), each kept as two int64 arrays, the high and the low
    32 bits. :meth:`value` is the exact total rounded once to float64: the same bits as
    converting an int64 total that did not overflow, so runs below the limit are unchanged.
    """

    def __init__(self):
        self.hi: dict[str, np.ndarray] = {}
        self.lo: dict[str, np.ndarray] = {}

    def _put(self, name, hi, lo) -> None:
        if name in self.hi:
            hi, lo = self.hi[name] + hi, self.lo[name] + lo
        self.hi[name] = hi + (lo >> 32)
        self.lo[name] = lo & _LOW

    def add(self, name: str, v: np.ndarray) -> None:
        """Add an int64 array (a sum below 2^62 in magnitude)."""
        v = np.asarray(v, dtype=np.int64)
        self._put(name, v >> 32, v & _LOW)

    def merge(self, other: WideSums) -> None:
        for name in other.hi:
            self._put(name, other.hi[name], other.lo[name])

    def value(self, name: str) -> np.ndarray:
        """The total, float64 (hi 2^32 is exact, one rounding in the addition)."""
        return self.hi[name].astype(np.float64) * 4294967296.0 + self.lo[name]


#: media in which a packet crossing a voxel (its shortest side) interacts with a chance of
#: about THIN or less, and media that do not absorb, get their fluence rate from the track
#: length, as MCmatlab's continuous absorption gives it; NA / mua there would rest on a few
#: interactions (in air on none: a map of zeros). Elsewhere NFR = NA / mua, as before
THIN = 0.1


def track_media(args: tuple, spec: OutputSpec | None = None, enabled: bool = True
                ) -> np.ndarray | None:
    """(n_media,) bool: the media present in the grid of the kernel arguments ``args`` whose
    fluence is tallied along the path; None if none is, if not ``enabled``
    (``MC.calc_normalized_fluence_rate``), or if deposition criteria apply (they filter
    ``NA`` packet by packet, and the track-length tally does not follow them)."""
    if not enabled or (spec is not None and spec.active and spec.oi[KO.OI_DC] == 1):
        return None
    M, mua, mus = args[0], args[1], args[2]
    dmin = min(args[9], args[10], args[11])
    present = np.bincount(np.asarray(M).ravel(), minlength=len(mua)) > 0
    thin = present & ((mua <= 0.0) | ((mua + mus) * dmin < THIN))
    return thin if thin.any() else None


def track_length(sums: WideSums, track, d: tuple, shape: tuple) -> np.ndarray | None:
    """(shape) weight x cm (launched-packet units) travelled in each voxel of the tracked
    media, from the ``"flu"`` total of ``sums``; ``d`` the voxel sides (dx, dy, dz) in cm."""
    if track is None:
        return None
    return sums.value("flu").reshape(shape) / (fluence_scale(*d) * K.W_ONE)


def kernel_safety(args: tuple, spec: OutputSpec | None = None) -> np.ndarray:
    """(nvox,) float32 cm: the safety distances (:mod:`mcmatlab_py.safety`) of the grid of
    the kernel arguments ``args``; where deposition criteria count the transitions between
    media, each medium is its own kind. A grid of one medium needs none: ``inf``."""
    M = args[0]
    if args[5] >= 0:
        return np.full(M.size, np.inf, dtype=np.float32)
    by_medium = spec is not None and spec.active and spec.oi[KO.OI_DC] == 1
    kinds = medium_kinds(*args[1:5], args[22], by_medium=by_medium)
    return safety_distances(M.reshape(args[6:9]), kinds, args[9:12])


class HostRun:
    """The per-worker int64 accumulators of a run on this machine's threads, moved into
    :class:`WideSums` every :data:`FLUSH_PHOTONS` packets. ``args``: the kernel's
    arguments (:func:`_kernel_args`); ``n_slots`` workers; ``bs`` packets per batch;
    ``track``: tally the track length in thin media (:func:`track_media`)."""

    def __init__(self, args: tuple, n_slots: int, spec: OutputSpec, bs: int, track: bool = True):
        self.args, self.bs = args, bs
        self.acc = np.zeros((n_slots, args[0].size), dtype=np.int64)
        # rows padded to 512 bytes so that threads do not share cache lines
        self.tally = np.zeros((n_slots, 64), dtype=np.int64)
        self.out = spec.arrays(n_slots)
        self.track = track_media(args, spec, track)
        if self.track is not None:  # the tally cuts every path at the voxel faces
            self.args = args = (*args[:5], -1, *args[6:])
        self.flu = np.zeros((n_slots, args[0].size if self.track is not None else 1),
                            dtype=np.int64)
        self.safe = kernel_safety(args, spec)
        self.sums = WideSums()
        self.pending = 0  #: packets in the int64 accumulators since they were last moved
        self._run(0, 0)  # compile or load first

    def _run(self, a: int, b: int) -> None:
        K.run_batches(*self.args, a, b, self.acc, self.tally, *self.out, self.track, self.flu,
                      self.safe)

    def run(self, start: int, stop: int) -> None:
        """Batches ``[start, stop)``, in chunks of at most FLUSH_PHOTONS packets."""
        step = max(1, FLUSH_PHOTONS // self.bs)
        for a in range(start, stop, step):
            b = min(a + step, stop)
            self._run(a, b)
            self.pending += (b - a) * self.bs
            if self.pending >= FLUSH_PHOTONS:
                self.flush()

    def flush(self) -> None:
        named = [("acc", self.acc), ("tally", self.tally), ("ext", self.out[3]),
                 ("flu", self.flu)]
        for name, arr in named:
            self.sums.add(name, arr.sum(axis=0))
            arr[:] = 0
        self.pending = 0

    def collected(self) -> int:
        """Packets collected so far (MCmatlab's requestCollectedPhotons)."""
        got = int(self.out[3][:, KO.EXT_COLLECTED].sum())
        if "ext" in self.sums.hi:
            got += int(self.sums.value("ext")[KO.EXT_COLLECTED])
        return got

    def totals(self) -> WideSums:
        self.flush()
        return self.sums


def optical_arrays(media, wavelength: float | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(mua, mus, g, n) arrays of a list of media at ``wavelength`` (nm), float64.

    One value per medium: media that depend on FR, T or FD are binned by
    :func:`mcmatlab_py.media_bins.optical_media_properties` (as ``run_monte_carlo`` does).
    """
    for m in media:
        if m.is_state_dependent:
            raise NotBuiltError(
                f"Medium({m.name!r}) depends on FR, T or FD: one value per medium cannot "
                "hold it; run_monte_carlo splits such media into sub-media (and "
                "mcmatlab_py.frt couples them with the heat simulation)")
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
    if getattr(MC, "use_gpu", False):
        if client is not None:
            raise NotBuiltError("MC.use_gpu with a dask client (a cluster of GPUs) is not built")
        return _simulate_gpu(G, MC, M, mua, mus, g, nref, seed=seed, n_photons=n_photons,
                             time_limit_s=time_limit_s, label=label)
    if client is not None:
        return _simulate_distributed(G, MC, M, mua, mus, g, nref, seed=seed,
                                     n_photons=n_photons, client=client, label=label)
    n_threads = min(MC.n_threads or numba.get_num_threads(), numba.config.NUMBA_NUM_THREADS)
    n_slots = n_threads  # one worker per thread, each with its own tally rows
    bs = MC.batch_size
    spec = output_spec(G, MC, len(mua), _parent_media(G, MC, len(mua)))
    collect_target = n_photons if getattr(MC, "request_collected_photons", False) else None
    if collect_target is not None:
        n_photons = None  # run until enough packets are collected
        time_limit_s = 60.0 * MC.simulation_time_requested if MC.simulation_time_requested \
            else None
    n_total = n_photons if n_photons is not None else MAX_PHOTONS
    n_batches = -(-n_total // bs) if n_photons is not None else None
    args = _kernel_args(G, MC, M, mua, mus, g, nref, seed, n_total)

    old_threads = numba.get_num_threads()
    numba.set_num_threads(n_threads)
    try:
        # compiles (or loads) outside the timing
        host = HostRun(args, n_slots, spec, bs, MC.calc_normalized_fluence_rate)
        if collect_target is not None:
            done, kernel_s, kernel_cpu = _run_until_collected(host, collect_target,
                                                              time_limit_s)
            n_photons = done * bs
            n_batches = done
        total = n_batches if n_batches is not None else time_limit_s
        bar = Progress(total, label, enabled=MC.progress and collect_target is None)
        done = 0 if collect_target is None else n_batches
        if collect_target is None:
            kernel_s = 0.0
            kernel_cpu = 0.0
        per_round = 8 * n_slots
        while done < (n_batches if n_batches is not None else np.inf):
            stop = done + per_round if n_batches is None else min(done + per_round, n_batches)
            t0 = time.perf_counter()
            c0 = time.process_time()
            host.run(done, stop)
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
            if n_batches is not None and done == n_round:  # the estimate, once, up front
                warn_long_run((n_batches - done) / rate,
                              f"MC.n_photons_requested = {n_total:.3g}",
                              f"{rate * bs:.3g} photons/s on the first {done * bs:.3g}",
                              "request fewer photons, or set MC.simulation_time_requested")
            per_round = int(min(max(n_slots, 0.5 * rate), 50 * per_round))
            per_round = max(n_slots, per_round - per_round % n_slots)
            if n_batches is None:
                remaining = time_limit_s - kernel_s
                per_round = max(n_slots, min(per_round, int(rate * remaining) + n_slots))
        bar.close()
    finally:
        numba.set_num_threads(old_threads)
    n_done = n_photons if n_photons is not None else done * bs
    sums = host.totals()
    return MCResult(absorbed=sums.value("acc").reshape(M.shape) / K.W_ONE,
                    tally=sums.value("tally")[: K.N_TALLY], n_photons=int(n_done),
                    kernel_seconds=kernel_s, kernel_cpu_seconds=kernel_cpu, spec=spec,
                    ext=sums.value("ext"), paths=host.out[4], path_n=host.out[5],
                    track=host.track,
                    track_length=track_length(sums, host.track, (G.dx, G.dy, G.dz), M.shape))


def gpu_available() -> bool:
    """Whether ``MC.use_gpu = True`` can run here: the ``numba-cuda`` package (the ``gpu``
    extra) and a CUDA GPU, or numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1`` set before
    ``numba.cuda`` is first imported)."""
    try:
        from numba import cuda
    except ImportError:
        return False
    return bool(cuda.is_available())


def _simulate_gpu(G, MC, M, mua, mus, g, nref, *, seed, n_photons, time_limit_s,
                  label) -> MCResult:
    """The plain run on a CUDA GPU (:mod:`mcmatlab_py._mc_cuda`): the same totals as
    :func:`simulate`, statistically (each CUDA thread runs its own random stream)."""
    spec = output_spec(G, MC, len(mua), _parent_media(G, MC, len(mua)))
    if spec.active:
        raise NotBuiltError(
            "MC.use_gpu runs the plain Monte Carlo only (NA, NFR, the escaped and absorbed "
            "fractions): the optional outputs (normalized irradiance, far field, light "
            "collector, radial bins, deposition criteria, example paths) are not built for the "
            "GPU; set MC.use_gpu = False for them")
    if MC.n_outside is None and not MC.matched_interfaces:
        raise NotBuiltError(
            "MC.use_gpu with MC.n_outside = None (MCmatlab's faces) is not built for the GPU: "
            "set MC.n_outside to a refractive index, or MC.use_gpu = False")
    if not gpu_available():
        raise RuntimeError(
            "MC.use_gpu = True needs numba-cuda (pip install 'tissue-enkf[gpu]') and an NVIDIA "
            "GPU with its driver; none was found (numba.cuda.is_available() is False). "
            "Set MC.use_gpu = False to run on the CPU")
    from numba import cuda

    from . import _mc_cuda as KC

    if not numba.config.ENABLE_CUDASIM:
        cuda.select_device(int(MC.gpu_device))
    n_total = n_photons if n_photons is not None else MAX_PHOTONS
    args = list(_kernel_args(G, MC, M, mua, mus, g, nref, seed, n_total))
    if args[22] is None:  # phase_idx: the CUDA kernel takes an array (-1: Henyey-Greenstein)
        args[22] = np.full(len(mua), -1, dtype=np.int32)
    per = KC.PHOTONS_PER_THREAD
    args[27] = per
    track = track_media(args, spec, MC.calc_normalized_fluence_rate)
    if track is not None:
        args[5] = -1  # uniform_medium: the track-length tally cuts paths at voxel faces
    args = [cuda.to_device(a) if isinstance(a, np.ndarray) else a for a in args]
    nvox = M.size
    acc = cuda.to_device(np.zeros(nvox, dtype=np.int64))
    tally = cuda.to_device(np.zeros(K.N_TALLY, dtype=np.int64))
    flu = cuda.to_device(np.zeros(nvox if track is not None else 1, dtype=np.int64))
    tracked = cuda.to_device(track if track is not None else np.zeros(len(mua), dtype=np.bool_))
    n_streams = -(-n_total // per) if n_photons is not None else None
    tpb = KC.THREADS_PER_BLOCK
    # compile outside the timed rounds (no streams: every thread returns at once); a
    # time-limited run would otherwise spend its minutes on the JIT (about 15 s on an H200)
    try:
        KC.transport_streams[1, tpb](*args, 0, 0, acc, tally, tracked, flu)
    except AttributeError as e:  # numba-cuda 0.30 compiles against numpy's np.row_stack
        if "row_stack" not in str(e):
            raise
        raise RuntimeError(
            f"MC.use_gpu: numba-cuda cannot compile the kernel with numpy {np.__version__} "
            f"({e}; numpy 2.5 removed np.row_stack): install numpy < 2.5 "
            "(pip install 'tissue-enkf[gpu]' pins it) or a numba-cuda that supports it") from e
    cuda.synchronize()
    bar = Progress(n_streams if n_streams is not None else time_limit_s, label,
                   enabled=MC.progress)
    sums, pending = WideSums(), 0
    named = [("acc", acc), ("tally", tally)] + ([("flu", flu)] if track is not None else [])
    zeros = {name: np.zeros(arr.shape, dtype=np.int64) for name, arr in named}

    def flush():  # move the int64 sums into the wide ones before they can overflow
        for name, arr in named:
            sums.add(name, arr.copy_to_host())
            arr.copy_to_device(zeros[name])

    max_streams = max(tpb, FLUSH_PHOTONS // per)
    done, per_round = 0, 64 * tpb
    kernel_s = kernel_cpu = 0.0
    while True:
        per_round = min(per_round, max_streams)
        todo = per_round if n_streams is None else min(per_round, n_streams - done)
        t0, c0 = time.perf_counter(), time.process_time()
        KC.transport_streams[-(-todo // tpb), tpb](*args, done, todo, acc, tally, tracked, flu)
        cuda.synchronize()
        dt = time.perf_counter() - t0
        kernel_s += dt
        kernel_cpu += time.process_time() - c0
        done += todo
        pending += todo * per
        if pending >= FLUSH_PHOTONS:
            flush()
            pending = 0
        bar.update(done if n_streams is not None else kernel_s,
                   f"{min(done * per, n_total) / max(kernel_s, 1e-9):.3g} photons/s")
        if (n_streams is not None and done >= n_streams) or (
                n_streams is None and kernel_s >= time_limit_s):
            break
        # rounds of about half a second
        per_round = int(min(max(tpb, 0.5 * todo / max(dt, 1e-6)), 16 * per_round))
        if n_streams is None:
            per_round = min(per_round, int((time_limit_s - kernel_s) * todo / max(dt, 1e-6)) + tpb)
    bar.close()
    flush()
    n_done = n_photons if n_photons is not None else done * per
    length = track_length(sums, track, (G.dx, G.dy, G.dz), M.shape)
    return MCResult(absorbed=sums.value("acc").reshape(M.shape) / K.W_ONE,
                    tally=sums.value("tally"), n_photons=int(n_done), kernel_seconds=kernel_s,
                    kernel_cpu_seconds=kernel_cpu, spec=spec, track=track, track_length=length)


def _run_until_collected(host: HostRun, target: int, time_limit_s):
    """MCmatlab's requestCollectedPhotons: run batches until ``target`` packets are collected.

    The size of each round depends only on the counts collected so far, never on the
    clock or the thread count, so a seed still gives the same result on any machine
    (unless ``time_limit_s`` stops the run first). Returns (batches, seconds, CPU seconds).
    """
    done, per_round = 0, 16
    kernel_s = kernel_cpu = 0.0
    while True:
        t0, c0 = time.perf_counter(), time.process_time()
        host.run(done, done + per_round)
        kernel_s += time.perf_counter() - t0
        kernel_cpu += time.process_time() - c0
        done += per_round
        got = host.collected()
        if got >= target or (time_limit_s is not None and kernel_s >= time_limit_s):
            return done, kernel_s, kernel_cpu
        # aim 10% past the target at the rate seen so far; at most 4x the batches done
        rate = got / done
        need = (target - got) / rate * 1.1 if got else 4 * done
        per_round = int(min(max(math.ceil(need), 1), 4 * done))
        if done * host.bs > 10**12:
            raise RuntimeError(f"MC.request_collected_photons: {got} of {target} packets "
                               f"collected after {done * host.bs} launched; check the collector")


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
            # n_outside None (MCmatlab's faces: no Fresnel at the cuboid) reaches the kernels as 0
            int(MC.boundary_type), float(MC.n_outside or 0.0), bool(MC.matched_interfaces),
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


def batch_range(args: tuple, batches: tuple[int, int], spec: OutputSpec | None = None,
                track: bool = True) -> tuple:
    """Batches ``[start, stop)`` of a run on this machine's threads (a task body): the
    :class:`WideSums` of the absorbed weights ``acc`` (nvox,), the tallies ``tally`` (64,)
    and the optional outputs' tallies ``ext`` (n_ext,), fixed point; the kernel seconds;
    the example paths and their lengths."""
    if spec is None:
        spec = OutputSpec(None, np.zeros(KO.OF_SIZE), np.zeros(1, dtype=np.bool_), 1, 0)
    host = HostRun(args, numba.get_num_threads(), spec, int(args[27]), track)
    t0 = time.perf_counter()
    host.run(batches[0], batches[1])
    return host.totals(), time.perf_counter() - t0, host.out[4], host.out[5]


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
    if getattr(MC, "request_collected_photons", False):
        raise NotBuiltError("MC.request_collected_photons is not built for runs on a cluster")
    args = _kernel_args(G, MC, M, mua, mus, g, nref, seed, n_photons)
    spec = output_spec(G, MC, len(mua), _parent_media(G, MC, len(mua)))
    t0 = time.perf_counter()
    parts = run_tasks(functools.partial(batch_range, args, spec=spec,
                                        track=MC.calc_normalized_fluence_rate),
                      ranges, client=client,
                      progress=MC.progress, label=label)
    wall = time.perf_counter() - t0
    sums = WideSums()
    for p in parts:
        sums.merge(p[0])
    # each example path was written by the one task that ran its packet
    path_n = np.max([p[3] for p in parts], axis=0)
    paths = parts[0][2].copy()
    for p in parts[1:]:
        rows = p[3] > 0
        paths[rows] = p[2][rows]
    track = track_media(args, spec, MC.calc_normalized_fluence_rate)
    length = track_length(sums, track, (G.dx, G.dy, G.dz), M.shape)
    return MCResult(absorbed=sums.value("acc").reshape(M.shape) / K.W_ONE,
                    tally=sums.value("tally")[: K.N_TALLY], n_photons=int(n_photons),
                    kernel_seconds=wall, kernel_cpu_seconds=float(sum(p[1] for p in parts)),
                    spec=spec, ext=sums.value("ext"), paths=paths, path_n=path_n,
                    track=track, track_length=length)


def run_monte_carlo(model, client=None) -> None:
    """Validate ``model.G`` and ``model.MC``, run the Monte Carlo, and fill ``model.MC``."""
    run_simulation(model.G, model.MC, client=client)


def run_simulation(G, MC, *, client=None, power: float = 1.0) -> None:
    """Validate ``G`` and ``MC`` (a :class:`~mcmatlab_py.model.MonteCarloSimulation` or its
    fluorescence subclass), run the Monte Carlo, and fill ``MC``.

    ``power``: W launched per W the outputs are normalised to. The maps (``NA``, ``NFR``,
    ``NI_*``, far field, collector image, MCML bins) are multiplied by it; the fractions
    (``absorbed_fraction``, ``escaped``, ...) stay fractions of the launched power. The
    fluorescence run gives the fluorescence emitted per W of incident excitation, so its maps
    are per W incident as MCmatlab's. An array ``MC.wavelength`` runs each wavelength in
    turn (:mod:`mcmatlab_py.broadband`).
    """
    M_raw = G.medium_map()  # validates G
    MC.validate(G)
    if is_broadband(MC.wavelength):
        run_broadband(G, MC, M_raw, client=client, power=power)
        return
    MC.spectrum = MC.n_photons_per_wavelength = None  # a broadband run's, if MC held one
    run_validated(G, MC, M_raw, client=client, power=power)


def run_validated(G, MC, M_raw: np.ndarray, *, client=None, power: float = 1.0) -> None:
    """:func:`run_simulation` of one wavelength after ``G`` and ``MC`` were validated."""
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
    if power != 1.0:
        MC.NA = MC.NA * power
        MC.NFR = MC.NFR * power
    if res.spec is not None and res.spec.active:
        store_outputs(G, MC, res.spec, res.ext, res.paths, res.path_n,
                      res.tally[K.T_LAUNCHED] / K.W_ONE / power)
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
    if res.track is not None:  # thin media: the fluence rate from the track length
        MC.NFR = np.where(res.track[M], res.track_length / (launched * dV), MC.NFR)
    # with deposition criteria NA holds only what met them; the balance counts all
    MC.absorbed_fraction = float((res.absorbed.sum() + frac(K.T_ABSORBED_EXCLUDED) * launched)
                                 / launched)
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
