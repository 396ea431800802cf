"""Spectral library: tissue chromophore absorption and the scattering power law.

The tabulated spectra (``data/spectra.csv``, 300-1000 nm in 1 nm steps) are the
numbers of the library that MCmatlab ships (``spectralLIB.mat``, S. L. Jacques'
library from mcxyz), used by MCmatlab's ``calc_mua`` helper:

* oxy- and deoxy-haemoglobin: whole blood with 150 g/L haemoglobin,
  :math:`\\mu_a = \\ln(10)\\, e\\, 150 / 64500` with :math:`e` the molar extinction
  coefficients (cm^-1/M) compiled by S. Prahl (omlc.org, from W. B. Gratzer and
  N. Kollias); :func:`hb_molar_extinction` gives :math:`e` back;
* water: G. M. Hale and M. R. Querry, Appl. Opt. 12, 555 (1973),
  :math:`\\mu_a = 4\\pi k/\\lambda` at their wavelengths, linearly interpolated;
* fat: the 930 nm lipid band as in MCmatlab's library (which names no source),
  1e-4 cm^-1 outside 870-954 nm;
* melanin: the interior of a cutaneous melanosome, Jacques' power law
  :math:`\\mu_a = 6.6\\times 10^{11} \\lambda^{-3.33}` cm^-1 (:func:`melanin_power_law`),
  tabulated as :math:`679.16\\,(\\lambda/500)^{-3.33}` (its 500 nm value rounded).

Values between the 1 nm points are linear interpolations (MATLAB's ``interp1``).
Scattering follows the power law of S. L. Jacques, "Optical properties of biological
tissues: a review", Phys. Med. Biol. 58, R37 (2013), eq. 2 (:func:`reduced_scattering`).
"""

from __future__ import annotations

import csv
import functools
import math
from importlib import resources

import numpy as np

__all__ = [
    "CHROMOPHORES",
    "WAVELENGTH_RANGE",
    "absorption",
    "calc_mua",
    "calc_mus",
    "hb_molar_extinction",
    "melanin_power_law",
    "reduced_scattering",
    "spectral_table",
]

#: nm, the range of the tabulated spectra
WAVELENGTH_RANGE = (300.0, 1000.0)
#: chromophore name -> column of ``data/spectra.csv`` (absorption coefficient, cm^-1)
CHROMOPHORES = {
    "oxy_blood": "mua_HbO2_blood",
    "deoxy_blood": "mua_Hb_blood",
    "water": "mua_water",
    "fat": "mua_fat",
    "melanin": "mua_melanin",
}
HB_GRAMS_PER_LITRE = 150.0  #: g/L haemoglobin of the tabulated whole blood
HB_MOLAR_MASS = 64500.0  #: g/mol, Prahl's gram molecular weight of haemoglobin


@functools.cache
def spectral_table() -> dict[str, np.ndarray]:
    """The shipped table: ``{"wavelength_nm": (701,), column: (701,) cm^-1, ...}`` (read once)."""
    text = (resources.files("mcmatlab_py") / "data" / "spectra.csv").read_text(encoding="utf-8")
    rows = csv.reader(line for line in text.splitlines() if line and not line.startswith("#"))
    header = next(rows)
    data = np.array([[float(v) for v in row] for row in rows], dtype=np.float64)
    table = {name: data[:, i].copy() for i, name in enumerate(header)}
    for a in table.values():
        a.flags.writeable = False
    return table


def _wavelength(wavelength) -> np.ndarray:
    lam = np.asarray(wavelength, dtype=np.float64)
    lo, hi = WAVELENGTH_RANGE
    bad = ~np.isfinite(lam) | (lam < lo) | (lam > hi)
    if bad.any():
        v = float(lam[bad].flat[0]) if lam.ndim else float(lam)
        raise ValueError(f"wavelength must be in [{lo:g}, {hi:g}] nm (the tabulated range), "
                         f"got {v!r}")
    return lam


def _result(x, like) -> float | np.ndarray:
    return float(x) if np.ndim(like) == 0 else x


def absorption(chromophore: str, wavelength) -> float | np.ndarray:
    """Absorption coefficient (cm^-1) of a chromophore at ``wavelength`` (nm).

    Parameters
    ----------
    chromophore : str
        One of :data:`CHROMOPHORES`: ``"oxy_blood"`` and ``"deoxy_blood"`` (whole
        blood, 150 g/L haemoglobin), ``"water"``, ``"fat"``, ``"melanin"``.
    wavelength : float or array
        nm, within :data:`WAVELENGTH_RANGE`.
    """
    if chromophore not in CHROMOPHORES:
        raise ValueError(f"chromophore must be one of {sorted(CHROMOPHORES)}, got {chromophore!r}")
    lam = _wavelength(wavelength)
    t = spectral_table()
    return _result(np.interp(lam, t["wavelength_nm"], t[CHROMOPHORES[chromophore]]), wavelength)


def hb_molar_extinction(wavelength, *, oxygenated: bool = True) -> float | np.ndarray:
    """Molar extinction coefficient of (oxy-)haemoglobin, cm^-1/M (Prahl's compilation).

    The inverse of the blood column's :math:`\\mu_a = \\ln(10)\\, e\\, 150/64500`.
    """
    mua = absorption("oxy_blood" if oxygenated else "deoxy_blood", wavelength)
    return mua * HB_MOLAR_MASS / (math.log(10.0) * HB_GRAMS_PER_LITRE)


def melanin_power_law(wavelength) -> float | np.ndarray:
    """Absorption of a melanosome's interior, cm^-1: :math:`6.6\\times10^{11}\\lambda^{-3.33}`
    (Jacques; wavelength in nm, any positive value)."""
    lam = np.asarray(wavelength, dtype=np.float64)
    if not (np.isfinite(lam).all() and (lam > 0).all()):
        raise ValueError(f"wavelength must be > 0 nm, got {wavelength!r}")
    return _result(6.6e11 * lam ** -3.33, wavelength)


def _fraction(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}") from None
    if not 0.0 <= v <= 1.0:
        raise ValueError(f"{name} must be in [0, 1], got {value!r}")
    return v


def calc_mua(wavelength, S: float, B: float, W: float, F: float, M: float) -> float | np.ndarray:
    """Tissue absorption coefficient (cm^-1) from its chromophore fractions (MCmatlab's ``calc_mua``).

    .. math:: \\mu_a = B S \\mu_{a,oxy} + B(1-S) \\mu_{a,deoxy} + W \\mu_{a,water}
              + F \\mu_{a,fat} + M \\mu_{a,mel}

    Jacques (2013), eq. 12 without bilirubin and beta-carotene.

    Parameters
    ----------
    wavelength : float or array
        nm, within :data:`WAVELENGTH_RANGE`.
    S : float
        Oxygen saturation of the blood, 0..1.
    B : float
        Blood volume fraction, 0..1 (whole blood of 150 g/L haemoglobin).
    W, F, M : float
        Water, fat and melanosome volume fractions, 0..1.
    """
    S, B, W, F, M = (_fraction(n, v) for n, v in zip("SBWFM", (S, B, W, F, M), strict=True))
    mua = (B * S * absorption("oxy_blood", wavelength)
           + B * (1 - S) * absorption("deoxy_blood", wavelength)
           + W * absorption("water", wavelength) + F * absorption("fat", wavelength)
           + M * absorption("melanin", wavelength))
    return _result(mua, wavelength)


def reduced_scattering(wavelength, a_prime: float, f_ray: float, b_mie: float
                       ) -> float | np.ndarray:
    """Reduced scattering coefficient, cm^-1 (Jacques 2013, eq. 2).

    .. math:: \\mu_s' = a' \\left(f_{Ray} (\\lambda/500)^{-4}
              + (1 - f_{Ray}) (\\lambda/500)^{-b_{Mie}}\\right)

    Parameters
    ----------
    wavelength : float or array
        nm (> 0; the power law is not limited to the tabulated range).
    a_prime : float
        :math:`\\mu_s'` at 500 nm, cm^-1 (>= 0).
    f_ray : float
        Rayleigh fraction of the scattering at 500 nm, 0..1.
    b_mie : float
        Mie scattering power.
    """
    lam = np.asarray(wavelength, dtype=np.float64)
    if not (np.isfinite(lam).all() and (lam > 0).all()):
        raise ValueError(f"wavelength must be > 0 nm, got {wavelength!r}")
    a = float(a_prime)
    if not (math.isfinite(a) and a >= 0):
        raise ValueError(f"a_prime must be >= 0 (cm^-1), got {a_prime!r}")
    f = _fraction("f_ray", f_ray)
    b = float(b_mie)
    if not math.isfinite(b):
        raise ValueError(f"b_mie must be finite, got {b_mie!r}")
    x = lam / 500.0
    return _result(a * (f * x ** -4.0 + (1.0 - f) * x ** -b), wavelength)


def calc_mus(wavelength, a_prime: float, f_ray: float, b_mie: float, g: float
             ) -> float | np.ndarray:
    """Scattering coefficient, cm^-1 (MCmatlab's ``calc_mus``): :math:`\\mu_s'/(1 - g)`.

    See :func:`reduced_scattering` for the other parameters; ``g`` in [-1, 1).
    """
    gv = float(g)
    if not -1.0 <= gv < 1.0:
        raise ValueError(f"g must be in [-1, 1) (mus = mus'/(1 - g)), got {g!r}")
    return _result(reduced_scattering(wavelength, a_prime, f_ray, b_mie) / (1.0 - gv), wavelength)
