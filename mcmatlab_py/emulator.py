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
import hashlib
import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fem.checks import shorten

from ._interp import interpolate_log_na, stencil_starts
from ._strict import NotBuiltError
from .light_source import source_kind
from .media import Medium
from .model import Geometry, MonteCarloSimulation

__all__ = [
    "EMULATED_SOURCES",
    "AbsorptionEmulator",
    "EmulatorSpec",
    "default_cache_dir",
    "cache_key",
    "check_emulated",
    "entry_problem",
    "interpolate_log_na",
    "load_cached",
    "resolve_method",
    "symmetrize",
    "table_point",
    "table_row",
    "table_rows",
    "store_atomically",
    "usable_cache_dir",
    "white_supported",
]

CACHE_VERSION = 5
#: build methods of :meth:`AbsorptionEmulator.build`: direct Monte Carlo per table point, or
#: one perturbation ("white") Monte Carlo run per mus column (:mod:`mcmatlab_py.white`)
#: ("auto": white where the white kernel applies, see :func:`resolve_method`, else table)
METHODS = ("table", "white", "auto")
WHITE_VERSION = 5  #: bumped when the white kernel's numbers change
#: The table holds log(NA + NA_OFFSET): smooth where NA is zero or noisy in voxels
#: that (almost) no photon reaches, and exactly inverted on evaluation.
NA_OFFSET = 1e-3  # W/cm^3/W, far below the NA of the voxels that matter
#: s between two stores of a table being built (each writes the whole table): a run
#: interrupted or killed loses at most this much of its Monte Carlo
STORE_EVERY_S = 30.0


def default_cache_dir() -> Path:
    """``$TISSUE_ENKF_CACHE``, else ``~/.cache/tissue-enkf``."""
    env = os.environ.get("TISSUE_ENKF_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "tissue-enkf"


#: the light sources an emulator table is built for (straight beams and a point)
EMULATED_SOURCES = ("pencil", "tophat", "gaussian", "plane_wave", "isotropic_point")


def _emulated_source(source_type) -> str:
    """``source_type`` as the emulator names it: a name as given (the cache keys of earlier
    tables), an MCmatlab code (0: pencil) by its name."""
    return source_type if isinstance(source_type, str) else source_kind(source_type)


def check_emulated(model) -> None:
    """Raise :class:`NotBuiltError` naming what of ``model`` an emulator table cannot
    represent: a tilted beam or line emitter, a source other than :data:`EMULATED_SOURCES`,
    a source distribution, media given as functions or with a custom phase function (the
    table would silently be that of a straight, plain beam in a plain medium)."""
    G, src = model.G, model.MC.light_source
    unsupported = [f"MC.light_source.{k}" for k in ("theta", "phi", "psi", "emitter_length")
                   if getattr(src, k)]
    try:
        name = _emulated_source(src.source_type)
    except ValueError:  # not a source type at all: said by MC.validate
        name = None
    if name not in EMULATED_SOURCES:
        unsupported.append(f"MC.light_source.source_type = {shorten(repr(src.source_type))}")
    if model.MC.source_distribution is not None:
        unsupported.append("MC.source_distribution")
    for i, m in enumerate(G.media):
        for k in ("mua", "mus", "g", "n"):
            if callable(getattr(m, k)):
                unsupported.append(f"G.media[{i}].{k} as a function")
        if getattr(m, "custom_phase_func", None) is not None:
            unsupported.append(f"G.media[{i}].custom_phase_func")
    if unsupported:
        raise NotBuiltError(f"the absorption emulator supports straight pencil, top-hat, "
                            f"Gaussian, plane-wave and point sources in a plain medium; "
                            f"not built for {', '.join(unsupported)}")


@dataclass
class EmulatorSpec:
    """Everything that changes the tabulated maps (hashed into the cache key).

    The geometry is a single medium whose ``mua`` and ``mus`` are replaced by the table
    values (``g`` and ``n`` fixed), or, with ``media`` and ``medium_map`` (issue #19), a
    voxel map of several media of which one, ``estimated``, takes the table's ``mua`` and
    ``mus`` while the others keep theirs.
    """

    nx: int
    ny: int
    nz: int
    Lx: float  #: cm
    Ly: float  #: cm
    Lz: float  #: cm
    g: float
    n: float
    source_type: str
    radius: float  #: cm
    x_focus: float = 0.0
    y_focus: float = 0.0
    z_focus: float = 0.0
    boundary_type: int = 1
    matched_interfaces: bool = True
    n_outside: float = 1.0
    mua_range: tuple[float, float] = (0.1, 20.0)  #: cm^-1
    mus_range: tuple[float, float] = (10.0, 2000.0)  #: cm^-1
    n_mua: int = 12  #: log-spaced table points in mua_range
    n_mus: int = 12  #: log-spaced table points in mus_range
    #: None: tabulate NA on the voxels. (mx, my, mz): tabulate the P1 nodal load per W
    #: incident, ``L @ NA`` (W/W), on ``fem.box_mesh`` of mx x my x mz boxes over the same
    #: cuboid, so that a fine Monte Carlo grid feeds a coarse heat mesh exactly
    mesh_divisions: tuple | None = None
    #: photons per table point at mus = 100 cm^-1; other columns get
    #: ``n_photons * clip((100 / mus)^0.7, 0.5, 5)`` (see :meth:`photons_at`)
    n_photons: int = 250_000
    seed: int = 12345
    #: several media: ``(mua, mus, g, n)`` of each medium of ``medium_map`` (cm^-1), the
    #: estimated one's ``mua`` and ``mus`` None (the table's); None: one medium (g, n above)
    media: tuple | None = None
    estimated: int = 0  #: the medium whose mua and mus the table varies
    #: (nx, ny, nz) medium index of every voxel with ``media`` (its hash is in the key)
    medium_map: np.ndarray | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        for name in ("n_mua", "n_mus"):
            if int(getattr(self, name)) < 4:
                raise ValueError(f"EmulatorSpec.{name} must be >= 4, got {getattr(self, name)!r}")
        for name in ("mua_range", "mus_range"):
            lo, hi = getattr(self, name)
            if not (0 < lo < hi and np.isfinite(hi)):
                raise ValueError(f"EmulatorSpec.{name} must be (lo, hi) with 0 < lo < hi, "
                                 f"got {getattr(self, name)!r}")
        self.mua_range = tuple(float(v) for v in self.mua_range)
        self.mus_range = tuple(float(v) for v in self.mus_range)
        if self.mesh_divisions is not None:
            md = tuple(int(v) for v in self.mesh_divisions)
            if len(md) != 3 or min(md) < 1:
                raise ValueError("EmulatorSpec.mesh_divisions must be three integers >= 1, "
                                 f"got {self.mesh_divisions!r}")
            self.mesh_divisions = md
        if self.media is not None:
            self._check_media()

    def _check_media(self) -> None:
        media = tuple(tuple(None if v is None else float(v) for v in m) for m in self.media)
        if len(media) < 2 or any(len(m) != 4 for m in media):
            raise ValueError(f"EmulatorSpec.media must hold (mua, mus, g, n) of two or more "
                             f"media, got {self.media!r}")
        if not 0 <= int(self.estimated) < len(media):
            raise ValueError(f"EmulatorSpec.estimated must be a medium index in 0..{len(media) - 1}"
                             f", got {self.estimated!r}")
        self.estimated = int(self.estimated)
        mua, mus, self.g, self.n = media[self.estimated]
        media = tuple((None, None, *m[2:]) if i == self.estimated else m
                      for i, m in enumerate(media))
        M = np.asarray(self.medium_map)
        if M.shape != (self.nx, self.ny, self.nz) or M.dtype.kind not in "iu":
            raise ValueError(f"EmulatorSpec.medium_map must be integer indices of shape "
                             f"{(self.nx, self.ny, self.nz)}, got {M.dtype} {M.shape}")
        if M.min() < 0 or M.max() >= len(media) or not (M == self.estimated).any():
            raise ValueError(f"EmulatorSpec.medium_map must hold indices in 0..{len(media) - 1} "
                             f"and at least one voxel of the estimated medium {self.estimated}")
        self.media = media
        self.medium_map = np.ascontiguousarray(M, dtype=np.int32)

    @property
    def field_shape(self) -> tuple[int, int, int]:
        """Shape of the tabulated field: the voxels, or the mesh nodes (mx+1, my+1, mz+1)."""
        if self.mesh_divisions is None:
            return (self.nx, self.ny, self.nz)
        return tuple(m + 1 for m in self.mesh_divisions)

    @property
    def offset(self) -> float:
        """Offset of the log table: NA_OFFSET, times the mesh cell volume for nodal loads."""
        if self.mesh_divisions is None:
            return NA_OFFSET
        mx, my, mz = self.mesh_divisions
        return NA_OFFSET * self.Lx * self.Ly * self.Lz / (mx * my * mz)

    @classmethod
    def from_model(cls, model, medium: int | None = None, **kw) -> EmulatorSpec:
        """The spec of a model (its G and MC.light_source): one medium, or several with
        ``medium``, the index in ``G.media`` of the one whose mua and mus are tabulated."""
        G, MC = model.G, model.MC
        G.validate()
        if len(G.media) != 1 and medium is None:
            raise ValueError(f"G.media has {len(G.media)} media: name the one whose mua and mus "
                             "the emulator varies (medium = its index)")
        medium = 0 if medium is None else int(medium)
        if not 0 <= medium < len(G.media):
            raise ValueError(f"medium must be an index of G.media (0..{len(G.media) - 1}), "
                             f"got {medium}")
        check_emulated(model)
        src = MC.light_source
        if len(G.media) > 1:
            kw.update(media=tuple((m.mua, m.mus, m.g, m.n) for m in G.media), estimated=medium,
                      medium_map=G.medium_map())
        return cls(nx=G.nx, ny=G.ny, nz=G.nz, Lx=G.Lx, Ly=G.Ly, Lz=G.Lz, g=G.media[medium].g,
                   n=G.media[medium].n, source_type=_emulated_source(src.source_type),
                   radius=src.radius,
                   x_focus=src.x_focus, y_focus=src.y_focus, z_focus=src.z_focus,
                   boundary_type=MC.boundary_type, matched_interfaces=MC.matched_interfaces,
                   n_outside=MC.n_outside, **kw)

    def key(self) -> str:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        if self.media is None:  # one medium: the key of the tables cached before media
            for k in ("media", "estimated", "medium_map"):
                del d[k]
        else:
            d["medium_map"] = [self.medium_map.shape, hashlib.sha256(
                self.medium_map.tobytes()).hexdigest()]
        d["version"] = CACHE_VERSION
        d["batch_size"] = MonteCarloSimulation().batch_size
        d["weight_threshold"] = MonteCarloSimulation().weight_threshold
        text = json.dumps(d, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:24]

    def symmetric_axes(self, voxels: bool = False) -> tuple[bool, bool, bool]:
        """(x -> -x, y -> -y, x <-> y): the mirror symmetries of the block and beam, on the
        tabulated field (or, ``voxels=True``, on the Monte Carlo voxels)."""
        sx = self.x_focus == 0
        sy = self.y_focus == 0
        a, b, _ = (self.nx, self.ny, self.nz) if voxels else self.field_shape
        swap = (self.x_focus == self.y_focus and self.nx == self.ny and self.Lx == self.Ly
                and a == b)
        if self.medium_map is not None:  # the media must share the mirror symmetries
            if not voxels and self.mesh_divisions is not None:
                # a thin absorbing layer puts its power into the top mesh cells, where the
                # Kuhn triangulation's asymmetric P1 loads differ from their mirror average by
                # 5% (rel. L2, the 80 um epidermis of examples/two_layer.toml on 20 x 20 x 10):
                # keep the exact loads on every node (the voxels are still averaged)
                return False, False, False
            M = self.medium_map
            sx = sx and np.array_equal(M, M[::-1])
            sy = sy and np.array_equal(M, M[:, ::-1])
            swap = swap and np.array_equal(M, M.transpose(1, 0, 2))
        return sx, sy, swap

    def orbits(self, voxels: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Voxels equal by symmetry: ``(representatives (n_unique,), inverse (nvox,))``.

        ``field.ravel()[representatives][inverse]`` rebuilds a symmetric field; the table
        stores only the ``n_unique`` representatives (about nvox / 8 for a centred beam
        on a square block). ``voxels=True``: the orbits of the Monte Carlo voxels (the
        same as the field's unless ``mesh_divisions`` is set).
        """
        sx, sy, swap = self.symmetric_axes(voxels)
        a, b, c = (self.nx, self.ny, self.nz) if voxels else self.field_shape
        i, j, k = np.meshgrid(np.arange(a), np.arange(b), np.arange(c), indexing="ij")
        if sx:
            i = np.minimum(i, a - 1 - i)
        if sy:
            j = np.minimum(j, b - 1 - j)
        if swap:
            i, j = np.minimum(i, j), np.maximum(i, j)
        canon = ((i * b + j) * c + k).ravel()
        reps, inverse = np.unique(canon, return_inverse=True)
        return reps, inverse

    def photons_at(self, mus: float) -> int:
        """Photons for a table point with scattering ``mus``.

        Weakly scattering points are cheap per photon but noisy (few interactions per
        photon), strongly scattering ones expensive but smooth: the schedule spends
        photons where they buy accuracy (measured in validation/emulator_accuracy.py).
        """
        return int(self.n_photons * float(np.clip((100.0 / mus) ** 0.7, 0.5, 5.0)))

    def mua_grid(self) -> np.ndarray:
        return np.geomspace(*self.mua_range, self.n_mua)

    def mus_grid(self) -> np.ndarray:
        return np.geomspace(*self.mus_range, self.n_mus)

    def model(self, mua: float, mus: float, n_photons: int | None = None, seed=None):
        """A :class:`~mcmatlab_py.Model` of this block with the given coefficients."""
        from .model import Model

        m = Model()
        m.G = Geometry(nx=self.nx, ny=self.ny, nz=self.nz, Lx=self.Lx, Ly=self.Ly, Lz=self.Lz,
                       media=[Medium("tissue", mua=mua, mus=mus, g=self.g, n=self.n)])
        if self.media is not None:
            m.G.media = [Medium(f"medium {i}", mua=mua if i == self.estimated else p[0],
                                mus=mus if i == self.estimated else p[1], g=p[2], n=p[3])
                         for i, p in enumerate(self.media)]
            m.G.geom_func, m.G.geom_func_params = _voxel_map, self.medium_map
        MC = m.MC
        MC.n_photons_requested = int(n_photons or self.n_photons)
        MC.seed = self.seed if seed is None else seed
        MC.boundary_type = self.boundary_type
        MC.matched_interfaces = self.matched_interfaces
        MC.n_outside = self.n_outside
        MC.progress = False
        src = MC.light_source
        src.source_type, src.radius = self.source_type, self.radius
        src.x_focus, src.y_focus, src.z_focus = self.x_focus, self.y_focus, self.z_focus
        return m


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
        (:mod:`mcmatlab_py.white`; ``n_mus`` runs, same photons per column; on demand, only
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
        loaded = _load(path, spec, key)
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
        import time

        from .distributed import run_tasks
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
            if not _store(path, cache_key(spec, self.method), self):
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
        from fem.threads import release_free_memory

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
    """One task of a white fill: ``(b, rows)`` -> :func:`mcmatlab_py.white.white_column`."""
    from .white import white_column

    return white_column(spec, *task)


def white_supported(spec: EmulatorSpec) -> str | None:
    """None when the white build applies to ``spec``, else why not
    (:func:`mcmatlab_py.white.white_obstacle`: one refractive index for all media or
    matched interfaces, and ``mua > 0`` in every fixed medium)."""
    from .white import white_obstacle

    obstacle = white_obstacle(spec)
    return None if obstacle is None else obstacle[1]


def resolve_method(spec: EmulatorSpec, method: str) -> str:
    """The build method for ``spec``: ``method`` itself, or for ``"auto"`` ``"white"``
    where :func:`white_supported` allows it, else ``"table"``."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if method == "auto":
        return "table" if white_supported(spec) else "white"
    return method


def _voxel_map(X, Y, Z, M):
    """``G.geom_func`` of a spec with several media: its stored voxel map (picklable)."""
    return M


_OPERATORS: dict = {}


def _load_operator(spec: EmulatorSpec):
    """The voxel -> P1 node operator of a nodal-load spec (built once per process)."""
    import fem
    from fem.threads import release_free_memory

    key = (spec.nx, spec.ny, spec.nz, spec.Lx, spec.Ly, spec.Lz, tuple(spec.mesh_divisions))
    if key not in _OPERATORS:
        grid = fem.BoxGrid(spec.nx, spec.ny, spec.nz, spec.Lx, spec.Ly, spec.Lz)
        mesh = fem.BoxGrid(*spec.mesh_divisions, spec.Lx, spec.Ly, spec.Lz).mesh()
        _OPERATORS.clear()  # one at a time: the matrices of fine grids are large
        _OPERATORS[key] = fem.voxel_load_matrix(mesh, grid)
        del mesh
        release_free_memory()  # its temporaries: ~270 MB kept otherwise
    return _OPERATORS[key]


def table_point(spec: EmulatorSpec, point: tuple[int, int]) -> tuple[np.ndarray, float]:
    """One table point ``(i_mua, i_mus)``: log(NA + offset) at the orbit representatives
    (n_unique,) and the absorbed fraction. Deterministic (seed ``spec.seed``): the same
    numbers wherever and on however many threads it runs."""
    from .monte_carlo import optical_arrays, simulate

    a, b = point
    mua, mus = spec.mua_grid()[a], spec.mus_grid()[b]
    m = spec.model(mua, mus, n_photons=spec.photons_at(mus))
    M = m.G.medium_map()
    m.MC.validate(m.G)
    res = simulate(m.G, m.MC, M, *optical_arrays(m.G.media, m.MC.wavelength), seed=spec.seed,
                   n_photons=m.MC.n_photons_requested)
    dV = m.G.dx * m.G.dy * m.G.dz
    return table_row(spec, res.absorbed / (res.n_photons * dV)), float(res.absorbed.sum()
                                                                     / res.n_photons)


def table_row(spec: EmulatorSpec, na: np.ndarray) -> np.ndarray:
    """The stored form of one table point's NA (nx, ny, nz) in W/cm^3/W: projected onto
    the mesh nodes when ``spec.mesh_divisions`` is set, symmetrised, log(. + offset) at
    the orbit representatives (n_unique,)."""
    return table_rows(spec, na[None])[0]


def table_rows(spec: EmulatorSpec, na: np.ndarray, symmetric: bool = False) -> np.ndarray:
    """:func:`table_row` of a stack of maps (K, nx, ny, nz) -> (K, n_unique), with one sparse
    product for the projection; ``symmetric``: the maps are already symmetrised on the
    voxels (as the white run's orbit tallies are)."""
    if spec.mesh_divisions is not None:
        if not symmetric:
            na = np.stack([symmetrize(m, spec, voxels=True) for m in na])
        flat = na.reshape(na.shape[0], -1)
        na = (_load_operator(spec) @ flat.T).T.reshape((-1, *spec.field_shape))  # W/node/W
    reps, _ = spec.orbits()
    return np.stack([np.log(symmetrize(m, spec).ravel()[reps] + spec.offset) for m in na])


def symmetrize(na: np.ndarray, spec: EmulatorSpec, voxels: bool = False) -> np.ndarray:
    """Average a field over the mirror symmetries of the block and beam.

    A beam centred on the block is symmetric under x -> -x and y -> -y, and a square
    block under x <-> y as well: averaging over these images is an exact variance
    reduction (up to 8 times fewer photons for the same noise). The field is on the
    spec's voxels, or (``voxels=False`` with ``mesh_divisions``) on its mesh nodes, where
    the average also evens out the O(h^2) asymmetry of the Kuhn triangulation's quadrature
    (not with several media: :meth:`EmulatorSpec.symmetric_axes`).
    """
    sx, sy, swap = spec.symmetric_axes(voxels and spec.media is not None)
    if voxels:
        swap = swap and spec.nx == spec.ny
    if sx:
        na = 0.5 * (na + na[::-1])
    if sy:
        na = 0.5 * (na + na[:, ::-1])
    if swap:
        na = 0.5 * (na + na.transpose(1, 0, 2))
    return na


def cache_key(spec: EmulatorSpec, method: str = "table") -> str:
    """The cache key of a table: the spec's, and for ``"white"`` the method as well (the
    ``"table"`` key is the spec's own, so the tables cached before methods existed stay);
    ``"auto"`` is first resolved (:func:`resolve_method`)."""
    method = resolve_method(spec, method)
    if method == "table":
        return spec.key()
    text = f"{spec.key()}-{method}-{WHITE_VERSION}"
    return f"{method}-" + hashlib.sha256(text.encode()).hexdigest()[:24]


def _checksum(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def entry_problem(path: Path) -> str | None:
    """Why the cache entry ``path`` cannot be used (``"it is a directory"``), or None when
    it is a regular file or absent (it is then written)."""
    import stat

    from .files import file_kind

    try:
        mode = os.stat(path).st_mode  # a FIFO is not opened: that could wait forever
    except FileNotFoundError:
        return None
    except OSError as err:
        return err.strerror or type(err).__name__
    return None if stat.S_ISREG(mode) else f"it is {file_kind(mode)}, not a regular file"


def usable_cache_dir(cache: Path, entry: str | None = None) -> Path:
    """``cache`` if a table can be written there (and its file ``entry``, when given, is a
    regular file or absent); else a temporary folder, removed when this process exits,
    with a warning that says why (the table is then rebuilt by the next run)."""
    import atexit
    import shutil
    import tempfile

    why = None if entry is None else entry_problem(cache / entry)
    if why is not None:
        why = f"the cache entry {str(cache / entry)!r} cannot be used ({why})"
    else:
        try:
            cache.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=cache, prefix=".probe-"):
                pass
            return cache
        except OSError as err:
            why = (f"the cache folder {str(cache)!r} cannot be written "
                   f"({err.strerror or type(err).__name__})")
    tmp = Path(tempfile.mkdtemp(prefix="tissue-enkf-cache-"))
    atexit.register(shutil.rmtree, tmp, True)
    warnings.warn(f"{why}; what would be cached goes to {tmp}, removed when this run ends "
                  "(set TISSUE_ENKF_CACHE or --cache-dir to a writable folder)",
                  RuntimeWarning, stacklevel=3)
    return tmp


def store_atomically(path: Path, what: str = "emulator cache", **arrays) -> bool:
    """Write ``arrays`` to the NPZ file ``path`` atomically (a temporary file beside it,
    renamed over it: a reader never sees half a file, and an interrupted or failed write
    leaves nothing). A write that fails (a full disk, no permission, a directory in its
    place) gives one warning naming the path and returns False: a cache that cannot be
    written never stops a valid run."""
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.npz")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(tmp, **arrays)
        os.replace(tmp, path)
        return True
    except OSError as err:
        warnings.warn(f"the {what} {str(path)!r} cannot be written "
                      f"({err.strerror or type(err).__name__}): the run goes on without it",
                      RuntimeWarning, stacklevel=3)
        return False
    finally:  # interrupted (Ctrl-C, SIGTERM) or failed: no half-written file stays
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass


def load_cached(path: Path, what: str = "cache") -> dict | None:
    """The arrays of the cached NPZ file ``path``, or None when there is none to use: absent,
    not a regular file (left alone, never opened: a FIFO would wait), or unreadable
    (removed: it is computed again). A forged header is refused before anything is
    allocated."""
    if not path.exists() or entry_problem(path) is not None:
        return None
    from .files import npz_headers

    try:
        npz_headers(path, what)
        with np.load(path, allow_pickle=False) as f:
            return {k: f[k] for k in f.files}
    except Exception:  # noqa: BLE001 - any unreadable file is treated as corrupted
        try:
            path.unlink(missing_ok=True)
        except OSError:
            pass
        return None


def _store(path: Path, key: str, emu: AbsorptionEmulator) -> bool:
    """Write the table (and which points it holds) atomically; points another process
    added to the file meanwhile are kept. False (after a warning) when it cannot be
    written."""
    on_disk = _load(path, emu.spec, key, quiet=True)
    if on_disk is not None:
        extra = on_disk["have"] & ~emu.have
        emu.log_na[extra] = on_disk["log_na"][extra]
        emu.absorbed[extra] = on_disk["absorbed"][extra]
        emu.have |= extra
    return store_atomically(path, log_na=emu.log_na, absorbed=emu.absorbed, have=emu.have,
                            build_seconds=emu.build_seconds, key=key,
                            checksum=_checksum(emu.log_na, emu.absorbed, emu.have))


def _load(path: Path, spec: EmulatorSpec, key: str, quiet: bool = False):
    if not path.exists() or entry_problem(path) is not None:
        return None
    from .files import npz_headers

    orbits = spec.orbits()[0].size
    try:
        # from the headers: a forged one that declares a huge shape is not allocated
        heads = npz_headers(path, "emulator cache")
        expect = {"log_na": (spec.n_mua, spec.n_mus, orbits), "absorbed": (spec.n_mua, spec.n_mus),
                  "have": (spec.n_mua, spec.n_mus)}
        if any(k in heads and heads[k][0] != shape for k, shape in expect.items()):
            raise ValueError("a table of another shape")
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in ("log_na", "absorbed", "build_seconds", "key", "checksum")}
            if "have" in f:
                data["have"] = f["have"]
                check = _checksum(data["log_na"], data["absorbed"], data["have"])
            else:  # written before on-demand tables: complete
                data["have"] = np.ones((spec.n_mua, spec.n_mus), dtype=bool)
                check = _checksum(data["log_na"], data["absorbed"])
        ok = (str(data["key"]) == key
              and data["log_na"].shape == (spec.n_mua, spec.n_mus, spec.orbits()[0].size)
              and data["have"].shape == (spec.n_mua, spec.n_mus) and data["have"].dtype == bool
              and str(data["checksum"]) == check)
    except Exception:  # noqa: BLE001 - any unreadable file is treated as corrupted
        ok = False
    if not ok:
        if quiet:
            return None
        warnings.warn(f"emulator cache {path} is corrupted or stale: rebuilding", RuntimeWarning,
                      stacklevel=3)
        try:
            path.unlink(missing_ok=True)
        except OSError:  # no permission: the rebuilt table replaces it, or is not stored
            pass
        return None
    return data


def __getattr__(name: str):
    """The exact mode lives in :mod:`mcmatlab_py.exact`; its names stay importable from here.

    Looked up on first use rather than imported at the end of this module: ``exact``
    imports this module, so ``import mcmatlab_py.exact`` on its own would otherwise meet a
    half-initialised ``exact``.
    """
    if name in ("DirectMonteCarloAbsorption", "direct_member"):
        from . import exact

        return getattr(exact, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
