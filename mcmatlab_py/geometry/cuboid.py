"""The voxel cuboid and its media: MCmatlab's ``model.G`` (:class:`Geometry`).

x and y span [-Lx/2, Lx/2] and [-Ly/2, Ly/2]; z spans [0, Lz] and points into the
tissue. ``geom_func`` maps voxel-centre coordinates to medium indices; a bad value raises
a ``ValueError`` that names the field and the value.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from fem.checks import check_number, shorten

from .._strict import StrictAttributes
from .media import Medium, check_positive, n_arguments

__all__ = ["MIN_VOXEL_SIZE", "Geometry", "check_int"]

MIN_VOXEL_SIZE = 1e-7  #: cm: smaller voxels make the kernel's face distances underflow


def check_int(owner: str, name: str, value, minimum: int = 1, maximum: int | None = None) -> int:
    """``owner.name`` as an int in [minimum, maximum]; ValueError naming it otherwise."""
    return check_number(f"{owner}.{name}", value, integer=True, lo=minimum, hi=maximum)


@dataclass
class Geometry(StrictAttributes):
    """The voxel cuboid (MCmatlab's ``model.G``).

    x and y span [-Lx/2, Lx/2] and [-Ly/2, Ly/2]; z spans [0, Lz] and points into
    the tissue (z = 0 is the irradiated surface). Voxel (i, j, k) has its centre at
    ``(x[i], y[j], z[k])``.
    """

    nx: int = 100  #: number of voxels along x
    ny: int = 100  #: number of voxels along y
    nz: int = 100  #: number of voxels along z
    Lx: float = 0.1  #: cm
    Ly: float = 0.1  #: cm
    Lz: float = 0.1  #: cm
    media: list[Medium] = field(default_factory=list)  #: media, indexed by ``geom_func``
    #: ``geom_func(X, Y, Z, params)`` or ``geom_func(X, Y, Z)`` -> (nx, ny, nz) int medium
    #: index at the voxel centres (cm); ``None`` fills the cuboid with ``media[0]``.
    geom_func: Callable | None = None
    #: anything, passed as ``params`` to a four-argument ``geom_func`` (MCmatlab's geomFuncParams)
    geom_func_params: object = None

    _owner_label = "G"
    _renamed = {"mediaPropertiesFunc": "media"}
    _not_built = ("silentMode", "M_raw")
    _instead = {"mediaPropParams": "G.media is the list of Medium itself (MCmatlab's "
                "mediaPropertiesFunc, called with mediaPropParams): build the list from your "
                "parameters, e.g. G.media = my_media(params), and again when they change"}

    #: more voxels than this cannot be held (a medium map, per-thread int64 tallies)
    MAX_VOXELS = 200_000_000

    def validate(self) -> None:
        for name in ("nx", "ny", "nz"):
            setattr(self, name, check_int("G", name, getattr(self, name)))
        n = self.nx * self.ny * self.nz
        if n > self.MAX_VOXELS:
            raise ValueError(f"G.nx * G.ny * G.nz = {n:.3g} voxels is more than this machine can "
                             f"hold (limit {self.MAX_VOXELS}: medium map and tallies)")
        for name in ("Lx", "Ly", "Lz"):
            setattr(self, name, check_positive("G", name, getattr(self, name)))
        for L, n in (("Lx", "nx"), ("Ly", "ny"), ("Lz", "nz")):
            if getattr(self, L) / getattr(self, n) < MIN_VOXEL_SIZE:
                raise ValueError(f"G.{L} / G.{n} = {getattr(self, L) / getattr(self, n):.3g} cm is "
                                 f"below the smallest voxel size {MIN_VOXEL_SIZE:g} cm (1 nm)")
        if not isinstance(self.media, list | tuple):
            raise ValueError(f"G.media must be a list of Medium, got {shorten(repr(self.media))}")
        if not self.media:
            raise ValueError("G.media must hold at least one Medium, got []")
        if self.geom_func is not None and not callable(self.geom_func):
            raise ValueError(f"G.geom_func must be a function of (X, Y, Z) or (X, Y, Z, params), "
                             f"or None, got {shorten(repr(self.geom_func))}")
        for i, m in enumerate(self.media):
            if not isinstance(m, Medium):
                raise ValueError(f"G.media[{i}] must be a Medium, got {m!r}")
            m.__post_init__()  # re-check values changed after construction

    @property
    def grid(self):
        """The voxel grid as a :class:`fem.BoxGrid` (one definition of coordinates)."""
        from fem import BoxGrid

        return BoxGrid(self.nx, self.ny, self.nz, self.Lx, self.Ly, self.Lz)

    @property
    def dx(self) -> float:
        """cm, voxel size along x (likewise ``dy``, ``dz``)."""
        return self.grid.dx

    @property
    def dy(self) -> float:
        return self.grid.dy

    @property
    def dz(self) -> float:
        return self.grid.dz

    @property
    def x(self) -> np.ndarray:
        """(nx,) voxel-centre x coordinates, cm (likewise ``y``, ``z``)."""
        return self.grid.x

    @property
    def y(self) -> np.ndarray:
        return self.grid.y

    @property
    def z(self) -> np.ndarray:
        return self.grid.z

    def medium_map(self) -> np.ndarray:
        """(nx, ny, nz) int32 medium index of every voxel (MCmatlab's ``M``), validated."""
        self.validate()
        if self.geom_func is None:
            return np.zeros((self.nx, self.ny, self.nz), dtype=np.int32)
        X, Y, Z = np.meshgrid(self.x, self.y, self.z, indexing="ij")
        k = n_arguments(self.geom_func)
        if k == 4:
            M = np.asarray(self.geom_func(X, Y, Z, self.geom_func_params))
        elif k == 3 or k is None:
            if self.geom_func_params is not None:
                raise ValueError("G.geom_func_params is set but G.geom_func takes (X, Y, Z): give "
                                 f"it a fourth argument, got {self.geom_func!r}")
            M = np.asarray(self.geom_func(X, Y, Z))
        else:
            raise ValueError("G.geom_func must take (X, Y, Z) or (X, Y, Z, params), "
                             f"got {self.geom_func!r} taking {k} arguments")
        if M.shape != X.shape:
            raise ValueError(
                f"G.geom_func must return an array of shape {X.shape}, got shape {M.shape}"
            )
        if M.dtype.kind not in "iub":
            if M.dtype.kind == "f" and np.all(np.isfinite(M)) and np.all(M == np.round(M)):
                M = M.astype(np.int64)
            else:
                raise ValueError(f"G.geom_func must return integer medium indices, got {M.dtype}")
        bad = (M < 0) | (M >= len(self.media))
        if bad.any():
            value = int(M[bad].flat[0])
            raise ValueError(
                f"G.geom_func returned medium index {value}, outside 0..{len(self.media) - 1} "
                f"(G.media has {len(self.media)} entries)"
            )
        return M.astype(np.int32)
