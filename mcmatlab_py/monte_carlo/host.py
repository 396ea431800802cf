"""The host side of the Monte Carlo kernels: their arguments, the per-thread int64
accumulators of a run on this machine (:class:`HostRun`) and their exact totals past
int64's range (:class:`WideSums`), shared by the CPU, GPU, cluster and white runs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._strict import NotBuiltError
from . import _outputs as KO
from ._batches import run_batches
from ._tally import W_ONE, fluence_scale
from .outputs import OutputSpec
from .safety import delta_groups, medium_kinds, navigation_safety

__all__ = [
    "FLUSH_PHOTONS",
    "THIN",
    "HostRun",
    "MCResult",
    "WideSums",
    "kernel_args",
    "kernel_groups",
    "kernel_safety",
    "optical_arrays",
    "parent_media",
    "track_length",
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
    return sums.value("flu").reshape(shape) / (fluence_scale(*d) * W_ONE)


def kernel_groups(args: tuple, spec: OutputSpec | None = None, track=None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(kinds, group, majorant, merged)`` (n_media,) of the kernel arguments ``args``: the
    kinds of medium (:func:`mcmatlab_py.monte_carlo.safety.medium_kinds`) and their groups
    crossed by delta tracking (:func:`mcmatlab_py.monte_carlo.safety.delta_groups`), with
    ``track`` (:func:`track_media`) the media kept out of them, and with matched interfaces
    (``MC.matched_interfaces``) regardless of the refractive indices; where deposition
    criteria count the transitions between media, each medium is a kind and a group of its
    own."""
    M, mua, mus, nref = args[0], args[1], args[2], args[4]
    by_medium = spec is not None and spec.active and spec.oi[KO.OI_DC] == 1
    kinds = medium_kinds(*args[1:5], args[22], by_medium=by_medium)
    if by_medium or args[5] >= 0:  # counted transitions, or one medium: no groups
        return (kinds, kinds, np.asarray(mua, float) + np.asarray(mus, float),
                np.zeros(len(mua), bool))
    if args[14]:  # matched interfaces: the refractive indices do not act
        nref = np.ones(len(mua))
    present = np.bincount(np.asarray(M).ravel(), minlength=len(mua)) > 0
    return (kinds, *delta_groups(kinds, mua, mus, nref, present, track))


def kernel_safety(args: tuple, spec: OutputSpec | None = None, track=None,
                  groups: tuple | None = None) -> np.ndarray:
    """(nvox,) float32 cm: the signed safety distances of the general kernel
    (:func:`mcmatlab_py.monte_carlo.safety.navigation_safety`) of the grid of the kernel
    arguments ``args``, with the kinds and groups ``groups`` of :func:`kernel_groups`
    (computed if None). A grid of one medium needs none: ``inf``."""
    M = args[0]
    if args[5] >= 0:
        return np.full(M.size, np.inf, dtype=np.float32)
    kinds, group, _, merged = groups if groups is not None else kernel_groups(args, spec, track)
    return navigation_safety(M.reshape(args[6:9]), kinds, group, merged, args[9:12])


class HostRun:
    """The per-worker int64 accumulators of a run on this machine's threads, moved into
    :class:`WideSums` every :data:`FLUSH_PHOTONS` packets. ``args``: the kernel's
    arguments (:func:`kernel_args`); ``n_slots`` workers; ``bs`` packets per batch;
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
        groups = kernel_groups(args, spec, self.track)
        self.majorant = groups[2]
        self.safe = kernel_safety(args, spec, self.track, groups)
        self.sums = WideSums()
        self.pending = 0  #: packets in the int64 accumulators since they were last moved
        self._run(0, 0)  # compile or load first

    def _run(self, a: int, b: int) -> None:
        run_batches(*self.args, a, b, self.acc, self.tally, *self.out, self.track, self.flu,
                    self.safe, self.majorant)

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
    :func:`mcmatlab_py.geometry.media_bins.optical_media_properties` (as ``run_monte_carlo`` does).
    """
    for m in media:
        if m.is_state_dependent:
            raise NotBuiltError(
                f"Medium({m.name!r}) depends on FR, T or FD: one value per medium cannot "
                "hold it; run_monte_carlo splits such media into sub-media (and "
                "mcmatlab_py.frt couples them with the heat simulation)")
    return tuple(np.array([m.value(f, wavelength) for m in media], dtype=np.float64)
                 for f in ("mua", "mus", "g", "n"))


def kernel_args(G, MC, M, mua, mus, g, nref, seed, n_total):
    from ..light.source import source_arrays
    from .optics import interface_normals, phase_function_tables

    nx, ny, nz = M.shape
    source = source_arrays(MC.light_source, G, getattr(MC, "source_distribution", None))
    phase = phase_function_tables(G.media, parent_media(G, MC, len(mua)),
                                  getattr(MC, "wavelength", None))
    if np.all(phase[0] < 0):
        phase = (None, phase[1])  # Henyey-Greenstein only: the kernel is compiled without tables
    # one byte a voxel where it holds the media (the look-ups stay in the cache)
    Mf = np.ascontiguousarray(M, dtype=np.uint8 if len(mua) <= 256 else np.int32).ravel()
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


def parent_media(G, MC, n_sub: int) -> np.ndarray:
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
