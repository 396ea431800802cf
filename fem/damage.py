r"""Arrhenius thermal damage, as in MCmatlab's heat simulation (Henriques 1947).

The damage integral of a node with activation energy ``E`` (J/mol) and frequency
factor ``A`` (1/s) grows at the Arrhenius rate

.. math::

    k(T) = A \exp\!\Big(-\frac{E}{R\,(T + 273.15)}\Big),
    \qquad R = 8.3144598\ \mathrm{J\,mol^{-1}\,K^{-1}},

with ``T`` in deg C.  Over a step of length :math:`\Delta t` from :math:`T^n` to
:math:`T^{n+1}` two quadratures are offered (``rule``):

.. math::

    \text{midpoint (MCmatlab's, the default):}\quad
    \Omega \mathrel{+}= \Delta t\, k\big(\tfrac12 (T^n + T^{n+1})\big),

    \text{trapezoid:}\quad
    \Omega \mathrel{+}= \tfrac{\Delta t}{2}\,\big(k(T^n) + k(T^{n+1})\big).

Both are exact for a constant temperature and second order in the step.  The
damaged fraction is :math:`1 - e^{-\Omega}`.  Nodes with ``A = 0`` never take
damage.  Everything broadcasts over an ensemble (N, npoints).

One numba kernel (:func:`_advance`) does the arithmetic of both rules; the
functions here validate their input once and call it.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["GAS_CONSTANT", "KELVIN", "RULES", "DamageIntegral", "advance_damage", "arrhenius_increment",
           "element_to_node", "fractional_damage", "update_damage"]

GAS_CONSTANT = 8.3144598  #: J mol^-1 K^-1, as MCmatlab
KELVIN = 273.15  #: K, the absolute temperature of 0 deg C
RULES = ("midpoint", "trapezoid")  #: the quadratures of one step, see the module doc


# ------------------------------------------------------------------------------ kernel
@numba.njit(cache=True)
def _rate(T, E, A):  # pragma: no cover - compiled
    """Arrhenius rate (1/s) at ``T`` deg C; 0 where ``A = 0``."""
    if A > 0.0:
        return A * math.exp(-E / (GAS_CONSTANT * (T + KELVIN)))
    return 0.0


@numba.njit(cache=True)
def _advance(omega, T_old, T_new, E, A, dt, trapezoid):  # pragma: no cover - compiled
    """Add one step's damage to ``omega`` (rows, n), in place.

    T_old, T_new : (rows, n) deg C; E, A : (n,) J/mol and 1/s; dt : s;
    trapezoid : the trapezoid rule if True, else the midpoint rule.
    """
    rows, n = omega.shape
    for m in range(rows):
        for i in range(n):
            if trapezoid:
                omega[m, i] += 0.5 * dt * (_rate(T_old[m, i], E[i], A[i])
                                           + _rate(T_new[m, i], E[i], A[i]))
            else:
                omega[m, i] += dt * _rate(0.5 * (T_old[m, i] + T_new[m, i]), E[i], A[i])


# ------------------------------------------------------------------------------ Python layer
def _rates(E, A) -> tuple[np.ndarray, np.ndarray]:
    E = np.asarray(E, dtype=float)
    A = np.asarray(A, dtype=float)
    if np.any(~np.isfinite(E)) or np.any(E < 0):
        raise ValueError(f"E must be finite and >= 0 (J/mol), got min {float(np.min(E))!r}")
    if np.any(~np.isfinite(A)) or np.any(A < 0):
        raise ValueError(f"A must be finite and >= 0 (1/s), got min {float(np.min(A))!r}")
    return E, A


def advance_damage(omega, T_old, T_new, dt: float, E, A, rule: str = "midpoint") -> np.ndarray:
    """Add one step's damage integral increment to ``omega``, in place.

    Parameters
    ----------
    omega : float64 array, the broadcast shape of the other arguments
        Damage integral so far (dimensionless); updated in place.
    T_old, T_new : array (npoints,) or (N, npoints)
        deg C, temperatures at the start and end of the step.
    dt : float
        s, step length (> 0).
    E : float or array (npoints,)
        J/mol, activation energy (>= 0).
    A : float or array (npoints,)
        1/s, frequency factor (>= 0; 0: no damage).
    rule : {"midpoint", "trapezoid"}
        The quadrature of the step (module doc).

    Returns
    -------
    numpy.ndarray
        ``omega``.
    """
    if rule not in RULES:
        raise ValueError(f"rule must be one of {RULES}, got {rule!r}")
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be > 0, got {float(dt)!r}")
    E, A = _rates(E, A)
    T_old = np.asarray(T_old, dtype=float)
    T_new = np.asarray(T_new, dtype=float)
    shape = np.broadcast_shapes(T_old.shape, T_new.shape, E.shape, A.shape)
    if not isinstance(omega, np.ndarray) or omega.dtype != np.float64 or omega.shape != shape:
        raise ValueError(f"omega must be a float64 array of shape {shape}, got "
                         f"{type(omega).__name__} {getattr(omega, 'dtype', '')} "
                         f"{np.shape(omega)}")
    size = math.prod(shape)
    if size == 0:
        return omega
    # rows of n values sharing one E and A per column; per-member E or A: one long row
    n = shape[-1] if shape and E.ndim <= 1 and A.ndim <= 1 else size

    def rows(x):
        return np.broadcast_to(x, shape).reshape(-1, n)

    work = np.ascontiguousarray(omega).reshape(-1, n)
    _advance(work, np.ascontiguousarray(rows(T_old)), np.ascontiguousarray(rows(T_new)),
             np.ascontiguousarray(rows(E)[0]), np.ascontiguousarray(rows(A)[0]), float(dt),
             rule == "trapezoid")
    if not np.shares_memory(work, omega):
        omega[...] = work.reshape(shape)
    return omega


class DamageIntegral:
    """:func:`advance_damage` for one set of points whose ``E`` and ``A`` stay: checked once,
    so that a long run's steps pay only the kernel.

    Parameters
    ----------
    E, A : array (npoints,)
        J/mol and 1/s, as :func:`advance_damage`'s.
    rule : {"midpoint", "trapezoid"}
    """

    def __init__(self, E, A, rule: str = "midpoint"):
        if rule not in RULES:
            raise ValueError(f"rule must be one of {RULES}, got {rule!r}")
        E, A = _rates(E, A)
        if E.ndim != 1 or A.shape != E.shape:
            raise ValueError(f"E and A must be (npoints,) arrays, got {E.shape} and {A.shape}")
        self.E = np.ascontiguousarray(E)
        self.A = np.ascontiguousarray(A)
        self.trapezoid = rule == "trapezoid"

    def advance(self, omega: np.ndarray, T_old: np.ndarray, T_new: np.ndarray,
                dt: float) -> np.ndarray:
        """Add one step's damage to ``omega`` ((npoints,) float64, in place) from
        ``T_old`` to ``T_new`` ((npoints,) deg C) over ``dt`` s; returns ``omega``."""
        n = self.E.size
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be > 0, got {float(dt)!r}")
        if (not isinstance(omega, np.ndarray) or omega.dtype != np.float64
                or omega.shape != (n,) or not omega.flags.c_contiguous):
            raise ValueError(f"omega must be a contiguous float64 array of shape ({n},), got "
                             f"{type(omega).__name__} {getattr(omega, 'dtype', '')} "
                             f"{np.shape(omega)}")
        T_old = np.ascontiguousarray(T_old, dtype=np.float64)
        T_new = np.ascontiguousarray(T_new, dtype=np.float64)
        if T_old.shape != (n,) or T_new.shape != (n,):
            raise ValueError(f"T_old and T_new must be ({n},), got {T_old.shape} and "
                             f"{T_new.shape}")
        _advance(omega.reshape(1, n), T_old.reshape(1, n), T_new.reshape(1, n), self.E,
                 self.A, float(dt), self.trapezoid)
        return omega


def arrhenius_increment(T_old, T_new, dt: float, E, A, rule: str = "midpoint") -> np.ndarray:
    """Damage integral increment of one step, dimensionless (see :func:`advance_damage`).

    Parameters
    ----------
    T_old, T_new : array (npoints,) or (N, npoints)
        deg C, temperatures at the start and end of the step.
    dt : float
        s, step length (> 0).
    E : float or array (npoints,)
        J/mol, activation energy.
    A : float or array (npoints,)
        1/s, frequency factor (0: no damage).
    rule : {"midpoint", "trapezoid"}

    Returns
    -------
    numpy.ndarray
        The broadcast shape of the arguments.
    """
    shape = np.broadcast_shapes(np.shape(T_old), np.shape(T_new), np.shape(E), np.shape(A))
    return advance_damage(np.zeros(shape), T_old, T_new, dt, E, A, rule)


def update_damage(omega, T_old, T_new, dt: float, E, A, rule: str = "midpoint") -> np.ndarray:
    """``omega + arrhenius_increment(...)`` (a new array)."""
    return np.asarray(omega, dtype=float) + arrhenius_increment(T_old, T_new, dt, E, A, rule)


def fractional_damage(omega) -> np.ndarray:
    """Damaged fraction ``1 - exp(-omega)``, in [0, 1]."""
    return -np.expm1(-np.asarray(omega, dtype=float))


def element_to_node(mesh, values, how: str = "max") -> np.ndarray:
    """Per-node values from per-element values (e.g. E and A of each medium).

    Parameters
    ----------
    values : array (nelements,)
    how : {"max", "min", "mean"}
        A node shared by elements of several media takes the largest (default,
        so a node touching damageable tissue can be damaged), smallest or
        volume-unweighted mean value.

    Returns
    -------
    array (npoints,)
    """
    v = np.asarray(values, dtype=float)
    ne, n = mesh.t.shape[1], mesh.p.shape[1]
    if v.shape != (ne,):
        raise ValueError(f"values must have shape ({ne},), got {v.shape}")
    t = mesh.t
    if how == "max":
        out = np.full(n, -np.inf)
        for a in range(4):
            np.maximum.at(out, t[a], v)
    elif how == "min":
        out = np.full(n, np.inf)
        for a in range(4):
            np.minimum.at(out, t[a], v)
    elif how == "mean":
        s = np.bincount(t.ravel(), weights=np.tile(v, 4), minlength=n)
        c = np.bincount(t.ravel(), minlength=n)
        out = s / np.maximum(c, 1)
    else:
        raise ValueError(f"how must be 'max', 'min' or 'mean', got {how!r}")
    return out
