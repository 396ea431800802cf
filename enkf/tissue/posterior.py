"""The smoother's posterior over a window's unknowns, for what goes beyond ES-MDA: the
importance sampler (:mod:`enkf.importance`), its mode search (:mod:`enkf.modes`) and the
logistic path's fit (:func:`enkf.tissue.paths.fit_logistic`): whitened residuals, the log
posterior in the prior's box, and the box's quasi-random screening for modes."""

from __future__ import annotations

import warnings

import numpy as np

from ..modes import find_modes

__all__ = ["IMPORTANCE_CHUNK", "MIN_MODE_MASS", "MODE_SEARCH", "MODE_STARTS", "log_posterior",
           "residuals_of", "search_modes"]


#: members re-run over the window at once by the importance sampler (memory: the window's
#: predictions of this many members)
IMPORTANCE_CHUNK = 250


#: the prior's points screened for modes by default (with importance sampling)
MODE_SEARCH = 256
#: the screened points' best that start a local search, beside the ensemble's mean
MODE_STARTS = 8
#: modes of less Laplace mass than this share of the largest's are not sampled
MIN_MODE_MASS = 1e-8


def search_modes(residuals, U, lo, hi, n_drift, n_knots, step, n_points, rng):
    """Other modes of the posterior for the importance sampler (:mod:`enkf.modes`):
    ``n_points`` quasi-random points of the prior box screened by their cost, the best
    :data:`MODE_STARTS` and the ensemble's mean ``U`` started by Levenberg-Marquardt.
    Returns ``(centres, covariances, masses)``: each mode's Laplace mass, its cost and the
    uniform prior's ``sum(u)`` in the logs, relative to the largest; None if no start
    gave finite residuals."""
    from scipy.stats import qmc

    n_box = lo.size
    with warnings.catch_warnings():  # Sobol's balance wants a power of 2; any number will do
        warnings.simplefilter("ignore", UserWarning)
        first = lo + (hi - lo) * qmc.Sobol(n_box, seed=rng).random(int(n_points))
    # drifting parameters start constant: their later knots at the first's
    P = np.hstack([first] + [first[:, n_box - n_drift:]] * (n_knots - 1))
    z = residuals(P)
    best = P[np.argsort(np.sum(z * z, axis=1))[:MODE_STARTS]]
    span_lo = np.r_[lo, np.tile(lo[n_box - n_drift:], n_knots - 1)]
    span_hi = np.r_[hi, np.tile(hi[n_box - n_drift:], n_knots - 1)]
    if n_knots > 1:  # later knots: the box widened by 3 sd of the walk
        reach = np.r_[np.zeros(n_box), 3 * step * np.sqrt(np.repeat(np.arange(1, n_knots),
                                                                     n_drift))]
        span_lo, span_hi = span_lo - reach, span_hi + reach
    modes = find_modes(residuals, np.vstack([U.mean(axis=0), best]), span_lo, span_hi)
    if not len(modes.U):
        return None
    log_mass = (-modes.cost + modes.U[:, :n_box].sum(axis=1)
                + 0.5 * np.linalg.slogdet(modes.cov)[1])
    mass = np.exp(log_mass - log_mass.max())
    keep = mass >= MIN_MODE_MASS
    return modes.U[keep], modes.cov[keep], mass[keep]


def residuals_of(simulate, y, R, n_box, n_drift, n_knots, step):
    """``residuals(U) -> (M, n)``: the smoother's whitened residuals of the logs ``U`` (its
    layout: :func:`enkf.tissue.paths.knots_of`): the readings ``y`` against the members' predictions with
    covariance ``R`` (p,) or (p, p), and each later knot's step from the previous (sd
    ``step``) for drifting parameters. Minus half their squared sum is the log posterior
    inside the box, but for the uniform prior's ``sum(U)`` (:func:`log_posterior`)."""
    dense = np.ndim(R) == 2
    L = np.linalg.cholesky(R) if dense else None

    def residuals(U: np.ndarray) -> np.ndarray:
        out = []
        for s in range(0, U.shape[0], IMPORTANCE_CHUNK):
            r = y - simulate(U[s:s + IMPORTANCE_CHUNK])
            out.append((np.linalg.solve(L, r.T) if dense else r.T / np.sqrt(R)[:, None]).T)
        z = np.vstack(out)
        if n_knots > 1:
            walk = np.diff(U[:, n_box - n_drift:].reshape(U.shape[0], n_knots, n_drift), axis=1)
            z = np.hstack([z, walk.reshape(U.shape[0], -1) / step])
        return z

    return residuals


def log_posterior(residuals, lo, hi):
    """``log_post(U) -> (M,)``: the smoother's log posterior of the logs ``U`` up to a
    constant. The prior: uniform in each parameter between ``lo`` and ``hi`` (logs; the
    first knot's for drifting ones), so ``sum(U)`` in the logs inside the box and ``-inf``
    outside; the rest from ``residuals`` (:func:`residuals_of`)."""
    n_box = lo.size

    def log_post(U: np.ndarray) -> np.ndarray:
        first = U[:, :n_box]
        out = np.where(np.all((first >= lo) & (first <= hi), axis=1), first.sum(axis=1),
                       -np.inf)
        inside = np.flatnonzero(np.isfinite(out))
        if inside.size:
            z = residuals(U[inside])
            out[inside] += -0.5 * np.sum(z * z, axis=1)
        return out

    return log_post
