"""Media: the optical and thermal properties of one tissue type (MCmatlab's ``mediaPropertiesFunc``)."""

from __future__ import annotations

import math
from dataclasses import dataclass


def check_positive(owner: str, field: str, value, *, allow_zero: bool = False) -> float:
    """Return ``value`` as float, or raise ValueError naming ``owner.field`` and the value."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{field} must be a number, got {value!r}") from None
    if math.isnan(v) or math.isinf(v):
        raise ValueError(f"{owner}.{field} must be finite, got {value!r}")
    if v < 0 or (v == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{owner}.{field} must be {bound}, got {value!r}")
    return v


@dataclass
class Medium:
    """One medium of the geometry.

    Parameters
    ----------
    name : str
        Label used in plots and error messages.
    mua : float
        Absorption coefficient, cm^-1 (>= 0).
    mus : float
        Scattering coefficient, cm^-1 (>= 0).
    g : float
        Henyey-Greenstein anisotropy, in (-1, 1).
    n : float
        Refractive index (>= 1).
    VHC : float, optional
        Volumetric heat capacity, J cm^-3 K^-1 (> 0); needed by the heat simulation.
    TC : float, optional
        Thermal conductivity, W cm^-1 K^-1 (> 0); needed by the heat simulation.
    E : float, optional
        Arrhenius activation energy, J/mol (>= 0), for thermal damage.
    A : float, optional
        Arrhenius frequency factor, 1/s (>= 0), for thermal damage.
    """

    name: str
    mua: float
    mus: float
    g: float = 0.0
    n: float = 1.0
    VHC: float | None = None
    TC: float | None = None
    E: float | None = None
    A: float | None = None

    def __post_init__(self):
        owner = f"Medium({self.name!r})"
        self.mua = check_positive(owner, "mua", self.mua, allow_zero=True)
        self.mus = check_positive(owner, "mus", self.mus, allow_zero=True)
        g = check_positive(owner, "g", abs(_num(owner, "g", self.g)), allow_zero=True)
        if not g < 1.0:
            raise ValueError(f"{owner}.g must be in (-1, 1), got {self.g!r}")
        self.g = float(self.g)
        n = _num(owner, "n", self.n)
        if not n >= 1.0:
            raise ValueError(f"{owner}.n must be >= 1, got {self.n!r}")
        self.n = n
        for field in ("VHC", "TC"):
            value = getattr(self, field)
            if value is not None:
                setattr(self, field, check_positive(owner, field, value))
        for field in ("E", "A"):
            value = getattr(self, field)
            if value is not None:
                setattr(self, field, check_positive(owner, field, value, allow_zero=True))


def _num(owner: str, field: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{field} must be a number, got {value!r}") from None
    if math.isnan(v) or math.isinf(v):
        raise ValueError(f"{owner}.{field} must be finite, got {value!r}")
    return v
