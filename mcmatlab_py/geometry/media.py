"""Media: the optical and thermal properties of one tissue type (MCmatlab's ``mediumProperties``).

As in MCmatlab, ``mua``, ``mus`` and ``g`` may be a number, a function of wavelength
``f(wavelength)`` (nm), or a function ``f(wavelength, FR, T, FD)`` of wavelength,
fluence rate (W/cm^2), temperature (deg C) and fractional damage (0..1); ``n`` a
number or a function of wavelength; ``VHC`` and ``TC`` a number or a function
``f(T, FD)``. Functions of FR, T or FD receive 1-D arrays over the voxels of the
medium and must compute element-wise; such a medium is split into ``n_bins``
sub-media (see :mod:`mcmatlab_py.geometry.media_bins`).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fem.checks import check_number, shorten

from .._strict import StrictAttributes

__all__ = ["Medium", "check_positive"]

OPTICAL_FIELDS = ("mua", "mus", "g")  #: may depend on (wavelength, FR, T, FD)
THERMAL_FIELDS = ("VHC", "TC")  #: may depend on (T, FD)
#: upper limits of user-given fields, far beyond any tissue or laser but small enough that
#: no product in the simulations overflows (G.Lz = 1e300 or mua = 1e300 gave tracebacks
#: and nonsense): cm^-1, J cm^-3 K^-1, W cm^-1 K^-1, J/mol, 1/s, cm, W, s, W cm^-2 K^-1.
#: They are sanity bounds against unit mistakes, not physics. VHC: water has 4.19 and no
#: solid or liquid much over 5, but MCmatlab's Example 14 gives 2000 to a material on
#: purpose (slow heating); 1e5 lets such choices through and still refuses SI units
#: (J m^-3 K^-1: water 4.19e6). TC: diamond, the best bulk conductor, has 22 (water 0.0058);
#: 1e4 leaves room for idealised heat sinks (a region held near one temperature).
LIMITS = {"mua": 1e6, "mus": 1e6, "VHC": 1e5, "TC": 1e4, "E": 1e8, "A": 1e250,
          "Lx": 1e3, "Ly": 1e3, "Lz": 1e3, "radius": 1e3, "P": 1e6, "duration_on": 1e7,
          "duration_off": 1e7, "dt": 1e7, "heat_transfer_coefficient": 1e3}

#: field -> (accepted argument counts of a function, what they are)
_ARITIES = {
    "mua": ((1, 4), "(wavelength) or (wavelength, FR, T, FD)"),
    "mus": ((1, 4), "(wavelength) or (wavelength, FR, T, FD)"),
    "g": ((1, 4), "(wavelength) or (wavelength, FR, T, FD)"),
    "n": ((1,), "(wavelength)"),
    "VHC": ((2,), "(T, FD)"),
    "TC": ((2,), "(T, FD)"),
    "QY": ((1, 4), "(wavelength) or (wavelength, FR, T, FD)"),
    "ES": ((1, 4), "(wavelength) or (wavelength, FR, T, FD)"),
}
#: fluorescence: quantum yield (of the excitation wavelength) and emission spectrum (of the
#: fluorescence wavelength); ``None``: the medium does not fluoresce
FLUORESCENCE_FIELDS = ("QY", "ES")


def check_positive(owner: str, field: str, value, *, allow_zero: bool = False) -> float:
    """Return ``value`` as float, or raise ValueError naming ``owner.field`` and the value
    (:func:`fem.checks.check_number` with ``lo = 0``, ``hi``: the field's physical limit)."""
    return check_number(f"{owner}.{field}", value, lo=0.0, lo_open=not allow_zero,
                        hi=LIMITS.get(field))


def _range_problem(field: str, v: np.ndarray) -> str | None:
    """What is wrong with values ``v`` of ``field`` (None if nothing): one rule per field."""
    if field == "n":
        if np.isnan(v).any():
            return "must not be NaN"
        return "must be >= 1" if (v < 1).any() else None  # inf: a perfect reflector
    if not np.isfinite(v).all():
        return "must be finite"
    if field == "g":
        return "must be in [-1, 1]" if (np.abs(v) > 1).any() else None
    if field in LIMITS and (v > LIMITS[field]).any():
        return f"must be <= {LIMITS[field]:g}"
    if field == "VHC":
        return "must be > 0" if (v <= 0).any() else None
    # TC = 0 is a perfect insulator (MCmatlab takes it): no heat crosses the medium
    return "must be >= 0" if (v < 0).any() else None  # mua, mus, E, A


def _first_bad(field: str, v: np.ndarray):
    for x in np.ravel(v):
        if _range_problem(field, np.asarray([x])):
            return float(x)
    return float(np.ravel(v)[0])


def n_arguments(f: Callable) -> int | None:
    """Number of positional arguments ``f`` takes (None if it cannot be told)."""
    nin = getattr(f, "nin", None)  # numpy ufuncs
    if isinstance(nin, int):
        return nin
    try:
        params = inspect.signature(f).parameters.values()
    except (TypeError, ValueError):
        return None
    kinds = [p.kind for p in params]
    if inspect.Parameter.VAR_POSITIONAL in kinds:
        return None
    # the arguments a call must give: those with defaults (f(theta, g=0.9)) are parameters
    return sum(p.kind in (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
               and p.default is inspect.Parameter.empty for p in params)


@dataclass
class Medium(StrictAttributes):
    """One medium of the geometry (MCmatlab's ``mediumProperties``).

    Parameters
    ----------
    name : str
        Label used in plots and error messages.
    mua : float or callable
        Absorption coefficient, cm^-1 (>= 0): a number, ``mua(wavelength)`` or
        ``mua(wavelength, FR, T, FD)``.
    mus : float or callable
        Scattering coefficient, cm^-1 (>= 0), as ``mua``.
    g : float or callable
        Henyey-Greenstein anisotropy in [-1, 1], as ``mua``; ``g = 1`` scatters
        without deflection (MCmatlab's air in examples 1, 3, 4).
    n : float or callable
        Refractive index (>= 1), or ``n(wavelength)``; ``inf`` is a perfect reflector.
    VHC : float or callable, optional
        Volumetric heat capacity, J cm^-3 K^-1 (> 0), or ``VHC(T, FD)``; needed by the heat
        simulation.
    TC : float or callable, optional
        Thermal conductivity, W cm^-1 K^-1 (>= 0; 0 is a perfect insulator), or
        ``TC(T, FD)``; needed by the heat simulation.
    E : float, optional
        Arrhenius activation energy, J/mol (>= 0), for thermal damage.
    A : float, optional
        Arrhenius frequency factor, 1/s (>= 0), for thermal damage.
    n_bins : int
        Sub-media that a medium with FR-, T- or FD-dependent properties is split into
        (MCmatlab's ``nBins``); 1 for others.
    custom_phase_func : callable or array, optional
        Phase function of the scattering angle theta (rad) per solid angle, not
        necessarily normalised (MCmatlab's ``customPhaseFunc``): ``f(theta)``,
        ``f(wavelength, theta)`` or values at equispaced angles over [0, pi]. Used
        instead of Henyey-Greenstein (``g`` is then ignored); see :mod:`mcmatlab_py.monte_carlo.optics`.
    """

    name: str
    mua: float | Callable
    mus: float | Callable
    g: float | Callable = 0.0
    n: float | Callable = 1.0
    VHC: float | Callable | None = None
    TC: float | Callable | None = None
    E: float | None = None
    A: float | None = None
    n_bins: int = 1
    #: phase function of the scattering angle theta (rad), per solid angle, not necessarily
    #: normalised: ``f(theta)``, ``f(wavelength, theta)`` (MCmatlab's customPhaseFunc) or
    #: values at equispaced angles over [0, pi]; replaces Henyey-Greenstein (``g`` unused)
    custom_phase_func: Callable | np.ndarray | None = None
    #: fluorescence quantum yield (photons out per photon absorbed), of the excitation
    #: wavelength: a number, ``QY(wavelength)`` or ``QY(wavelength, FR, T, FD)``; None: none
    QY: float | Callable | None = None
    #: emission spectrum of the fluorescence wavelength, not normalised (as ``QY``)
    ES: float | Callable | None = None

    _owner_label = "Medium"
    _renamed = {"nBins": "n_bins"}
    _not_built = ("PY",)

    def __post_init__(self):
        owner = self._label
        for field in ("mua", "mus", "g", "n", "VHC", "TC", *FLUORESCENCE_FIELDS):
            value = getattr(self, field)
            if value is None and field in (*THERMAL_FIELDS, *FLUORESCENCE_FIELDS):
                continue
            if callable(value):
                self._arity(field)
            else:
                setattr(self, field, self._number(field, value))
        for field in ("E", "A"):
            value = getattr(self, field)
            if value is not None:
                setattr(self, field, check_positive(owner, field, value, allow_zero=True))
        self.n_bins = check_number(f"{owner}.n_bins", self.n_bins, integer=True, lo=1, hi=255)
        cpf = self.custom_phase_func
        if cpf is not None and not callable(cpf):
            arr = np.asarray(cpf, dtype=np.float64)  # checked in full when tabulated (optics)
            if arr.ndim != 1 or arr.size < 2:
                raise ValueError(f"{owner}.custom_phase_func must be a function of theta or a "
                                 f"1-D array of >= 2 values, got {cpf!r}")

    @property
    def _label(self) -> str:
        return f"Medium({self.name!r})"

    def _number(self, field: str, value) -> float:
        if isinstance(value, bool | str | bytes):  # float() would take "1.0"
            raise ValueError(f"{self._label}.{field} must be a number or a function, "
                             f"got {shorten(repr(value))}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{self._label}.{field} must be a number or a function, "
                             f"got {value!r}") from None
        problem = _range_problem(field, np.asarray([v]))
        if problem:
            raise ValueError(f"{self._label}.{field} {problem}, got {value!r}")
        return v

    def _arity(self, field: str) -> int:
        f = getattr(self, field)
        allowed, meaning = _ARITIES[field]
        k = n_arguments(f)
        if k not in allowed:
            raise ValueError(f"{self._label}.{field} must be a number or a function of "
                             f"{meaning}, got {f!r} taking {k} arguments")
        return k

    # ------------------------------------------------------------------ evaluation

    def depends_on_state(self, field: str) -> bool:
        """True if ``field`` is a function of FR, T or FD (the medium must be binned)."""
        value = getattr(self, field)
        if not callable(value):
            return False
        return field in THERMAL_FIELDS or self._arity(field) == 4

    @property
    def is_state_dependent(self) -> bool:
        """True if any optical property depends on FR, T or FD."""
        return any(self.depends_on_state(f) for f in OPTICAL_FIELDS)

    def value(self, field: str, wavelength: float | None = None) -> float:
        """``field`` as one number: a constant, or the function at ``wavelength`` (nm).

        Raises ValueError naming the field if the result is out of range, and
        :class:`ValueError` if a function of wavelength is given no wavelength.
        """
        v = getattr(self, field)
        if not callable(v):
            return float(v)
        if self.depends_on_state(field):
            raise ValueError(f"{self._label}.{field} depends on FR, T or FD: evaluate it with "
                             "values(), or bin it with mcmatlab_py.geometry.media_bins")
        if wavelength is None:
            raise ValueError(f"{self._label}.{field} is a function of wavelength: set "
                             "MC.wavelength (nm)")
        where = f"{field}(wavelength={wavelength})"
        out = np.asarray(v(wavelength), dtype=np.float64)
        if out.size != 1:
            raise ValueError(f"{self._label}.{where} must return one number, got shape {out.shape}")
        return float(self._checked(field, out.reshape(()), where))

    def values(self, field: str, wavelength: float | None, FR: np.ndarray, T: np.ndarray,
               FD: np.ndarray) -> np.ndarray:
        """``field`` at every voxel: (n,) float64 from (n,) FR (W/cm^2), T (deg C), FD.

        Constants and functions of wavelength are broadcast; ``VHC``/``TC`` take (T, FD).
        """
        v = getattr(self, field)
        shape = np.shape(FR)
        if not callable(v):
            return np.full(shape, float(v))
        if not self.depends_on_state(field):
            return np.full(shape, self.value(field, wavelength))
        if field in THERMAL_FIELDS:
            out, where = v(T, FD), f"{field}(T, FD)"
        else:
            if wavelength is None:
                raise ValueError(f"{self._label}.{field} is a function of wavelength: set "
                                 "MC.wavelength (nm)")
            out, where = v(wavelength, FR, T, FD), f"{field}(wavelength={wavelength}, FR, T, FD)"
        out = np.asarray(out, dtype=np.float64)
        try:
            out = np.broadcast_to(out, shape)
        except ValueError:
            raise ValueError(f"{self._label}.{where} must return a number or an array of shape "
                             f"{shape} (one per voxel), got shape {out.shape}") from None
        return np.array(self._checked(field, out, where), dtype=np.float64)

    def _checked(self, field: str, out, where: str):
        arr = np.asarray(out, dtype=np.float64)
        problem = _range_problem(field, arr)
        if problem:
            raise ValueError(f"{self._label}.{where} returned {_first_bad(field, arr)!r}: "
                             f"{field} {problem}")
        return out
