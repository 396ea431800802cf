"""The forms of a drift: optics as functions of heated time, from a few unknowns.

A restart from the smoother (:mod:`enkf.tissue.restart`) writes each drifting parameter's
path over the window's heated time ``H`` (:func:`enkf.tissue.smooth.heated_time`) in one
of these forms, its unknowns in log units:

``K`` (an integer >= 2): knots
    piecewise linear through ``K`` values spread evenly over ``H``: ``K`` unknowns per
    drifting parameter. Any path, but each later knot is known only from the readings
    around it: with 9 knots the bound on mus at the end of the paper's pulse is 14-28% of
    its value (``validation/reports/drift_identifiability.md``).
``"logistic"``
    a logistic's segment between a value before and one after the drift, its centre
    ``c`` and width ``w`` shared by the drifting parameters (they change together, as at
    the onset of coagulation)::

        p(h) = a + (b - a) s(h),   s(h) = (sig((h - c) / w) - sig(-c / w))
                                          / (sig((H - c) / w) - sig(-c / w))

    ``s`` is 0 at the start and 1 at the end of the heated time: a line (``w`` large), a
    step at ``c`` (``w`` small), a rise that saturates (``c <= 0``). Two unknowns per
    drifting parameter and two shared ones; the bound on mus at the end is 1-2% on the
    paper's ramps, a step and a saturating rise, and the form is within 13% of each (the
    report above). Its unknowns ``U``: the constant parameters' logs, then the drifting
    ones' ``log a``, their ``log b``, ``c / H`` and ``log(w / H)``.

The paths are held as knots in either case (the logistic's at :data:`LOGISTIC_KNOTS`
points), so that what reads a path (:meth:`SmootherEstimates.at`) needs no form.
"""

from __future__ import annotations

import numpy as np

__all__ = ["LOGISTIC", "LOGISTIC_KNOTS", "check_form", "fit_logistic", "free_values",
           "knot_values", "knots_of", "logistic_box", "logistic_knots"]

LOGISTIC = "logistic"
#: the knots that carry a logistic path (a step over a tenth of the heated time is drawn
#: with four of them)
LOGISTIC_KNOTS = 41
#: the logistic's prior: centre / H normal (mean, sd), log(width / H) normal (mean, sd)
LOGISTIC_CENTRE = (0.5, 0.4)
LOGISTIC_LOG_WIDTH = (np.log(0.2), 1.0)


def check_form(form, where: str, lo: int = 2):
    """``form`` as an int >= ``lo`` or :data:`LOGISTIC`; a ValueError naming ``where``
    otherwise."""
    if isinstance(form, str) and form == LOGISTIC:
        return LOGISTIC
    if isinstance(form, (int, np.integer)) and not isinstance(form, bool) and form >= lo:
        return int(form)
    raise ValueError(f"{where} must be an integer >= {lo} or {LOGISTIC!r}, got "
                     f"{form!r}")


def free_values(form, n_par: int, n_drift: int) -> int:
    """The unknowns of a restart in ``form``: ``n_par`` parameters of which ``n_drift``
    drift."""
    if form == LOGISTIC:
        return n_par + n_drift + 2
    return n_par + (int(form) - 1) * n_drift


def knot_values(V: np.ndarray, tk: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """(M, N, n_par): the members' parameters at the heated times ``tau`` (M,), linear in
    the values ``V`` (N, K, n_par) between the knots ``tk`` (K,)."""
    n_knots = V.shape[1]
    if n_knots == 1:
        return np.broadcast_to(V[:, 0], (tau.size, *V[:, 0].shape))
    j = np.clip(np.searchsorted(tk, tau, side="right") - 1, 0, n_knots - 2)
    w = np.clip((tau - tk[j]) / (tk[j + 1] - tk[j]), 0.0, 1.0)[:, None, None]
    return (1 - w) * V[:, j].transpose(1, 0, 2) + w * V[:, j + 1].transpose(1, 0, 2)


def knots_of(U: np.ndarray, drift: np.ndarray, n_knots: int) -> np.ndarray:
    """(N, K, n_par) knot values from the logs ``U`` (N, n_const + K * n_drift): the
    constant parameters' first, then the drifting ones' knot by knot."""
    n_c = int((~drift).sum())
    V = np.empty((U.shape[0], n_knots, drift.size))
    V[:, :, ~drift] = np.exp(U[:, :n_c])[:, None, :]
    V[:, :, drift] = np.exp(U[:, n_c:]).reshape(U.shape[0], n_knots, -1)
    return V


def _sig(x):
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def logistic_knots(U: np.ndarray, drift: np.ndarray, tk: np.ndarray) -> np.ndarray:
    """(N, K, n_par) a logistic path's values at the knots ``tk`` (K,) s of heated time
    (from 0 to the window's ``H = tk[-1]``) from its unknowns ``U`` (module doc)."""
    n_c, n_d = int((~drift).sum()), int(drift.sum())
    H = float(tk[-1])
    c = U[:, -2:-1] * H
    w = np.exp(U[:, -1:]) * H
    lo, hi = _sig(-c / w), _sig((H - c) / w)
    # a step outside the heated time (both ends saturated): no drift, not 0 / 0
    s = np.clip((_sig((tk[None, :] - c) / w) - lo) / np.maximum(hi - lo, 1e-12), 0.0, 1.0)
    a, b = np.exp(U[:, n_c:n_c + n_d]), np.exp(U[:, n_c + n_d:n_c + 2 * n_d])
    V = np.empty((U.shape[0], tk.size, drift.size))
    V[:, :, ~drift] = np.exp(U[:, :n_c])[:, None, :]
    V[:, :, drift] = a[:, None, :] * (1.0 - s[:, :, None]) + b[:, None, :] * s[:, :, None]
    return V


def logistic_box(lo: np.ndarray, hi: np.ndarray, drift: np.ndarray, drift_log_std: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The box of a logistic path's unknowns from the logs of the parameters' prior box
    ``lo``, ``hi`` (n_par,): the constant parameters' and the first values' boxes, the
    values after the drift the first's widened by 3 ``drift_log_std``, the centre in
    [-1, 2] (of the heated time), the width in [0.005, 5] of it."""
    reach = 3.0 * drift_log_std
    return (np.r_[lo[~drift], lo[drift], lo[drift] - reach, -1.0, np.log(0.005)],
            np.r_[hi[~drift], hi[drift], hi[drift] + reach, 2.0, np.log(5.0)])


#: the prior box's quasi-random points screened for a logistic path's starts, and the best
#: of them refined by Levenberg-Marquardt (with the prior's mean)
LOGISTIC_SCREEN = 128
LOGISTIC_STARTS = 6


def fit_logistic(data_residuals, prior_mean: np.ndarray, prior_sd: np.ndarray,
                 drift_log_std: float, lo: np.ndarray, hi: np.ndarray, n_members: int,
                 rng: np.random.Generator) -> np.ndarray:
    """(n_members, d) a logistic path's unknowns drawn from the Laplace approximation of
    their posterior at its best mode.

    ES-MDA's one Gaussian update from the prior left the logistic on the wrong side of
    the mua-mus ridge on some seeds (a 4 times larger misfit than a mode near the
    truth); the posterior's modes are found instead from :data:`LOGISTIC_SCREEN`
    quasi-random points of the box ``lo``-``hi`` (d,) (the drifting parameters' values,
    then the centre and log width), the best :data:`LOGISTIC_STARTS` and the prior's mean
    refined by Levenberg-Marquardt (:func:`enkf.modes.find_modes`); the members are drawn
    from the modes in proportion to their Laplace mass.

    ``data_residuals(U) -> (M, n)``: the readings' whitened residuals; the prior: the
    first values (and the constant parameters) normal of ``prior_mean``, ``prior_sd``
    (the constant ones and the first values' entries of U), each value after the drift a
    normal step of sd ``drift_log_std`` from its first, the centre and log width
    :data:`LOGISTIC_CENTRE`, :data:`LOGISTIC_LOG_WIDTH`.
    """
    from scipy.stats import qmc

    from ..modes import find_modes

    n_first = prior_mean.size  # the constant parameters' and the drifting ones' first
    n_drift = lo.size - n_first - 2
    mean = np.r_[prior_mean, np.zeros(n_drift), LOGISTIC_CENTRE[0], LOGISTIC_LOG_WIDTH[0]]
    sd = np.r_[prior_sd, np.full(n_drift, drift_log_std), LOGISTIC_CENTRE[1],
               LOGISTIC_LOG_WIDTH[1]]

    def prior_residuals(U):
        Z = U.copy()
        Z[:, n_first:n_first + n_drift] -= U[:, n_first - n_drift:n_first]  # the steps
        return (Z - mean) / sd

    def residuals(U):
        return np.hstack([data_residuals(U), prior_residuals(U)])

    start_mean = mean.copy()
    start_mean[n_first:n_first + n_drift] = prior_mean[-n_drift:]
    points = lo + (hi - lo) * qmc.Sobol(lo.size, seed=rng).random(LOGISTIC_SCREEN)
    z = residuals(points)
    best = points[np.argsort(np.sum(z * z, axis=1))[:LOGISTIC_STARTS]]
    modes = find_modes(residuals, np.vstack([start_mean, best]), lo, hi)
    if not len(modes.U):
        raise ValueError("the logistic path's fit found no mode with finite residuals")
    log_mass = -modes.cost + 0.5 * np.linalg.slogdet(modes.cov)[1]
    mass = np.exp(log_mass - log_mass.max())
    which = rng.choice(len(mass), size=n_members, p=mass / mass.sum())
    U = np.empty((n_members, lo.size))
    for j in range(len(mass)):
        m = which == j
        if m.any():
            L = np.linalg.cholesky(modes.cov[j])
            U[m] = modes.U[j] + rng.standard_normal((int(m.sum()), lo.size)) @ L.T
    return U
