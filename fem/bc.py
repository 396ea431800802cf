"""Thermal boundary conditions on the six faces of the simulation cuboid.

Faces are named by axis and side: ``"x-"``, ``"x+"``, ``"y-"``, ``"y+"``,
``"z-"`` (the top, irradiated surface ``z = 0``) and ``"z+"`` (the bottom,
``z = Lz``).  A face is located on any mesh as the plane of the mesh's bounding
box, so user meshes must be boxes too.

Kinds (MCmatlab's ``heatBoundaryType`` numbers where they exist):

- 0, ``"insulating"``: no heat flux (natural condition, nothing to assemble);
- 1, ``"fixed"``: Dirichlet, the face nodes are held at ``temperature``; with
  ``temperature=None`` they keep the temperature they have when stepping
  starts, which is MCmatlab's type 1 (all cuboid faces at ``T_initial``);
- 2, ``"convective"``: Robin, heat flux out ``h (T - temperature)`` with ``h``
  in W cm^-2 K^-1 and ``temperature`` the ambient temperature.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

__all__ = ["FACES", "FaceBC", "HeatBoundary", "face_facets", "face_nodes"]

#: Face names in a fixed order; a later Dirichlet face wins on shared edges.
FACES = ("x-", "x+", "y-", "y+", "z-", "z+")

_KINDS = {0: "insulating", 1: "fixed", 2: "convective"}
_KIND_NAMES = tuple(_KINDS.values())


def _kind(value) -> str:
    if isinstance(value, str) and value in _KIND_NAMES:
        return value
    if not isinstance(value, bool) and isinstance(value, int | np.integer) and int(value) in _KINDS:
        return _KINDS[int(value)]
    raise ValueError(f"kind must be one of {_KIND_NAMES} or 0, 1, 2, got {value!r}")


@dataclass(frozen=True)
class FaceBC:
    """The thermal condition on one face.

    Parameters
    ----------
    kind : {"insulating", "fixed", "convective"} or {0, 1, 2}
    temperature : float or None
        deg C.  ``"fixed"``: the held temperature (None: hold the nodes at
        their temperature when stepping starts).  ``"convective"``: the
        ambient temperature (required).
    h : float
        W cm^-2 K^-1, heat transfer coefficient (``"convective"`` only, > 0).
    """

    kind: str = "insulating"
    temperature: float | None = None
    h: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "kind", _kind(self.kind))
        if self.temperature is not None:
            T = float(self.temperature)
            if not np.isfinite(T):
                raise ValueError(f"temperature must be finite, got {self.temperature!r}")
            object.__setattr__(self, "temperature", T)
        h = float(self.h)
        if self.kind == "convective":
            if not np.isfinite(h) or h <= 0:
                raise ValueError(f"h must be > 0 for a convective face, got {self.h!r}")
            if self.temperature is None:
                raise ValueError(
                    "temperature (ambient) is required for a convective face, got None"
                )
        elif h != 0.0:
            raise ValueError(f"h must be 0 for a {self.kind} face, got {self.h!r}")
        object.__setattr__(self, "h", h)


def _face_bc(value) -> FaceBC:
    if isinstance(value, FaceBC):
        return value
    if isinstance(value, Mapping):
        return FaceBC(**value)
    return FaceBC(kind=value)


@dataclass(frozen=True)
class HeatBoundary:
    """Thermal conditions on the six faces of the cuboid.

    Parameters
    ----------
    faces : mapping of face name to FaceBC
        Face names from :data:`FACES`; values may also be a kind (``0``,
        ``"insulating"``, ...) or a dict of :class:`FaceBC` arguments.  Missing
        faces are insulating.

    Examples
    --------
    >>> top = FaceBC("convective", temperature=20.0, h=1e-3)
    >>> bc = HeatBoundary({"z-": top, "z+": FaceBC("fixed", temperature=37.0)})
    >>> bc["x-"].kind
    'insulating'
    """

    faces: Mapping[str, FaceBC] = field(default_factory=dict)

    def __post_init__(self):
        faces = dict(self.faces)
        unknown = [f for f in faces if f not in FACES]
        if unknown:
            raise ValueError(f"faces keys must be in {FACES}, got {unknown[0]!r}")
        full = {f: _face_bc(faces.get(f, FaceBC())) for f in FACES}
        object.__setattr__(self, "faces", full)

    def __getitem__(self, face: str) -> FaceBC:
        return self.faces[face]

    @classmethod
    def from_mcmatlab(
        cls, heat_boundary_type: int, *, temperature: float | None = None, h: float = 0.0
    ) -> HeatBoundary:
        """Same condition on every face from an MCmatlab-style type number.

        Parameters
        ----------
        heat_boundary_type : {0, 1, 2}
            0 insulating, 1 fixed (``temperature=None``: hold at the initial
            temperature, as MCmatlab), 2 convective (needs ``h`` and the
            ambient ``temperature``).
        """
        kind = _kind(heat_boundary_type)
        if kind == "insulating":
            return cls({f: FaceBC() for f in FACES})
        return cls({f: FaceBC(kind, temperature=temperature, h=h) for f in FACES})

    def of_kind(self, kind) -> tuple[str, ...]:
        """Names of the faces of a kind."""
        kind = _kind(kind)
        return tuple(f for f in FACES if self.faces[f].kind == kind)

    @property
    def is_insulated(self) -> bool:
        return all(bc.kind == "insulating" for bc in self.faces.values())


def _face_plane(mesh, face: str) -> tuple[int, float, float]:
    if face not in FACES:
        raise ValueError(f"face must be one of {FACES}, got {face!r}")
    axis = "xyz".index(face[0])
    x = mesh.p[axis]
    lo, hi = float(x.min()), float(x.max())
    tol = 1e-9 * max(hi - lo, np.abs(mesh.p).max())
    return axis, (lo if face[1] == "-" else hi), tol


def face_nodes(mesh, face: str) -> np.ndarray:
    """Indices of the mesh nodes on a face plane of the mesh's bounding box."""
    axis, value, tol = _face_plane(mesh, face)
    return np.flatnonzero(np.abs(mesh.p[axis] - value) <= tol)


def face_facets(mesh, face: str) -> np.ndarray:
    """Boundary triangles on a face, shape (3, nfacets), node indices.

    A triangle of an element that lies in a bounding-box plane is a boundary
    facet (the mesh is on one side of the plane), so no facet table is built.
    """
    axis, value, tol = _face_plane(mesh, face)
    on = np.abs(mesh.p[axis] - value) <= tol
    t = mesh.t
    tris = []
    for tri in ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2)):
        rows = t[list(tri)]
        tris.append(rows[:, on[rows].all(axis=0)])
    return np.hstack(tris)
