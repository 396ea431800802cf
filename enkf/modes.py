r"""The posterior's modes from many starts: batched Levenberg-Marquardt in a box.

An ensemble smoother (:mod:`enkf.smoother`) follows one mode of the posterior: the one
its prior ensemble's mean leads to by linear updates. Where the readings leave separated
modes or a long curved valley with several minima (one surface sensor, two layers: the
dermis's scattering traded against the epidermis's; the drifting all-parameters twin),
importance sampling seeded by that ensemble (:func:`enkf.importance.amis`) stays near the
mode it was given (on the drifting all-parameters twin, seed 16: mus 58% low with a band
6% wide, where the search finds the truth's mode).

:func:`find_modes` looks for the others. Its cost is a least-squares one,
:math:`\tfrac12 \lVert r(u) \rVert^2` with whitened residuals ``r`` (readings and any
Gaussian prior terms), minimised from each start by Levenberg-Marquardt with
forward-difference Jacobians, all starts at once (one batch of model runs per iteration:
``K (d + 1)`` for ``K`` live starts), each step projected into the box ``[lo, hi]``.
Optima closer than ``merge`` standard deviations (of the better one's Laplace
covariance) are one mode. Each mode comes with its Laplace covariance
:math:`(J^\top J + \mathrm{diag}(s^{-2}))^{-1}`, ``s`` a quarter of the box's width, so
that directions the readings do not constrain stay as wide as the box, not infinite.

The modes seed the importance sampler (``amis(..., modes=...)``), which then weighs
them by the exact posterior: a mode found but worse by many log units gets no weight.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .checks import float_array

__all__ = ["Modes", "find_modes"]


@dataclass
class Modes:
    """Local minima of a least-squares cost, best first.

    ``U`` (K, d) where they are; ``cost`` (K,) the cost ``0.5 |r|^2`` there; ``cov``
    (K, d, d) each one's Laplace covariance; ``n_evaluations`` residual evaluations used.
    Starts where the residuals are not finite give none (K may be 0).
    """

    U: np.ndarray
    cost: np.ndarray
    cov: np.ndarray
    n_evaluations: int


def find_modes(residuals: Callable[[np.ndarray], np.ndarray], starts: np.ndarray,
               lo: np.ndarray, hi: np.ndarray, *, n_iter: int = 20, fd_step: float = 1e-4,
               merge: float = 3.0, tol: float = 1e-3,
               callback: Callable[[int, int], None] | None = None) -> Modes:
    """Minimise ``0.5 |residuals(u)|^2`` from each start in the box (module doc).

    Parameters
    ----------
    residuals : callable
        ``residuals(U) -> (M, n)``: the whitened residuals of each row of ``U`` (M, d)
    starts : (K, d) the starting points (clipped into the box)
    lo, hi : (d,) the box
    n_iter : Levenberg-Marquardt iterations at most
    fd_step : the forward-difference step, as a share of each box width
    merge : optima within this many standard deviations of a better one are dropped
    tol : a start stops when its cost falls by less than this in an iteration
    callback : ``callback(i, n_live)`` after iteration ``i``
    """
    lo = float_array(lo, "lo", 1)
    hi = float_array(hi, "hi", 1)
    if lo.shape != hi.shape or not np.all(hi > lo):
        raise ValueError(f"lo and hi must have the same shape and hi > lo, got {lo} and {hi}")
    starts = float_array(starts, "starts", 2)
    if starts.shape[1] != lo.size or starts.shape[0] < 1:
        raise ValueError(f"starts must have shape (K >= 1, {lo.size}), got {starts.shape}")
    if not (isinstance(n_iter, (int, np.integer)) and n_iter >= 1):
        raise ValueError(f"n_iter must be an integer >= 1, got {n_iter!r}")
    if not (np.isfinite(fd_step) and 0 < fd_step < 0.1):
        raise ValueError(f"fd_step must be in (0, 0.1) (share of the box), got {fd_step!r}")
    K, d = starts.shape
    width = hi - lo
    h = fd_step * width
    prior_info = np.diag((4.0 / width) ** 2)  # a quarter of the box: one sd
    U = np.clip(starts, lo, hi)
    count = [0]

    def res(V):
        count[0] += V.shape[0]
        r = np.asarray(residuals(V), float)
        if r.ndim != 2 or r.shape[0] != V.shape[0]:
            raise ValueError(f"residuals must return shape ({V.shape[0]}, n), got {r.shape}")
        return r

    def jacobians(V, r):
        """(k, n, d) forward differences, stepping inwards at the upper bound."""
        sign = np.where(V + h > hi, -1.0, 1.0)  # (k, d)
        P = np.repeat(V, d, axis=0) + (np.tile(np.eye(d), (V.shape[0], 1))
                                       * np.repeat(sign * h, d, axis=0))
        rp = res(P).reshape(V.shape[0], d, -1)
        return np.transpose(rp - r[:, None, :], (0, 2, 1)) / (sign * h)[:, None, :]

    r = res(U)
    cost = 0.5 * np.sum(r * r, axis=1)
    lam = np.full(K, 1e-2)
    live = np.ones(K, dtype=bool)
    for i in range(n_iter):
        idx = np.flatnonzero(live)
        if idx.size == 0:
            break
        J = jacobians(U[idx], r[idx])
        A = np.einsum("knd,kne->kde", J, J)
        g = np.einsum("knd,kn->kd", J, r[idx])
        D = np.einsum("kdd->kd", A) + 1e-12  # Marquardt's scaling: the diagonal
        step = -np.linalg.solve(A + lam[idx, None, None] * (D[:, :, None] * np.eye(d)),
                                g[..., None])[..., 0]
        trial = np.clip(U[idx] + step, lo, hi)
        rt = res(trial)
        ct = 0.5 * np.sum(rt * rt, axis=1)
        better = ct < cost[idx]
        gain = cost[idx] - ct
        acc = idx[better]
        U[acc], r[acc], cost[acc] = trial[better], rt[better], ct[better]
        lam[acc] = np.maximum(lam[acc] / 3.0, 1e-9)
        lam[idx[~better]] *= 4.0
        live[idx[better & (gain < tol)]] = False
        live[idx[~better & (lam[idx] > 1e8)]] = False
        if callback is not None:
            callback(i, int(live.sum()))
    J = jacobians(U, r)  # the Laplace covariance at each optimum
    cov = np.linalg.inv(np.einsum("knd,kne->kde", J, J) + prior_info)
    # a start whose residuals are not finite (a model that failed there) is no mode
    ok = np.isfinite(cost) & np.all(np.isfinite(cov), axis=(1, 2))
    order = np.flatnonzero(ok)[np.argsort(cost[ok])]
    keep = []
    for k in order:
        if all(_distance(U[k], U[j], cov[j]) > merge for j in keep):
            keep.append(k)
    keep = np.array(keep, dtype=int)
    return Modes(U[keep], cost[keep], cov[keep], count[0])


def _distance(u, centre, cov) -> float:
    z = np.linalg.solve(np.linalg.cholesky(cov), u - centre)
    return float(np.sqrt(z @ z))
