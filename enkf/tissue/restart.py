"""Restarts of the filter from the smoother (``setup.restarts``): where
(:func:`restart_points`) and with which ensemble (:func:`restart_ensemble`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from fem.threads import blas_threads

from ..problem import FilterResult
from ..random import standard_normal
from .pieces import FilterPieces
from .setup import TissueFilterSetup
from .smooth import heated_time, smooth_constant, smooth_drifting

__all__ = ["gaussian_ensemble", "restart_ensemble", "restart_points", "restarted"]


def restart_points(setup: TissueFilterSetup, times, data=None) -> list[int]:
    """The reading counts ``k`` (1..M) after which the filter restarts from the smoother
    (:attr:`SmootherRestarts.times`, :meth:`~TissueFilterSetup.restart_after`);
    with ``data`` (M, p), not before the first finite reading (the smoother needs one),
    and for drifting optics not before the laser has heated."""
    if not setup.restarts.times:
        return []
    t = np.asarray(times, float)
    finite = np.ones(t.size, bool) if data is None else \
        np.isfinite(np.asarray(data, float)).reshape(t.size, -1).any(axis=1)
    seen = np.cumsum(finite) > 0  # a finite reading at or before reading k
    if setup.restarts.drifts:  # drifting: and a heated step (the knots' clock)
        seen &= heated_time(setup.power, np.r_[0.0, t])[1:] > 0
    return [k + 1 for k in range(t.size) if seen[k]
            and setup.restart_after(float(t[k - 1]) if k else 0.0, float(t[k]))]


def restart_ensemble(setup: TissueFilterSetup, pieces: FilterPieces, times, data,
                     on_step: Callable | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """The ensemble a restart gives after the readings ``data`` at ``times`` (all of them
    so far): the parameters of the ES-MDA smoother over them
    (:func:`enkf.tissue.smooth.smooth_constant`, or with ``smoother_restart_knots >= 2``
    :func:`~enkf.tissue.smooth.smooth_drifting`'s at the last reading; with several counts
    of knots, an equal mixture of those smoothers, a block of members from each;
    ``setup.restarts.iterations`` updates from the prior; with
    ``setup.restarts.gaussian`` a log-normal ensemble of their moments,
    :func:`gaussian_ensemble`) and each member's temperatures re-run from ``T_initial``
    with its own optics (drifting: along its own path through its knots).

    The re-run carries the filter's model error (:meth:`FilterPieces.model_noise`: a
    draw of the structured error, or the white floor), so that the restarted members
    hold the spread of the temperatures that the filter's forecasts would have: without
    it, against data from another model their bands beneath the surface were too narrow.
    (Keeping instead each filter member's residual, its temperatures less a run of its
    own parameters, carried the analyses' compensation of the old parameters' errors:
    the twins' estimates went to 2-3 times the bound.)

    ``on_step(k, t, X, theta)``, if given, sees the re-run: step 0 at the start, then
    each step ``k`` at ``times[k - 1]`` with the members' optics of that step.

    Returns ``(X (N, n_nodes) deg C, theta (N, n_par), wall_s)``."""
    with blas_threads(1):  # small products, as the filter's steps (identify, online)
        return _restart_ensemble(setup, pieces, times, data, on_step)


def _restart_ensemble(setup, pieces, times, data, on_step):
    tic = time.perf_counter()
    kw = dict(n_iter=setup.restarts.iterations,
              discrepancy=setup.restarts.discrepancy,
              discrepancy_time=setup.restarts.discrepancy_time)
    edges = np.r_[0.0, np.asarray(times, float)]
    rng = np.random.default_rng([setup.seed, len(times), 7])
    if setup.restarts.drifts:  # drifting: each member's path, then its end
        parts = [smooth_drifting(setup, times, data, knots=k, drifting=setup.parameters.walking,
                                 **kw) for k in setup.restarts.knot_forms]
    else:
        parts = [smooth_constant(setup, times, data, **kw)]
    if setup.restarts.gaussian:
        parts = [_redrawn(sm, rng) for sm in parts]
    heated = heated_time(setup.power, edges)
    mid = 0.5 * (heated[:-1] + heated[1:])
    # each step's optics, (M, N, n_par); several forms of the drift: a block of members each
    blocks = np.array_split(np.arange(parts[0].theta.shape[0]), len(parts))
    path = np.concatenate([sm.at(mid)[:, b] for sm, b in zip(parts, blocks, strict=True)],
                          axis=1)
    theta = np.ascontiguousarray(np.concatenate(
        [sm.theta[b] for sm, b in zip(parts, blocks, strict=True)]))
    noise = pieces.model_noise()
    X = np.full((theta.shape[0], pieces.model.mesh.p.shape[1]), float(setup.T_initial))
    if on_step is not None:
        on_step(0, float(edges[0]), X, np.ascontiguousarray(path[0]))
    for k in range(edges.size - 1):
        th = np.ascontiguousarray(path[k])
        X1 = pieces.model(X, th, float(edges[k]), float(edges[k + 1]))
        if callable(noise):
            X1 = X1 + noise(rng, X, X1, th, float(edges[k]), float(edges[k + 1]))
        elif noise > 0:
            X1 = X1 + np.sqrt(noise) * standard_normal(rng, X1.shape)
        X = X1
        if on_step is not None:
            on_step(k + 1, float(edges[k + 1]), X, th)
    return X, theta, time.perf_counter() - tic


def _redrawn(sm, rng: np.random.Generator):
    """The smoother's estimates ``sm`` with its members replaced by a log-normal draw of
    their moments (:func:`gaussian_ensemble`): of ``theta``, or with knots of their free
    values (every knot of a drifting parameter, the first of a constant one; a parametric
    form's unknowns, ``sm.params``), ``theta`` then their last knot."""
    if sm.knots is None:
        return replace(sm, theta=gaussian_ensemble(sm.theta, rng))
    if sm.params is not None:  # a parametric form: its unknowns redrawn, then its path
        U = np.log(gaussian_ensemble(np.exp(sm.params), rng))
        V = sm.from_params(U)
        return replace(sm, theta=np.ascontiguousarray(V[:, -1]), knots=V, params=U)
    V = sm.knots.copy()  # (N, K, n_par)
    drift = np.any(V != V[:, :1], axis=(0, 1))
    cols = [(k, i) for i in range(V.shape[2]) for k in (range(V.shape[1]) if drift[i] else (0,))]
    W = gaussian_ensemble(np.stack([V[:, k, i] for k, i in cols], axis=1), rng)
    for j, (k, i) in enumerate(cols):
        if drift[i]:
            V[:, k, i] = W[:, j]
        else:  # one value over every knot
            V[:, :, i] = W[:, j, None]
    return replace(sm, theta=np.ascontiguousarray(V[:, -1]), knots=V)


def gaussian_ensemble(theta: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, n) positive members whose logs have exactly the mean and covariance of
    ``log theta``'s and are otherwise a normal draw: the members' skew and outliers, which
    the deterministic (ETKF) updates carry on unchanged, are dropped."""
    U = np.log(theta)
    N, d = U.shape
    if N <= d:
        raise ValueError(f"gaussian_ensemble needs more members than parameters, got {N} "
                         f"members for {d}")
    Z = rng.standard_normal((N, d))
    Z -= Z.mean(axis=0)
    Z = Z @ np.linalg.inv(np.linalg.cholesky(np.cov(Z.T).reshape(d, d))).T  # cov exactly I
    L = np.linalg.cholesky(np.cov(U.T).reshape(d, d))
    return np.exp(U.mean(axis=0) + Z @ L.T)


def restarted(last: FilterResult, X: np.ndarray, theta: np.ndarray) -> FilterResult:
    """A one-row result at ``last``'s final time holding the restarted ensemble."""
    nt = last.tracked_mean.shape[1]
    empty = np.zeros(0)
    return FilterResult(last.times[-1:].copy(), theta.mean(axis=0)[None],
                        theta.std(axis=0, ddof=1)[None], np.full((1, nt), np.nan),
                        np.full((1, nt), np.nan), np.zeros(0, bool), empty, empty, X, theta,
                        empty, empty, no_rows(last.innovation_normalized))


def no_rows(a: np.ndarray | None) -> np.ndarray | None:
    """``a``'s shape with no rows (a restart's row adds no step)."""
    return None if a is None else np.zeros((0, *a.shape[1:]))
