r"""The advice's drifting optics: each member's optics carried on over the forecast.

A member of a filter whose optics drift (a random walk of ``walk`` log units a step,
the drift bank's drifting filters) keeps drifting after the reading. Over the forecast's
steps its log optics are

.. math::

    \log\theta_n(t) = \log\theta_n(t_0) + v_n\,h(t) + \sigma \odot W_n(\tau(t)),

with :math:`h(t)` the heated time since the reading (the plan's pulses), :math:`v_n` the
member's own trend (the slope of its log optics against heated time over the last
readings, :func:`member_trends`), :math:`\sigma` the filter's walk std a step and
:math:`W_n` a standard Brownian motion in walk steps :math:`\tau` (a heated step counts
1, a step with the laser off the walk's ``random_walk_when_off`` factor), drawn afresh at
each reading. The optics act only through the load while the laser heats, so they are
held piecewise constant over pieces of ``drift_step`` s of heating, at each piece's
middle (:func:`optics_paths`); :func:`~enkf.tissue.advice.forecast.heat` sums the
responses to the pieces' loads.
"""

from __future__ import annotations

import numpy as np

__all__ = ["member_trends", "optics_paths", "remember"]


def remember(history: list, heated: float, log_theta: np.ndarray, window: float) -> None:
    """Add ``(heated s, log_theta (N, n))`` to ``history`` in place, keeping the last
    ``window`` s of heating and the reading before them; a reading without heating since
    the last replaces it, and other members (a restart: another N) start it afresh."""
    if history and history[-1][1].shape != log_theta.shape:
        history.clear()
    if history and history[-1][0] == heated:
        history[-1] = (heated, log_theta)
    else:
        history.append((heated, log_theta))
    while len(history) > 2 and history[1][0] < heated - window:
        history.pop(0)


def member_trends(history: list, window: float, n: int) -> np.ndarray:
    """(N, n) 1/s of heating: each member's least-squares slope of its log optics against
    heated time over the last ``window`` s of ``history`` (:func:`remember`), or over the
    readings so far while less than the window has been heated; (n,) zeros before any
    heating.

    Early in a pulse the slopes mix the filter's learning with the drift and scatter
    widely, and the advice's interval with them: that is what the readings tell then.
    (Held at zero until half the window had been heated, the forecast of the paper's ramps
    set the target's time too late at 0.1-0.4 s on every one of 20 runs:
    ``validation/reports/advice.md``.)"""
    if len(history) < 2:
        return np.zeros(n)
    h = np.array([a for a, _ in history])
    keep = h >= h[-1] - window - 1e-9
    h = h[keep]
    if h.size < 2 or h[-1] - h[0] <= 0:
        return np.zeros(n)
    m = np.array([b for (_, b), k in zip(history, keep, strict=True) if k])  # (k, N, n)
    hc = h - h.mean()
    return np.einsum("k,knp->np", hc, m - m.mean(0)) / (hc @ hc)


def optics_paths(theta, on, h: float, walk, when_off: float, trend, drift_step: float,
                 hold_below: float, rng: np.random.Generator):
    """The members' optics over a forecast of ``len(on)`` steps of ``h`` s.

    Parameters
    ----------
    theta : (N, n) the members' optics now.
    on : (K,) the fraction of each step with the laser on (the plan).
    walk : (n,) log units a step, the filter's walk; ``when_off``: its variance factor
        with the laser off.
    trend : (N, n) or (n,) 1/s of heating (:func:`member_trends`).
    drift_step : s of the pieces; ``hold_below``: a walk below it holds that parameter.
    rng : the walk's draws.

    Returns
    -------
    ``(thetas (S, N, n), seg (K,))``: each piece's optics and the piece of each step
    (steps with the laser off: any, they carry no load), or None where nothing drifts
    (no parameter walks at ``hold_below`` or more, or the laser stays off).
    """
    walk = np.asarray(walk, float)
    moving = walk >= hold_below
    on = np.asarray(on, float)
    K = on.size
    if not moving.any() or not (on > 0).any():
        return None
    heated = (np.cumsum(on) - 0.5 * on) * h  # s heated to each step's middle
    scale = on + (1.0 - on) * when_off  # the walk's variance factor of each step
    tau = np.cumsum(scale) - 0.5 * scale  # walk steps to each step's middle
    piece = np.floor((np.arange(K) + 0.5) * h / drift_step + 1e-9).astype(int)
    used = np.unique(piece[on > 0])
    seg = np.searchsorted(used, piece).clip(0, used.size - 1)
    steps_of = [np.flatnonzero((piece == u) & (on > 0)) for u in used]
    h_mid = np.array([heated[i].mean() for i in steps_of])
    tau_mid = np.array([tau[i].mean() for i in steps_of])
    th = np.asarray(theta, float)
    N, n = th.shape
    dtau = np.diff(np.r_[0.0, tau_mid])
    walked = np.cumsum(rng.standard_normal((used.size, N, n)) * np.sqrt(dtau)[:, None, None],
                       axis=0) * walk
    shift = walked + h_mid[:, None, None] * np.asarray(trend, float)[None]
    return np.exp(np.log(th)[None] + np.where(moving, shift, 0.0)), seg
