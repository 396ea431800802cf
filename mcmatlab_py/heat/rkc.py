r"""Heat steps chosen by accuracy, explicit: Runge-Kutta-Chebyshev (RKC) with error control.

For the lumped (diagonal) heat capacity :math:`m`, the semi-discrete heat equation is
:math:`\dot T = F(T) = m^{-1}(g + f - A T)`, :math:`A = K + R` (conduction and convection),
:math:`f` the laser's heat over the step. The second-order RKC method of Sommeijer,
Shampine & Verwer (1998, J. Comput. Appl. Math. 88, 315-326; their ``rkc.f``) takes one
step of length :math:`h` in :math:`s` stages,

.. math::

    Y_0 = T_n, \quad Y_1 = Y_0 + \tilde\mu_1 h F_0, \\
    Y_j = (1 - \mu_j - \nu_j) Y_0 + \mu_j Y_{j-1} + \nu_j Y_{j-2}
          + \tilde\mu_j h F(Y_{j-1}) + \tilde\gamma_j h F_0 \quad (j = 2..s),
    \quad T_{n+1} = Y_s,

with the coefficients of the shifted Chebyshev polynomials (damping :math:`\epsilon =
2/13`). Its stability interval along the negative real axis grows as :math:`s^2`,
:math:`\beta(s) \approx \tfrac23 (s^2 - 1)(1 - \tfrac{2}{15}\epsilon) \to 0.653\, s^2`:
a step of length :math:`h` needs
:math:`s = 1 + \lfloor\sqrt{1 + 1.54\, h \rho}\rfloor` stages, :math:`\rho` the spectral
radius of :math:`m^{-1} A` (here its Gershgorin bound, :func:`spectral_radius`). Each stage
is one product with the sparse :math:`A` (a numba CSR kernel that forms the stage in the same
pass), so a step costs :math:`s` products, and its cost grows as :math:`\sqrt h` where an
implicit step's is one (iterative) solve whatever its length. RKC therefore pays where the
accuracy asks for steps not much longer than the explicit stability bound :math:`2/\rho`
(short pulses: MCmatlab's Example 4), the implicit TR-BDF2 of :mod:`.steps` where the steps
can be much longer (:func:`choose_integrator`).

The local error is RKC's own estimate (``rkc.f``),

.. math:: e = \tfrac{1}{15}\big(12 (T_n - T_{n+1}) + 6 h (F_n + F_{n+1})\big),

whose :math:`F_{n+1}` is the next step's :math:`F_0` (one product per step in all). The step
is accepted when :math:`\max_i |e_i| \le \mathrm{rtol}\,\Delta T` as in :mod:`.steps`
(:math:`\Delta T` the largest temperature spread of the run so far; no error at held
nodes), and the next length is :math:`0.8\,h\,(\mathrm{tol}/|e|)^{1/3}`, between 0.1 and 10
times :math:`h`, no growth after a rejection; the last steps before a mark (phase edge,
sensor time) are cut to land on it.

RKC is not positivity-preserving: its stability polynomial is bounded by one on
:math:`[-\beta(s), 0]` but oscillates in sign there, so the lumped mass's discrete maximum
principle (which backward Euler keeps) does not hold step by step; the error control keeps
the over- and undershoots within the tolerance.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache

import numba
import numpy as np
import scipy.sparse as sp

from fem.banded import banded_at, banded_operator

__all__ = ["STABILITY_PER_STAGE2", "RKCSteps", "choose_integrator", "rkc_coefficients",
           "spectral_radius", "stages_for"]

_EPS = 2.0 / 13.0  #: RKC's damping (rkc.f): the stability region keeps a margin around -1
STABILITY_PER_STAGE2 = 0.653  #: beta(s) / s^2, the stability interval's length per stage^2
_MAX_STAGES = 250  #: a step needing more is shortened (rounding stays small below, rkc.f)


def stages_for(h: float, rho: float) -> int:
    """Stages (>= 2) for a step of ``h`` s with spectral radius ``rho`` (1/s), as ``rkc.f``."""
    return max(2, 1 + int(math.sqrt(1.0 + 1.54 * h * rho)))


@lru_cache(maxsize=512)
def rkc_coefficients(s: int) -> tuple[np.ndarray, ...]:
    """``(mu, nu, mu_tilde, gamma_tilde)``, each (s + 1,), of an ``s``-stage RKC step.

    Index ``j`` is stage ``j`` (``mu_tilde[1]`` the first stage's; ``[0]`` unused), from the
    three-term recurrences of the Chebyshev polynomials :math:`T_j(w_0)` and their first two
    derivatives (Sommeijer, Shampine & Verwer 1998, eq. 2.5-2.8).
    """
    if s < 2:
        raise ValueError(f"RKC needs at least 2 stages, got {s!r}")
    w0 = 1.0 + _EPS / s**2
    t1 = w0 * w0 - 1.0
    t2 = math.sqrt(t1)
    arg = s * math.log(w0 + t2)
    w1 = math.sinh(arg) * t1 / (math.cosh(arg) * s * t2 - w0 * math.sinh(arg))
    mu, nu, mut, gt = (np.zeros(s + 1) for _ in range(4))
    b_jm1 = b_jm2 = 1.0 / (4.0 * w0 * w0)  # b_0 = b_1 = b_2
    mut[1] = w1 * b_jm1
    z_jm1, z_jm2, dz_jm1, dz_jm2, d2_jm1, d2_jm2 = w0, 1.0, 1.0, 0.0, 0.0, 0.0
    for j in range(2, s + 1):
        z = 2.0 * w0 * z_jm1 - z_jm2
        dz = 2.0 * w0 * dz_jm1 - dz_jm2 + 2.0 * z_jm1
        d2 = 2.0 * w0 * d2_jm1 - d2_jm2 + 4.0 * dz_jm1
        b = d2 / (dz * dz)
        a_jm1 = 1.0 - z_jm1 * b_jm1
        mu[j] = 2.0 * w0 * b / b_jm1
        nu[j] = -b / b_jm2
        mut[j] = mu[j] * w1 / w0
        gt[j] = -a_jm1 * mut[j]
        z_jm2, z_jm1, dz_jm2, dz_jm1, d2_jm2, d2_jm1 = z_jm1, z, dz_jm1, dz, d2_jm1, d2
        b_jm2, b_jm1 = b_jm1, b
    return mu, nu, mut, gt


def spectral_radius(A, mass: np.ndarray, free: np.ndarray | None = None) -> float:
    """1/s, Gershgorin's bound on the spectral radius of :math:`m^{-1} A` over the free rows.

    ``A`` (npoints, npoints) W/K, ``mass`` (npoints,) J/K. An upper bound (the eigenvalues of
    :math:`m^{-1}A` are real, :math:`A` symmetric and :math:`m > 0`), within a few % of the
    7-point Laplacian's stiffest mode, so that RKC's stage count is safe without power
    iterations.
    """
    A = sp.csr_array(A)
    rows = np.empty(A.shape[0])
    _abs_row_sums(A.indptr, np.asarray(A.data, np.float64), rows)
    rows /= mass
    return float(rows.max() if free is None else rows[free].max(initial=0.0))


@numba.njit(cache=True)
def _abs_row_sums(indptr, data, out):  # pragma: no cover - numba
    """out[i] = sum |A[i, :]| of a CSR matrix (no |A| copy)."""
    for i in range(out.size):
        acc = 0.0
        for q in range(indptr[i], indptr[i + 1]):
            acc += abs(data[q])
        out[i] = acc


@numba.njit(cache=True)
def _tendency(indptr, indices, data, Y, load, w, out):  # pragma: no cover - numba
    """out = w (load - A Y): K/s, w = 1/m (0 at held nodes)."""
    for i in range(Y.size):
        acc = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            acc += data[k] * Y[indices[k]]
        out[i] = w[i] * (load[i] - acc)


@numba.njit(cache=True)
def _stage(indptr, indices, data, Yp, Y0, Ypp, F0, load, w, a0, mu, nu, mut_h, gt_h,
           out):  # pragma: no cover - numba
    """One RKC stage in one pass: out = a0 Y0 + mu Yp + nu Ypp + mut_h F(Yp) + gt_h F0."""
    for i in range(Yp.size):
        acc = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            acc += data[k] * Yp[indices[k]]
        out[i] = (a0 * Y0[i] + mu * Yp[i] + nu * Ypp[i] + mut_h * w[i] * (load[i] - acc)
                  + gt_h * F0[i])


@numba.njit(cache=True)
def _tendency_banded(diag, off, strides, Y, load, w, out):  # pragma: no cover - numba
    """:func:`_tendency` with A banded."""
    n = Y.size
    for i in range(n):
        out[i] = w[i] * (load[i] - banded_at(i, n, diag, off, strides, Y))


@numba.njit(cache=True)
def _stage_banded(diag, off, strides, Yp, Y0, Ypp, F0, load, w, a0, mu, nu, mut_h, gt_h,
                  out):  # pragma: no cover - numba
    """:func:`_stage` with A banded."""
    n = Yp.size
    for i in range(n):
        acc = banded_at(i, n, diag, off, strides, Yp)
        out[i] = (a0 * Y0[i] + mu * Yp[i] + nu * Ypp[i] + mut_h * w[i] * (load[i] - acc)
                  + gt_h * F0[i])


@numba.njit(cache=True)
def _error_and_range(T, T_new, F0, F1, h):  # pragma: no cover - numba
    """(max |e|, min T_new, max T_new), e RKC's local error estimate (deg C)."""
    err, lo, hi = 0.0, np.inf, -np.inf
    for i in range(T.size):
        e = abs(12.0 * (T[i] - T_new[i]) + 6.0 * h * (F0[i] + F1[i])) / 15.0
        err = max(err, e)
        lo = min(lo, T_new[i])
        hi = max(hi, T_new[i])
    return err, lo, hi


class RKCSteps:
    """Advance temperatures through an interval in error-controlled RKC steps.

    The same contract as :class:`.steps.ErrorControlledSteps` (``advance``, the counters),
    for a diagonal heat capacity.

    Parameters
    ----------
    A : sparse (npoints, npoints)
        W/K, :math:`K + R`.
    mass : array (npoints,)
        J/K, the lumped heat capacity (> 0).
    g : array (npoints,)
        W, the convective boundary's constant load.
    fixed : int array
        Nodes held at their temperature (their rate is zero).
    fixed_values : array (len(fixed),), optional
        deg C, the held nodes' temperatures (NaN or None: the ones they have).
    load : callable ``load(t0, t1) -> array or None``
        W per node, the laser's heat over ``[t0, t1]`` (s).
    rtol : float
        Local error per step, relative to the run's largest temperature spread (> 0).
    h0 : float
        s, the first step's length.
    spread : float
        deg C, the temperature spread before the first step.
    on_step : callable ``on_step(t0, t1, T_old, T_new)``, optional
        Called after every accepted step.
    h_min : float, optional
        s, the shortest step: one this short is accepted whatever its error (as the
        implicit controller's base step; a zero spread gives a zero tolerance). Default
        ``h0 / 64``.

    Attributes
    ----------
    rho : float
        1/s, the spectral radius bound of :math:`m^{-1} A`.
    n_accepted, n_rejected, n_products : int
        Steps accepted and retaken; products with ``A`` (the cost).
    lengths : set of float
        s, the distinct lengths of the accepted steps (they vary continuously).
    """

    def __init__(self, A, mass: np.ndarray, g: np.ndarray, fixed: np.ndarray, load: Callable,
                 rtol: float, h0: float, spread: float = 0.0, on_step: Callable | None = None,
                 h_min: float | None = None, fixed_values: np.ndarray | None = None,
                 rho: float | None = None):
        if not (math.isfinite(rtol) and rtol > 0):
            raise ValueError(f"HS.rtol must be a finite number > 0, got {rtol!r}")
        if not (math.isfinite(h0) and h0 > 0):
            raise ValueError(f"the first step must be > 0 s, got {h0!r}")
        mass = np.asarray(mass, float)
        if mass.shape != (A.shape[0],) or not np.all(mass > 0):
            raise ValueError("the lumped heat capacity must be (npoints,) and > 0")
        self.fixed = np.asarray(fixed, dtype=np.int64)
        self.fixed_values = (np.full(self.fixed.size, np.nan) if fixed_values is None
                             else np.asarray(fixed_values, float))
        self.set_operator(A, mass, g, rho)
        self.load = load
        self.rtol, self.h = float(rtol), float(h0)
        self.h_min = self.h / 64 if h_min is None else float(h_min)
        if not (math.isfinite(self.h_min) and self.h_min > 0):
            raise ValueError(f"the shortest step must be > 0 s, got {h_min!r}")
        self.spread = float(spread)
        self.on_step = on_step
        self.n_accepted = self.n_rejected = self.n_products = 0
        self.lengths: set = set()
        self._F = None  # (F at the current T, the load it was formed with, that T)

    def set_operator(self, A, mass: np.ndarray, g: np.ndarray, rho: float | None = None) -> None:
        """New media (re-binned at an update): ``A`` W/K, ``mass`` J/K, ``g`` W; the held
        nodes stay. ``rho``: :func:`spectral_radius` of these, if the caller has it."""
        A = sp.csr_array(A)
        A.sort_indices()
        # the axis-neighbour pattern of a structured mesh: products from its diagonals (and
        # no copy of the CSR arrays kept)
        self._banded = banded_operator(A)
        self._csr = None
        if self._banded is None:
            # 32-bit column indices where they fit: the stages stream the matrix from
            # memory (12 rather than 16 bytes per entry)
            index = np.int32 if A.shape[0] < 2**31 else np.int64
            self._csr = (A.indptr.astype(np.int64), A.indices.astype(index),
                         A.data.astype(np.float64))
        self.w = 1.0 / np.asarray(mass, float)
        self.w[self.fixed] = 0.0
        free = np.setdiff1d(np.arange(A.shape[0]), self.fixed, assume_unique=True)
        self.rho = spectral_radius(A, mass, free) if rho is None else float(rho)
        self.g = np.asarray(g, float)
        self._F = None

    def _rate(self, T, load, out=None):
        out = np.empty_like(T) if out is None else out
        if self._banded is not None:
            _tendency_banded(*self._banded, T, load, self.w, out)
        else:
            _tendency(*self._csr, T, load, self.w, out)
        self.n_products += 1
        return out

    def step(self, T: np.ndarray, F0: np.ndarray, load: np.ndarray,
             h: float) -> tuple[np.ndarray, np.ndarray]:
        """One RKC step of ``h`` s from ``T`` (rate ``F0``, K/s) under ``load`` (W):
        (new T, its rate)."""
        s = stages_for(h, self.rho)
        mu, nu, mut, gt = rkc_coefficients(s)
        bufs = [np.empty_like(T), np.empty_like(T), np.empty_like(T)]
        Ypp = T
        Yp = np.add(T, (mut[1] * h) * F0, out=bufs[0])
        for j in range(2, s + 1):
            out = bufs[(j - 1) % 3]  # neither Yp nor Ypp
            stage, op = ((_stage_banded, self._banded) if self._banded is not None
                         else (_stage, self._csr))
            stage(*op, Yp, T, Ypp, F0, load, self.w, 1.0 - mu[j] - nu[j], mu[j], nu[j],
                  mut[j] * h, gt[j] * h, out)
            Ypp, Yp = Yp, out
        self.n_products += s - 1
        if self.fixed.size:  # exactly held: the stage weights sum to one only to rounding
            Yp[self.fixed] = T[self.fixed]
        return Yp, self._rate(Yp, load)

    def advance(self, T: np.ndarray, t0: float, t1: float) -> np.ndarray:
        """Temperatures at ``t1`` from those at ``t0``, in as many steps as accuracy asks."""
        t, span = t0, t1 - t0
        T = np.asarray(T, float)
        held = np.isfinite(self.fixed_values)
        if held.any() and not np.array_equal(T[self.fixed[held]], self.fixed_values[held]):
            T = T.copy()
            T[self.fixed[held]] = self.fixed_values[held]
        h_stable = STABILITY_PER_STAGE2 * (_MAX_STAGES - 1) ** 2 / max(self.rho, 1e-300)
        rejected = False  # the last try was rejected: no growth after the next one
        while t1 - t > 1e-12 * span:
            nominal = h = max(min(self.h, h_stable), self.h_min)
            rest = t1 - t
            last = h >= rest * (1 - 1e-9)
            if last:
                h = rest
            elif h > 0.5 * rest:  # two even steps rather than a long and a sliver
                h = 0.5 * rest
            f = self.load(t, t + h)
            load = self.g if f is None else self.g + f
            if self._F is not None and self._F[2] is T:
                F0 = self._F[0] + self.w * (load - self._F[1])  # the last rate, new load
            else:
                F0 = self._rate(T, load)
            T_new, F1 = self.step(T, F0, load, h)
            err, lo, hi = _error_and_range(T, T_new, F0, F1, h)
            spread = max(self.spread, hi - lo)
            tol = self.rtol * spread
            ratio = err / tol if tol > 0 else (0.0 if err == 0 else math.inf)
            if ratio > 1.0 and h > self.h_min * (1 + 1e-9):
                self.n_rejected += 1
                self.h = max(h * max(0.1, 0.8 * ratio ** (-1.0 / 3.0)), self.h_min)
                self._F = (F0, load, T)
                rejected = True
                continue
            if self.on_step is not None:
                self.on_step(t, t + h, T, T_new)
            self.spread = spread
            self.n_accepted += 1
            self.lengths.add(round(h, 15))
            t = t1 if last else t + h
            T = T_new
            self._F = (F1, load, T)
            grow = max(0.1, min(10.0, 0.8 * ratio ** (-1.0 / 3.0))) if ratio > 0 else 10.0
            grow = min(1.0, grow) if rejected else grow
            # a step cut to land on a mark keeps the nominal length unless it erred too much
            self.h = h * grow if h >= nominal * (1 - 1e-9) else min(self.h, h * grow)
            rejected = False
        return T


def choose_integrator(rho: float, phase_lengths, implicit_cost: float,
                      steps_per_phase: int = 8) -> str:
    r"""``"rkc"`` or ``"implicit"``: the cheaper, in products with :math:`A`, over a run.

    The model: each phase (pulse, pause, cooling) of length :math:`L` is taken in
    ``steps_per_phase`` steps of :math:`L / 8` (the accuracy step's scale: the error-
    controlled TR-BDF2 took 62 steps over Example 4's 11 phases); an RKC step costs
    :func:`stages_for` products, an implicit TR-BDF2 step ``implicit_cost`` (two solves and
    a product, in products with :math:`A`). RKC's cost grows as the square root of the step,
    the implicit one's hardly at all, so the choice follows how the phases compare with the
    explicit stability bound :math:`2/\rho`.
    """
    lengths = [float(x) for x in phase_lengths if x > 0]
    if not lengths:
        return "implicit"
    rkc = sum(steps_per_phase * stages_for(L / steps_per_phase, rho) for L in lengths)
    implicit = steps_per_phase * len(lengths) * implicit_cost
    return "rkc" if rkc < implicit else "implicit"
