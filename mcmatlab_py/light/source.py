"""Light sources: validation and packing for the launch kernel (:mod:`mcmatlab_py.light._sources`).

MCmatlab's ``lightSource`` has six source types (``sourceType``), accepted here by
number or by name:

=====  ==============  ======================================================
code   name            source
=====  ==============  ======================================================
0      ``pencil``      a single ray through the focus
1      ``isotropic``   isotropic point (``emitter_length = 0``) or line emitter,
                       centred on the focus, the line along the beam axis
2      ``plane_wave``  uniform over the top face, along the beam axis
3      ``lg01``        Laguerre-Gaussian LG01 beam
4      ``radial``      radially factorizable beam: focal-plane distribution
                       (top-hat, Gaussian, custom array) times angular
                       distribution (top-hat, Gaussian, Lambertian, custom)
5      ``xy``          X/Y factorizable beam (e.g. a rectangular LED), turned
                       by ``psi`` about its axis
=====  ==============  ======================================================

This port also keeps its earlier names: ``tophat`` and ``gaussian`` (a collimated
beam of ``radius``) and ``isotropic_point`` (= ``isotropic``).

Geometry, as in MCmatlab's kernel: the beam axis ``u`` points along the polar angle
``theta`` and azimuth ``phi`` (``theta = 0``: straight down, +z). The transverse axes
``v`` (X) and ``w`` (Y): for ``theta = 0``, ``v`` is +x and ``w`` is +y; for an oblique
beam ``v`` is horizontal, normal to the plane of incidence (``u x z``, normalised);
both are then turned by ``psi`` about ``u``, and ``w = u x v``. Each ray crosses the
focal plane (through the focus ``(x_focus, y_focus, z_focus)``, normal to ``u``) at
a point drawn from the focal-plane distribution, along a direction drawn from the
angular one (tilted from ``u``; angular widths are half-angles in rad, the
distributions live on the tangent of the angle as in MCmatlab); the packet starts
where that ray crosses ``z = 0``. A focus below the surface makes the beam converge
inside the tissue. With ``MC.matched_interfaces = False`` the rays refract at the
top face (Snell, Fresnel's reflectance at their angle): the focus is then where they
would meet without refraction, as for a beam focused through a window in MCmatlab.

Packets that start off the top face, that cannot enter it (a ray pointing up), or
that are emitted outside the cuboid or inside a perfect reflector (``n = inf``) are
counted in ``MC.missed_fraction`` (MCmatlab launches them again instead).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from fem.checks import check_number, shorten

from .._strict import StrictAttributes
from ..geometry.media import check_positive
from . import _sources as S

if TYPE_CHECKING:
    from ..geometry.cuboid import Geometry

__all__ = [
    "IntensityDistribution",
    "LightSource",
    "beam_axes",
    "check_source_distribution",
    "pwl_table",
    "sample_light_source",
    "source_arrays",
    "source_kind",
    "validate_light_source",
]

#: MCmatlab's source type codes and our names for them
SOURCE_TYPE_NAMES = ("pencil", "isotropic", "plane_wave", "lg01", "radial", "xy")
#: every accepted string: the names above and this port's earlier names
SOURCE_TYPES = (*SOURCE_TYPE_NAMES, "tophat", "gaussian", "isotropic_point")
_ALIASES = {"isotropic_point": "isotropic"}

#: the 1-D distributions of MCmatlab's sourceIntensityDistribution (codes 0, 1, 2)
DISTRIBUTION_NAMES = {"tophat": S.D_TOPHAT, "top-hat": S.D_TOPHAT, "gaussian": S.D_GAUSSIAN,
                      "lambertian": S.D_LAMBERTIAN, "cosine": S.D_LAMBERTIAN}


def _lg01_outer_radius_ratio() -> float:
    """r / w where the LG01 intensity ``r^2 exp(-2 r^2 / w^2)`` falls to 1/e^2 of its peak
    outside the ring: with ``s = 2 r^2 / w^2``, ``s e^-s = e^-3`` for ``s > 1`` (s = 4.505).

    MCmatlab's ``radialWidth`` of an LG01 beam is this outer radius (its constant 1.50087).
    """
    s = 4.5
    for _ in range(50):  # Newton on s - ln s - 3 = 0
        s -= (s - math.log(s) - 3.0) / (1.0 - 1.0 / s)
    return math.sqrt(s / 2.0)


LG01_RADIUS_RATIO = _lg01_outer_radius_ratio()


@dataclass
class IntensityDistribution(StrictAttributes):
    """A focal-plane or angular intensity distribution (MCmatlab's ``sourceIntensityDistribution``).

    Each ``*_distr`` is ``0`` / ``"tophat"``, ``1`` / ``"gaussian"``, ``2`` /
    ``"lambertian"`` (angular only) or a 1-D array of intensities (a custom
    distribution, need not be normalised; sampled exactly as a piecewise-linear
    function). ``None`` leaves it unset (MCmatlab's NaN).

    Widths: in the focal plane, cm; angular, rad (half-angles). For top-hat and
    Gaussian the width is the radius (Gaussian: the 1/e^2 intensity radius); for a
    custom array the half-width of the whole array: a radial array spans radii
    ``[0, width]`` (intensity per area), an X or Y array spans ``[-width, width]``.
    Angular distributions act on ``tan`` of the angle (paraxial, as MCmatlab).
    """

    radial_distr: int | str | np.ndarray | None = None  #: radial beams (source type 4)
    radial_width: float | None = None  #: cm or rad
    x_distr: int | str | np.ndarray | None = None  #: X/Y beams (source type 5), along v
    x_width: float | None = None  #: cm or rad
    y_distr: int | str | np.ndarray | None = None  #: along w
    y_width: float | None = None  #: cm or rad

    _owner_label = "IntensityDistribution"


def source_kind(source_type) -> str:
    """The canonical name of ``source_type`` (an MCmatlab code 0..5 or a name)."""
    if isinstance(source_type, str):
        if source_type in SOURCE_TYPES:
            return _ALIASES.get(source_type, source_type)
    elif not isinstance(source_type, bool):
        try:
            code = float(source_type)
        except (TypeError, ValueError):
            code = math.nan
        if code.is_integer() and 0 <= code < len(SOURCE_TYPE_NAMES):
            return SOURCE_TYPE_NAMES[int(code)]
    raise ValueError(f"MC.light_source.source_type must be one of {SOURCE_TYPES} or an MCmatlab "
                     f"code 0..{len(SOURCE_TYPE_NAMES) - 1}, got {source_type!r}")


def _distribution(owner: str, value, *, angular: bool):
    """(code, custom array or None) of a ``*_distr`` value; ValueError naming ``owner``."""
    allowed = "0 (top-hat), 1 (Gaussian)" + (", 2 (Lambertian)" if angular else "")
    if isinstance(value, str):
        code = DISTRIBUTION_NAMES.get(value.lower())
        if code is None or (code == S.D_LAMBERTIAN and not angular):
            raise ValueError(f"{owner} must be {allowed} or an array, got {value!r}")
        return code, None
    if value is None:
        raise ValueError(f"{owner} must be set for this source type: {allowed} or an array")
    arr = np.asarray(value, dtype=np.float64) if not isinstance(value, bool) else None
    if arr is None or arr.ndim > 1:
        raise ValueError(f"{owner} must be {allowed} or a 1-D array, got {value!r}")
    if arr.size == 1:
        code = float(arr.ravel()[0])
        if code in (0.0, 1.0) or (angular and code == 2.0):
            return int(code), None
        raise ValueError(f"{owner} must be {allowed} or an array, got {value!r}")
    if arr.size < 2 or not np.all(np.isfinite(arr)) or np.any(arr < 0) or not arr.sum() > 0:
        raise ValueError(f"{owner} as an array must hold >= 2 finite, non-negative values with a "
                         f"positive sum, got {value!r}")
    return S.D_CUSTOM, arr


def _width(owner: str, value, *, angular: bool) -> float:
    """A width >= 0 (cm, or rad below pi/2 if ``angular``); ValueError naming ``owner``."""
    if value is None:
        raise ValueError(f"{owner} must be set for this source type")
    w = check_number(owner, value, lo=0.0, hi=1e3)
    if angular and not w < math.pi / 2:
        raise ValueError(f"{owner} must be in [0, pi/2) rad, got {shorten(repr(value))}")
    return w


def _number(name: str, value) -> float:
    return check_number(f"MC.light_source.{name}", value, lo=-1e3, hi=1e3)


def validate_light_source(src, G) -> None:
    """Check and normalise the fields of a :class:`~mcmatlab_py.light.source.LightSource`.

    Raises ValueError naming the field and the value; everything the kernel needs is
    then built by :func:`source_arrays` without further checks.
    """
    kind = source_kind(src.source_type)
    for name in ("x_focus", "y_focus", "z_focus", "theta", "phi", "psi"):
        setattr(src, name, _number(name, getattr(src, name)))
    src.emitter_length = check_positive("MC.light_source", "emitter_length", src.emitter_length,
                                        allow_zero=True)
    src.radius = check_positive("MC.light_source", "radius", src.radius,
                                allow_zero=kind not in ("tophat", "gaussian"))
    if kind == "isotropic":
        inside = (abs(src.x_focus) <= G.Lx / 2 and abs(src.y_focus) <= G.Ly / 2
                  and 0 <= src.z_focus <= G.Lz)
        if not inside:
            raise ValueError("MC.light_source (x_focus, y_focus, z_focus) must lie inside the "
                             f"cuboid, got {(src.x_focus, src.y_focus, src.z_focus)}")
    elif not math.cos(src.theta) > 1e-9:
        raise ValueError("MC.light_source.theta must aim the beam into the top face "
                         f"(cos(theta) > 0), got {src.theta!r}")
    for name in ("focal_plane_intensity_distribution", "angular_intensity_distribution"):
        if not isinstance(getattr(src, name), IntensityDistribution):
            raise ValueError(f"MC.light_source.{name} must be an IntensityDistribution, "
                             f"got {getattr(src, name)!r}")
    _beam_distributions(src, kind)  # raises on a missing or bad distribution


def _beam_distributions(src, kind: str):
    """[(code, array, width)] of near 1, near 2, far 1, far 2 for lg01/radial/xy beams."""
    fp = "MC.light_source.focal_plane_intensity_distribution"
    an = "MC.light_source.angular_intensity_distribution"
    FP, AN = src.focal_plane_intensity_distribution, src.angular_intensity_distribution
    if kind == "lg01":
        return [(None, None, _width(f"{fp}.radial_width", FP.radial_width, angular=False)),
                None, (None, None, _width(f"{an}.radial_width", AN.radial_width, angular=True)),
                None]
    if kind == "radial":
        c1, a1 = _distribution(f"{fp}.radial_distr", FP.radial_distr, angular=False)
        c3, a3 = _distribution(f"{an}.radial_distr", AN.radial_distr, angular=True)
        w3 = 0.0 if c3 == S.D_LAMBERTIAN else _width(f"{an}.radial_width", AN.radial_width,
                                                      angular=True)
        return [(c1, a1, _width(f"{fp}.radial_width", FP.radial_width, angular=False)), None,
                (c3, a3, w3), None]
    if kind == "xy":
        out = []
        for owner, dist, angular in ((fp, FP, False), (an, AN, True)):
            for ax in ("x", "y"):
                c, a = _distribution(f"{owner}.{ax}_distr", getattr(dist, f"{ax}_distr"),
                                     angular=angular)
                w = 0.0 if c == S.D_LAMBERTIAN else _width(f"{owner}.{ax}_width",
                                                           getattr(dist, f"{ax}_width"),
                                                           angular=angular)
                out.append((c, a, w))
        if (out[2][0] == S.D_LAMBERTIAN) != (out[3][0] == S.D_LAMBERTIAN):
            raise ValueError(f"{an}.x_distr and .y_distr must both be Lambertian (2), or neither; "
                             f"got {AN.x_distr!r} and {AN.y_distr!r}")
        return out
    return [None, None, None, None]


def check_source_distribution(value, shape: tuple[int, int, int], n_wavelengths: int | None = None,
                              *, owner: str = "MC") -> np.ndarray | None:
    """``MC.source_distribution`` as a float64 (nx, ny, nz) array, or None; ValueError if bad.

    A broadband run (``n_wavelengths`` given) also takes (nx, ny, nz, n_wavelengths), the
    emitters of each wavelength (MCmatlab's 4-D sourceDistribution): each wavelength's share
    of the power is its slice's share of the sum.
    """
    if value is None:
        return None
    arr = np.asarray(value, dtype=np.float64)
    name = f"{owner}.source_distribution"
    shapes = [tuple(shape)]
    if n_wavelengths is not None:
        shapes.append((*shape, n_wavelengths))
    if arr.shape not in shapes:
        broadband = f" or (nx, ny, nz, len({owner}.wavelength)) = {shapes[1]}" \
            if n_wavelengths is not None else ""
        raise ValueError(f"{name} must have the shape (nx, ny, nz) = {tuple(shape)}{broadband}, "
                         f"got shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0) or not arr.sum() > 0:
        raise ValueError(f"{name} must be finite and non-negative with a positive sum")
    return arr


def pwl_table(q: np.ndarray) -> np.ndarray:
    """(2 n,) float64: a density at n equispaced nodes, then its normalised cumulative integral.

    The density is linear between nodes (trapezoids); the kernel samples it exactly
    (:func:`mcmatlab_py.light._sources.sample_pwl`).
    """
    q = np.asarray(q, dtype=np.float64)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (q[1:] + q[:-1]))])
    cdf /= cdf[-1]
    cdf[-1] = 1.0
    return np.concatenate([q, cdf])


def beam_axes(theta: float, phi: float, psi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit vectors ``u`` (beam axis), ``v`` (X) and ``w = u x v`` (Y) of MCmatlab's convention."""
    u = np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                  math.cos(theta)])
    if u[2] == 1.0:
        w = np.array([1.0, 0.0, 0.0])
    else:
        w = np.cross(u, [0.0, 0.0, 1.0])
        w /= np.linalg.norm(w)
    # Rodrigues: turn w by psi about u (right-handed)
    v = w * math.cos(psi) + np.cross(u, w) * math.sin(psi) + u * (u @ w) * (1 - math.cos(psi))
    w = np.cross(u, v)
    w /= np.linalg.norm(w)
    return u, v, w


def source_arrays(src, G, source_distribution: np.ndarray | None = None):
    """Pack a validated source into the kernel's ``(si, sf, tab, vox)`` arrays.

    With a ``source_distribution`` ((nx, ny, nz), validated) the light source is
    ignored, as in MCmatlab: packets are emitted isotropically from uniformly random
    points of voxels chosen with probability proportional to the array.
    """
    si = np.zeros(S.SI_SIZE, dtype=np.int64)
    sf = np.zeros(S.SF_SIZE, dtype=np.float64)
    tables: list[np.ndarray] = []
    vox = np.zeros(1, dtype=np.int64)

    def add_table(slot: int, q: np.ndarray) -> None:
        offset = sum(t.size for t in tables)
        tables.append(pwl_table(q))
        si[S.SI_TAB + 2 * slot] = offset
        si[S.SI_TAB + 2 * slot + 1] = q.size

    if source_distribution is not None:
        flat = source_distribution.ravel()
        vox = np.flatnonzero(flat).astype(np.int64)
        cdf = np.concatenate([[0.0], np.cumsum(flat[vox])])
        cdf /= cdf[-1]
        cdf[-1] = 1.0
        si[S.SI_KIND] = S.SRC_VOLUME
        si[S.SI_VOX_OFF] = 0
        si[S.SI_VOX_N] = vox.size
        return si, sf, cdf, vox

    kind = source_kind(src.source_type)
    u, v, w = beam_axes(src.theta, src.phi, src.psi)
    sf[S.SF_F:S.SF_F + 3] = (src.x_focus + G.Lx / 2, src.y_focus + G.Ly / 2, src.z_focus)
    sf[S.SF_U:S.SF_U + 3] = u
    sf[S.SF_V:S.SF_V + 3] = v
    sf[S.SF_W:S.SF_W + 3] = w
    sf[S.SF_LENGTH] = src.emitter_length
    sf[S.SF_RADIUS] = src.radius
    sf[S.SF_LG01] = LG01_RADIUS_RATIO
    si[S.SI_SURFACE] = 0 if kind == "isotropic" else 1
    vertical = src.theta == 0.0
    simple = {"pencil": S.SRC_PENCIL, "tophat": S.SRC_TOPHAT, "gaussian": S.SRC_GAUSSIAN}
    if kind == "isotropic":
        si[S.SI_KIND] = S.SRC_ISOTROPIC
    elif kind == "plane_wave":
        si[S.SI_KIND] = S.SRC_PLANE_WAVE
    elif kind in simple and vertical:
        si[S.SI_KIND] = simple[kind]  # the collimated beams along +z, as this port always had
    else:
        si[S.SI_KIND] = S.SRC_BEAM
        if kind == "pencil":
            si[S.SI_NEAR], si[S.SI_FAR] = S.NEAR_POINT, S.FAR_NONE
        elif kind in ("tophat", "gaussian"):
            si[S.SI_NEAR], si[S.SI_FAR] = S.NEAR_RADIAL, S.FAR_NONE
            si[S.SI_D1] = S.D_TOPHAT if kind == "tophat" else S.D_GAUSSIAN
            sf[S.SF_NW1] = src.radius
        elif kind == "lg01":
            d = _beam_distributions(src, kind)
            si[S.SI_NEAR], si[S.SI_FAR] = S.NEAR_LG01, S.FAR_LG01
            sf[S.SF_NW1] = d[0][2]
            sf[S.SF_FW1] = d[2][2]  # an angle (paraxial), as MCmatlab
        else:
            d = _beam_distributions(src, kind)
            radial = kind == "radial"
            si[S.SI_NEAR] = S.NEAR_RADIAL if radial else S.NEAR_XY
            si[S.SI_FAR] = S.FAR_RADIAL if radial else S.FAR_XY
            for slot, entry in enumerate(d):
                if entry is None:
                    continue
                code, arr, width = entry
                si[S.SI_D1 + slot] = code
                if slot < 2:
                    sf[S.SF_NW1 + slot] = width
                else:
                    sf[S.SF_FW1 + slot - 2] = math.tan(width)
                if arr is not None:
                    # radial arrays give intensity per area: the density in r is r I(r)
                    q = arr * np.linspace(0.0, 1.0, arr.size) if radial else arr
                    add_table(slot, q)
    tab = np.concatenate(tables) if tables else np.zeros(1)
    return si, sf, tab, vox


def sample_light_source(model, n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Launch points and directions of ``n`` packets of ``model.MC``'s source, untransported.

    Returns ``x, y, z`` (cm, the model's coordinates), ``ux, uy, uz`` and ``ok``
    (False for rays that cannot enter the top face), each (n,). Before any
    refraction at the surface and whether or not the point lies on the cuboid: to
    look at a source, or to test it against its analytic distribution.
    """
    G, MC = model.G, model.MC
    G.validate()
    MC.light_source.validate(G)
    S_ = check_source_distribution(MC.source_distribution, (G.nx, G.ny, G.nz))
    si, sf, tab, vox = source_arrays(MC.light_source, G, S_)
    out = S.launch_many(si, sf, tab, vox, G.nx, G.ny, G.nz, G.dx, G.dy, G.dz,
                        np.uint64(seed), int(n))
    return {"x": out[:, 0] - G.Lx / 2, "y": out[:, 1] - G.Ly / 2, "z": out[:, 2],
            "ux": out[:, 3], "uy": out[:, 4], "uz": out[:, 5], "ok": out[:, 6] > 0}


@dataclass
class LightSource(StrictAttributes):
    """The light source (MCmatlab's ``model.MC.lightSource``); see the module functions below.

    ``source_type`` is MCmatlab's code 0..5 or its name (``pencil``, ``isotropic``,
    ``plane_wave``, ``lg01``, ``radial``, ``xy``); this port's ``tophat`` and
    ``gaussian`` (a collimated beam of ``radius``) and ``isotropic_point`` work as
    before. Beams enter the top face along the axis (``theta``, ``phi``) through the
    focus; isotropic emitters sit at the focus.
    """

    source_type: str | int = "pencil"
    radius: float = 0.0  #: cm: ``tophat`` radius, or the ``gaussian`` 1/e^2 intensity radius
    x_focus: float = 0.0  #: cm
    y_focus: float = 0.0  #: cm
    z_focus: float = 0.0  #: cm: focal plane depth of beams, position of isotropic emitters
    theta: float = 0.0  #: rad, polar angle of the beam axis (0: along +z, into the tissue)
    phi: float = 0.0  #: rad, azimuth of the beam axis
    psi: float = 0.0  #: rad, rotation of an X/Y beam about its axis
    emitter_length: float = 0.0  #: cm, length of an isotropic line emitter (0: a point)
    #: near field: the intensity in the focal plane (radial or X/Y, widths in cm)
    focal_plane_intensity_distribution: IntensityDistribution = field(
        default_factory=IntensityDistribution)
    #: far field: the intensity over ray angles (radial or X/Y, half-angles in rad)
    angular_intensity_distribution: IntensityDistribution = field(
        default_factory=IntensityDistribution)

    _owner_label = "MC.light_source"
    _renamed = {"FPID": "focal_plane_intensity_distribution",
                "AID": "angular_intensity_distribution", "beamType": "source_type"}

    def validate(self, G: Geometry) -> None:
        validate_light_source(self, G)
