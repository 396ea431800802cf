r"""Arrhenius thermal damage, as in MCmatlab's heat simulation.

Over a step of length :math:`\Delta t` from :math:`T^n` to :math:`T^{n+1}`

.. math::

    \Omega \mathrel{+}= \Delta t\, A \exp\!\Big(-\frac{E}{R\,(\bar T + 273.15)}\Big),
    \qquad \bar T = \tfrac12 (T^n + T^{n+1}),

with ``E`` (J/mol) and ``A`` (1/s) per node and :math:`R = 8.3144598` J/(mol K);
the damaged fraction is :math:`1 - e^{-\Omega}`.  Nodes with ``A = 0`` never
take damage.  Everything broadcasts over an ensemble (N, npoints).
"""

from __future__ import annotations

import numpy as np

__all__ = ["GAS_CONSTANT", "arrhenius_increment", "element_to_node", "fractional_damage",
           "update_damage"]

GAS_CONSTANT = 8.3144598  #: J mol^-1 K^-1, as MCmatlab


def _rates(E, A) -> tuple[np.ndarray, np.ndarray]:
    E = np.asarray(E, dtype=float)
    A = np.asarray(A, dtype=float)
    if np.any(~np.isfinite(E)) or np.any(E < 0):
        raise ValueError(f"E must be finite and >= 0 (J/mol), got min {float(np.min(E))!r}")
    if np.any(~np.isfinite(A)) or np.any(A < 0):
        raise ValueError(f"A must be finite and >= 0 (1/s), got min {float(np.min(A))!r}")
    return E, A


def arrhenius_increment(T_old, T_new, dt: float, E, A) -> np.ndarray:
    """Damage integral increment of one step, dimensionless.

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
    """
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be > 0, got {float(dt)!r}")
    E, A = _rates(E, A)
    Tmean = 0.5 * (np.asarray(T_old, dtype=float) + np.asarray(T_new, dtype=float))
    with np.errstate(over="ignore", under="ignore"):
        rate = A * np.exp(-E / (GAS_CONSTANT * (Tmean + 273.15)))
    return dt * np.where(A > 0, rate, 0.0)


def update_damage(omega, T_old, T_new, dt: float, E, A) -> np.ndarray:
    """``omega + arrhenius_increment(...)`` (a new array)."""
    return np.asarray(omega, dtype=float) + arrhenius_increment(T_old, T_new, dt, E, A)


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
