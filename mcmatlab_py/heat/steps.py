r"""Heat steps chosen by accuracy: TR-BDF2 with an embedded estimate of the local error.

The default heat simulation (``HS.dt = None``, ``HS.step_control = "accuracy"``) takes
steps whose length follows the temperatures, not the stiffest mode of the mesh. For
:math:`M \dot T = F(T) = g + f - A T` (:math:`A = K + R`), one step of length :math:`h` is
TR-BDF2 (Bank et al. 1985) with :math:`\gamma = 2 - \sqrt 2`: a trapezoidal stage to
:math:`t + \gamma h`,

.. math:: M \frac{T_\gamma - T_n}{\gamma h / 2} = F(T_n) + F(T_\gamma),

then the second-order backward difference through :math:`T_n, T_\gamma, T_{n+1}`,

.. math:: T_{n+1} - \frac{T_\gamma}{\gamma (2-\gamma)}
          + \frac{(1-\gamma)^2}{\gamma (2-\gamma)} T_n
          = \frac{1-\gamma}{2-\gamma} h M^{-1} F(T_{n+1}).

Both stages solve with the same matrix :math:`M/(\gamma h/2) + A`, so each is one
backward Euler solve of length :math:`\gamma h / 2` (the trapezoidal stage's explicit half
goes into its load): two solves and one product with :math:`A` per step. The method is
second order and L-stable (stiff modes decay, where Crank-Nicolson's ring). The local
error is estimated from the three tendencies (Hosea & Shampine 1996),

.. math:: e \approx 2 C h M^{-1} \Big(\frac{F_n}{\gamma} - \frac{F_\gamma}{\gamma(1-\gamma)}
          + \frac{F_{n+1}}{1-\gamma}\Big), \quad C = \frac{-3\gamma^2 + 4\gamma - 2}{12(2-\gamma)},

with the tendencies read off the stages' own equations (no further solve). A step is
accepted when :math:`\max_i |e_i| \le \mathrm{rtol}\,\Delta T`, :math:`\Delta T` the
largest spread of the temperatures (max - min over the nodes) in the run so far. The next
step is twice as long when the error was below an eighth of the tolerance (it grows as
:math:`h^3`); a rejected step is retaken at half the length. Step lengths are powers of
two times a base step, so that few distinct lengths occur (the direct solver's
factorizations are kept per length); the last step before a report time is cut to land
on it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = ["GAMMA", "ErrorControlledSteps"]

GAMMA = 2.0 - math.sqrt(2.0)  #: TR-BDF2's inner point: both stages share one matrix
_C = (-3.0 * GAMMA**2 + 4.0 * GAMMA - 2.0) / (12.0 * (2.0 - GAMMA))
_MAX_DOUBLINGS = 40  #: a step at most 2^40 base steps long (no practical bound)


class ErrorControlledSteps:
    """Advance temperatures through an interval in error-controlled TR-BDF2 steps.

    Parameters
    ----------
    solve : callable ``solve(T, dt, load) -> T``
        One backward Euler step of length ``dt`` (s): ``(M/dt + A) T' = M T/dt + g + load``
        (``load``: W per node, or None), with the fixed nodes held.
    apply_a : callable ``apply_a(T) -> A T``
        W per node: the conduction and convection out of each node at temperatures ``T``.
    operator : callable ``operator() -> (g, apply_m, mass, fixed)``
        The current operator's parts: ``g`` (npoints,) W, the convective boundary's
        constant load; ``apply_m(X) -> M X`` the heat capacity matrix's product (J/K);
        ``mass`` (npoints,) J/K, its row sums, the lumped capacity that scales the error
        estimate; ``fixed`` the nodes held at their temperature (no error there).
        Read at every step (media re-binned at an update change them).
    load : callable ``load(t0, t1) -> array or None``
        W per node, the laser's heat over the step ``[t0, t1]`` (s).
    rtol : float
        Local error per step, relative to the largest temperature spread of the run (> 0).
    dt_base : float
        s, the unit of the step lengths and the shortest step.
    start_level : int
        The first step is ``dt_base * 2**start_level`` long.
    spread : float
        deg C, the temperature spread before the first step.
    on_step : callable ``on_step(t0, t1, T_old, T_new)``, optional
        Called after every accepted step (damage, maxima, sensor readings).

    Attributes
    ----------
    n_accepted, n_rejected : int
        Steps accepted and retaken.
    lengths : set of float
        s, the distinct lengths of the accepted steps.
    """

    def __init__(self, solve: Callable, apply_a: Callable, operator: Callable, load: Callable,
                 rtol: float, dt_base: float, start_level: int = 0, spread: float = 0.0,
                 on_step: Callable | None = None):
        if not (math.isfinite(rtol) and rtol > 0):
            raise ValueError(f"HS.rtol must be a finite number > 0, got {rtol!r}")
        if not (math.isfinite(dt_base) and dt_base > 0):
            raise ValueError(f"the base step must be > 0 s, got {dt_base!r}")
        self.solve, self.apply_a, self.operator, self.load = solve, apply_a, operator, load
        self.rtol, self.dt_base = float(rtol), float(dt_base)
        self.level = int(start_level)  #: the next step is dt_base * 2**level long
        self.spread = float(spread)
        self.on_step = on_step
        self.n_accepted = 0
        self.n_rejected = 0
        self.lengths: set = set()

    def tr_bdf2(self, T: np.ndarray, t: float, h: float) -> tuple[np.ndarray, np.ndarray]:
        """One TR-BDF2 step of length ``h`` from ``T`` at ``t``: (new T, error estimate)."""
        g = GAMMA
        g_load, apply_m, m, fixed = self.operator()
        f = self.load(t, t + h)
        F_n = g_load - self.apply_a(T)  # M dT/dt at T, before the laser's share
        if f is not None:
            F_n = F_n + f
        sub = 0.5 * g * h  # both stages: backward Euler solves of this length
        # trapezoidal stage: (M/sub + A) T_g = M T/sub + g + f + F_n
        T_g = self.solve(T, sub, F_n if f is None else F_n + f)
        T_eff = (T_g - (1.0 - g) ** 2 * T) / (g * (2.0 - g))
        T_1 = self.solve(T_eff, sub, f)
        F_g = apply_m(T_g - T) / sub - F_n
        F_1 = apply_m(T_1 - T_eff) / sub
        est = 2.0 * _C * h * (F_n / g - F_g / (g * (1.0 - g)) + F_1 / (1.0 - g)) / m
        if len(fixed):
            est[fixed] = 0.0
        return T_1, est

    def advance(self, T: np.ndarray, t0: float, t1: float) -> np.ndarray:
        """Temperatures at ``t1`` from those at ``t0``, in as many steps as accuracy asks."""
        t = t0
        span = t1 - t0
        while t1 - t > 1e-12 * span:
            nominal = self.dt_base * 2.0 ** self.level
            rest = t1 - t
            last = nominal >= rest * (1 - 1e-9)
            h = rest if last else nominal
            T_new, est = self.tr_bdf2(T, t, h)
            err = float(np.max(np.abs(est)))
            spread = max(self.spread, float(T_new.max() - T_new.min()))
            tol = self.rtol * spread
            if err > tol and h > self.dt_base * (1 + 1e-9):  # retake at half the length
                self.n_rejected += 1
                self.level = max(0, min(self.level,
                                        math.ceil(math.log2(h / self.dt_base) - 1e-9)) - 1)
                continue
            if self.on_step is not None:
                self.on_step(t, t + h, T, T_new)
            self.spread = spread
            self.n_accepted += 1
            self.lengths.add(round(h, 15))
            t = t1 if last else t + h
            T = T_new
            if err <= tol / 8.0 and h >= nominal * (1 - 1e-9):
                self.level = min(self.level + 1, _MAX_DOUBLINGS)
        return T
