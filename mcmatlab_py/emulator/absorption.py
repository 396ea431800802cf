"""The absorption emulator: NA(mua, mus) from a table of Monte Carlo runs, in microseconds.

The filter needs, for each of its N members at every sensor tick, the absorbed
power map of a homogeneous block for that member's (mua, mus). Running Monte
Carlo there is what Arnold & Fichera call the barrier to online use. Instead we
tabulate ``NA`` once on a log-spaced (mua, mus) grid and interpolate
``log NA`` with 4-point (cubic) Lagrange polynomials in ``log mua`` and ``log mus``
(error O(h^4) in the table spacing h). All table points use the same random
seed (common random numbers), so the table is smooth in (mua, mus) and the
interpolant does not jitter from one point to the next.

Outside the table the emulator raises ``ValueError`` (``out_of_range="error"``,
the default) or clamps to the table edge with a ``RuntimeWarning``
(``out_of_range="clamp"``); it never extrapolates silently.

:class:`DirectMonteCarloAbsorption` has the same call signature and runs direct
Monte Carlo per evaluation: the exact mode, for checking.
"""

from __future__ import annotations

import functools
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fem.threads import release_free_memory

from ..distributed import run_tasks
from ._interp import interpolate_log_na, stencil_starts
from .cache import (
    cache_key,
    default_cache_dir,
    entry_problem,
    load_table,
    resolve_method,
    store_table,
    usable_cache_dir,
)
from .spec import EmulatorSpec
from .table import table_point
from .white import white_column

__all__ = ["AbsorptionEmulator", "check_range"]

#: s between two stores of a table being built (each writes the whole table): a run
#: interrupted or killed loses at most this much of its Monte Carlo
STORE_EVERY_S = 30.0


@dataclass
class AbsorptionEmulator:
    """NA(mua, mus) on a fixed grid by interpolation in a Monte Carlo table.

    Call with arrays ``mua`` (N,) and ``mus`` (N,) in cm^-1; returns NA (N, nx, ny, nz)
    in W/cm^3/W, or, when ``spec.mesh_divisions`` is set, the P1 nodal load per W
    incident (N, mx+1, my+1, mz+1) in W/W (C order of the nodes of ``fem.box_mesh``).
    """

    spec: EmulatorSpec
    log_na: np.ndarray  #: (n_mua, n_mus, n_unique) log(NA + NA_OFFSET) at the orbit representatives
    absorbed: np.ndarray = None  #: (n_mua, n_mus) absorbed fraction of each table point
    out_of_range: str = "error"  #: "error" or "clamp"
    build_seconds: float = 0.0
    #: (n_mua, n_mus) bool: the table points built so far (None: all). An emulator built
    #: ``on_demand`` runs the Monte Carlo of the points an interpolation needs the first time
    #: a member needs them (:meth:`fill`); the others hold NaN and are never read
    have: np.ndarray = None
    method: str = "table"  #: how missing points are built (:data:`METHODS`; auto resolved)
    exact = False  #: an interpolation, not Monte Carlo (enkf.tissue.absorption.Absorption)
    #: where missing points go (the cache file), the Dask client, whether to show progress
    _fill_with: tuple = field(default=(None, None, False), repr=False)
    _lmua: np.ndarray = field(init=False, repr=False)
    _lmus: np.ndarray = field(init=False, repr=False)
    inverse: np.ndarray = field(init=False, repr=False)  #: (nvox,) orbit of each voxel

    def __post_init__(self):
        self._lmua = np.log(self.spec.mua_grid())
        self._lmus = np.log(self.spec.mus_grid())
        self.inverse = self.spec.orbits()[1]
        if self.out_of_range not in ("error", "clamp"):
            raise ValueError(f"out_of_range must be 'error' or 'clamp', got {self.out_of_range!r}")
        self.log_na = np.ascontiguousarray(self.log_na, dtype=np.float64)
        if self.have is None:
            self.have = np.ones((self.spec.n_mua, self.spec.n_mus), dtype=bool)
        self.method = resolve_method(self.spec, self.method)

    def __getstate__(self):  # a Dask client does not travel (workers fill with their own cores)
        state = dict(self.__dict__)
        path, _client, progress = state["_fill_with"]
        state["_fill_with"] = (path, None, progress)
        return state

    @property
    def complete(self) -> bool:
        """Whether every table point is built."""
        return bool(self.have.all())

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.spec.field_shape

    @property
    def kind(self) -> str:
        """``"NA"`` (voxels) or ``"load"`` (P1 nodal loads)."""
        return "NA" if self.spec.mesh_divisions is None else "load"

    def _check(self, name, values, lo, hi):
        return check_range(name, values, lo, hi, self.out_of_range, "the emulator table")

    def unique(self, mua, mus) -> np.ndarray:
        """NA at the orbit representatives, (N, n_unique): expand with ``[:, self.inverse]``.

        The filter's forward model folds the expansion into its load operator, so that
        the interpolation and the exponentials run on about nvox / 8 values.
        """
        mua = self._check("mua", mua, *self.spec.mua_range)
        mus = self._check("mus", mus, *self.spec.mus_range)
        mua, mus = np.broadcast_arrays(mua, mus)
        if not self.have.all():
            self.fill(self.needed(mua, mus))
        out = np.empty((mua.size, self.log_na.shape[2]))
        interpolate_log_na(self.log_na, self._lmua, self._lmus, np.log(mua).ravel(),
                           np.log(mus).ravel(), self.spec.offset, out)
        return out

    def __call__(self, mua, mus) -> np.ndarray:
        """NA (N, nx, ny, nz) in W/cm^3/W for ``mua``, ``mus`` (N,) in cm^-1."""
        vals = self.unique(mua, mus)
        return vals[:, self.inverse].reshape((vals.shape[0], *self.shape))

    # ----------------------------------------------------------------- build & cache
    @classmethod
    def build(cls, spec: EmulatorSpec, *, cache_dir: str | Path | None = None,
              progress: bool = True, out_of_range: str = "error",
              client=None, method: str = "table", on_demand: bool = False) -> AbsorptionEmulator:
        """Load the table for ``spec`` from the cache, or run the Monte Carlo and store it.

        ``method="table"``: one direct Monte Carlo run per table point (``n_mua * n_mus``
        runs). ``method="white"``: one perturbation Monte Carlo run per ``mus`` column,
        whose packets carry one weight per tabulated ``mua``
        (:mod:`mcmatlab_py.emulator.white`; ``n_mus`` runs, same photons per column; on demand, only
        the rows a column still needs). ``method="auto"``: ``white`` where the white
        kernel applies to ``spec`` (:func:`resolve_method`), else ``table``. Each run uses
        all cores (photon batches in parallel), or, with a ``dask.distributed`` ``client``
        (:func:`mcmatlab_py.distributed.connect`), one task per run on the cluster's
        workers; both give the same table. The cache file is keyed by the spec and the
        method; a corrupted one is detected by its checksum and rebuilt.

        ``on_demand=True`` runs nothing now: each table point is built the first time an
        interpolation needs it (:meth:`fill`, from :meth:`unique`) and added to the cache,
        so a filter whose members stay in a corner of the table never pays for the rest
        (the paper's prior needs 7 of the 12 columns, not the costly high ``mus`` ones).
        The points are the same numbers either way.
        """
        method = resolve_method(spec, method)
        key = cache_key(spec, method)
        cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        path = cache / f"emulator-{key}.npz"
        if entry_problem(path) is not None:  # a directory or FIFO in its place: not read
            path = usable_cache_dir(cache, path.name) / path.name
        loaded = load_table(path, spec, key)
        if loaded is None:
            shape = (spec.n_mua, spec.n_mus)
            loaded = dict(log_na=np.full((*shape, spec.orbits()[0].size), np.nan),
                          absorbed=np.full(shape, np.nan), have=np.zeros(shape, dtype=bool),
                          build_seconds=0.0)
        emu = cls(spec=spec, log_na=loaded["log_na"], absorbed=loaded["absorbed"],
                  out_of_range=out_of_range, build_seconds=float(loaded["build_seconds"]),
                  have=loaded["have"], method=method)
        emu._fill_with = (path, client, progress)
        if not on_demand:
            emu.fill(np.ones_like(emu.have))
        return emu

    def needed(self, mua, mus) -> np.ndarray:
        """(n_mua, n_mus) bool: the table points the interpolation at ``mua``, ``mus``
        (N,) cm^-1 (inside the table's ranges) reads: the 4 x 4 stencil of each member."""
        need = np.zeros((self.spec.n_mua, self.spec.n_mus), dtype=bool)
        ia = stencil_starts(np.log(np.ravel(mua).astype(np.float64)), self._lmua)
        ib = stencil_starts(np.log(np.ravel(mus).astype(np.float64)), self._lmus)
        for a, b in set(zip(ia.tolist(), ib.tolist(), strict=True)):
            need[a:a + 4, b:b + 4] = True
        return need

    def needed_box(self, mua_range, mus_range) -> np.ndarray:
        """(n_mua, n_mus) bool: the table points that interpolations anywhere in the box
        ``mua_range`` x ``mus_range`` (cm^-1, inside the table) read (e.g. a prior's)."""
        axes = []
        for (lo, hi), grid in ((mua_range, self.spec.mua_grid()),
                               (mus_range, self.spec.mus_grid())):
            axes.append(np.r_[lo, hi, grid[(grid > lo) & (grid < hi)]])
        A, B = np.meshgrid(*axes, indexing="ij")
        return self.needed(A.ravel(), B.ravel())

    def fill(self, points: np.ndarray) -> None:
        """Run the Monte Carlo of the table points in ``points`` ((n_mua, n_mus) bool) not
        built yet, and add them to the cache file. ``method="white"`` runs one white run per
        ``mus`` column for the rows that column still needs. Each point's numbers depend
        only on the spec and its place in the table, so an emulator filled piece by piece
        equals one built at once, bit for bit."""
        missing = np.asarray(points, dtype=bool) & ~self.have
        if not missing.any():
            return
        spec = self.spec
        path, client, progress = self._fill_with
        if path is not None:  # before minutes of Monte Carlo, not after
            path = usable_cache_dir(path.parent, path.name) / path.name
            self._fill_with = (path, client, progress)
        t0 = time.perf_counter()
        saved = [time.monotonic()]

        def keep(filled: bool = False) -> None:
            """Store the points built so far: every STORE_EVERY_S seconds, at the end, and
            when the fill is interrupted (a rerun then builds only the rest)."""
            path = self._fill_with[0]
            if path is None or not (filled or time.monotonic() - saved[0] > STORE_EVERY_S):
                return
            if not store_table(path, cache_key(spec, self.method), self):
                self._fill_with = (None, client, progress)  # one warning, then no cache
            saved[0] = time.monotonic()

        # cost grows with mus: the expensive columns first, so the ETA is honest
        columns = [b for b in range(spec.n_mus)[::-1] if missing[:, b].any()]
        if self.method == "white":
            todo = [(b, np.flatnonzero(missing[:, b])) for b in columns]

            def put(i, result):
                (b, rows), (values, fracs) = todo[i], result
                self.log_na[rows, b], self.absorbed[rows, b] = values, fracs
                self.have[rows, b] = True  # last: a point is had once its numbers are in
                keep()
            task, label = functools.partial(_white_rows, spec), "emulator table (white)"
        else:
            todo = [(a, b) for b in columns for a in range(spec.n_mua) if missing[a, b]]

            def put(i, result):
                (a, b), (row, frac) = todo[i], result
                self.log_na[a, b], self.absorbed[a, b] = row, frac
                self.have[a, b] = True
                keep()
            task, label = functools.partial(table_point, spec), "emulator table"
        try:
            run_tasks(task, todo, client=client, progress=progress, label=label, on_result=put)
        except BaseException:
            self.build_seconds += time.perf_counter() - t0
            keep(filled=True)  # the points finished before Ctrl-C, SIGTERM or a failure
            raise
        self.build_seconds += time.perf_counter() - t0
        keep(filled=True)
        release_free_memory()  # the load operator's and the runs' temporaries


def check_range(name: str, values, lo: float, hi: float, out_of_range: str,
                what: str, unit: str = "cm^-1") -> np.ndarray:
    """``values`` (``unit``) as a float array inside ``[lo, hi]`` (``what``: the table or
    grid, for the messages): non-finite values are refused; values outside are refused
    (``out_of_range="error"``) or clamped with a ``RuntimeWarning`` that says "clamped"
    (the filter counts those)."""
    values = np.atleast_1d(np.asarray(values, dtype=np.float64))
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name} must be finite, got {float(values[~np.isfinite(values)][0])!r}")
    bad = (values < lo * (1 - 1e-12)) | (values > hi * (1 + 1e-12))
    if bad.any():
        if out_of_range == "error":
            raise ValueError(f"{name} = {float(values[bad][0])!r} {unit} is outside {what} "
                             f"[{lo}, {hi}]")
        warnings.warn(f"{name} = {float(values[bad][0])!r} clamped to {what} [{lo}, {hi}]",
                      RuntimeWarning, stacklevel=4)
        values = np.clip(values, lo, hi)
    return values


def _white_rows(spec: EmulatorSpec, task: tuple) -> tuple[np.ndarray, np.ndarray]:
    """One task of a white fill: ``(b, rows)`` -> :func:`mcmatlab_py.emulator.white.white_column`."""
    return white_column(spec, *task)
