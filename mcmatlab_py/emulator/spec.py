"""What an emulator table is of (:class:`EmulatorSpec`: the block, its media, the beam and
the (mua, mus) grid, hashed into the cache key), and which models a table can stand for
(:func:`check_emulated`)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field

import numpy as np

from fem.checks import shorten

from .._strict import NotBuiltError
from ..geometry.cuboid import Geometry
from ..geometry.media import Medium
from ..light.source import source_kind
from ..model import Model
from ..monte_carlo.simulation import MonteCarloSimulation

__all__ = ["CACHE_VERSION", "EMULATED_SOURCES", "NA_OFFSET", "EmulatorSpec", "check_emulated",
           "emulated_source"]

CACHE_VERSION = 5
#: The table holds log(NA + NA_OFFSET): smooth where NA is zero or noisy in voxels
#: that (almost) no photon reaches, and exactly inverted on evaluation.
NA_OFFSET = 1e-3  # W/cm^3/W, far below the NA of the voxels that matter
#: the light sources an emulator table is built for (straight beams and a point)
EMULATED_SOURCES = ("pencil", "tophat", "gaussian", "plane_wave", "isotropic_point")


def emulated_source(source_type) -> str:
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
        name = emulated_source(src.source_type)
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
                   n=G.media[medium].n, source_type=emulated_source(src.source_type),
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
        m = Model()
        m.G = Geometry(nx=self.nx, ny=self.ny, nz=self.nz, Lx=self.Lx, Ly=self.Ly, Lz=self.Lz,
                       media=[Medium("tissue", mua=mua, mus=mus, g=self.g, n=self.n)])
        if self.media is not None:
            m.G.media = [Medium(f"medium {i}", mua=mua if i == self.estimated else p[0],
                                mus=mus if i == self.estimated else p[1], g=p[2], n=p[3])
                         for i, p in enumerate(self.media)]
            m.G.geom_func, m.G.geom_func_params = voxel_map, self.medium_map
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


def voxel_map(X, Y, Z, M):
    """``G.geom_func`` of a spec with several media: its stored voxel map (picklable)."""
    return M
