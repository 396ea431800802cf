"""Optics from a whole window of readings: the ES-MDA smoother (:mod:`enkf.smoother`).

:func:`identify` is the online filter: one linear update per reading. After the readings,
the whole window can be analysed at once, as often as wanted: the smoother starts from
the same prior ensemble as the filter and runs ES-MDA over all the readings, each
member's temperatures re-run from ``T_initial`` with its own optics for every update.

* :func:`smooth_constant`: optics constant over the window. On the layered twin
  (``docs/layered.md``) it brings the error of the dermis's mus from 1.9 times the
  Cramér-Rao bound (the filter) to about the bound.
* :func:`smooth_drifting`: optics that change while the tissue is heated, piecewise
  linear in *heated time* (the seconds with the laser on so far: held while it is off)
  through ``knots`` values per parameter. Against the independent truths of issue #18
  (``validation/reports/smoother_drifting.md``) it meets the drifting targets the filter
  misses on truth A.

What they assume: the filter's coarse model, with no model noise. The readings' errors
are the sensor's noise plus, with ``discrepancy > 0``, a model discrepancy: a relative
error of the temperature rise, correlated over ``discrepancy_time`` seconds (an
exponential correlation), the form of the coarse model's error against finer and other
models. With ``discrepancy = 0`` the bands are those of a perfect model: the noise's
share only. A camera with a model error (``ThermalImage.model_error_rel_std > 0``) adds it
to each frame's pixels as the filter does (:meth:`ThermalImage.error_covariance` at the
members' mean prediction, recomputed at each update; the frames independent): the
smoother and the filter then read the images with one error model.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np

from ..checks import float_array
from ..importance import amis, weighted_quantile
from ..modes import find_modes
from ..smoother import es_mda
from .pieces import assemble
from .setup import TissueFilterSetup

__all__ = ["SmootherEstimates", "heated_time", "smooth_constant", "smooth_drifting"]


@dataclass
class SmootherEstimates:
    """The parameter ensemble after ES-MDA.

    ``names`` (n_par,); ``theta`` (N, n_par) the parameters at the end of the window,
    physical units (cm^-1 for mua and mus, the setup's units for VHC and TC); ``n_iter``
    updates; ``wall_s`` s. Drifting optics (:func:`smooth_drifting`): ``knot_times``
    (K,) s of heated time and ``knots`` (N, K, n_par) the members' values there.
    With ``importance`` samples (:mod:`enkf.importance`): ``theta`` (and ``knots``) hold
    the weighted samples of the posterior, ``weights`` (N,) their weights (sum 1) and
    ``ess`` their effective sample size; the statistics below are weighted. With a mode
    search (``mode_search``), ``n_modes`` the modes that seeded the sampler.
    """

    names: tuple
    theta: np.ndarray
    n_iter: int
    wall_s: float
    knot_times: np.ndarray | None = None
    knots: np.ndarray | None = None
    weights: np.ndarray | None = None
    ess: float | None = None
    n_modes: int | None = None

    @property
    def mean(self) -> np.ndarray:
        """(n_par,) the ensemble mean (weighted with importance weights)."""
        if self.weights is None:
            return self.theta.mean(axis=0)
        return self.weights @ self.theta

    @property
    def std(self) -> np.ndarray:
        """(n_par,) the ensemble standard deviation (weighted with importance weights)."""
        if self.weights is None:
            return self.theta.std(axis=0, ddof=1)
        return np.sqrt(self.weights @ (self.theta - self.mean) ** 2)

    def at(self, heated) -> np.ndarray:
        """(M, N, n_par) the members' parameters at the heated times ``heated`` (M,) s
        (:func:`heated_time`); constant optics: ``theta`` at every time. With importance
        samples, weigh the members with ``weights``."""
        heated = np.atleast_1d(np.asarray(heated, float))
        if self.knots is None:
            return np.broadcast_to(self.theta, (heated.size, *self.theta.shape))
        return _knot_values(self.knots, self.knot_times, heated)

    def knot_mean(self) -> np.ndarray:
        """(K, n_par) the mean of the knots' values (weighted with importance weights)."""
        if self.weights is None:
            return self.knots.mean(axis=0)
        return np.tensordot(self.weights, self.knots, axes=1)

    def band(self, i: int, q: float = 0.02275) -> tuple[float, float]:
        """The ``q`` and ``1 - q`` quantiles of parameter ``i`` (default: +-2 sd of a
        normal; positive like the members)."""
        if self.weights is None:
            return (float(np.quantile(self.theta[:, i], q)),
                    float(np.quantile(self.theta[:, i], 1 - q)))
        lo, hi = weighted_quantile(self.theta[:, i], self.weights, [q, 1 - q])
        return float(lo), float(hi)


def heated_time(power, edges) -> np.ndarray:
    """(M + 1,) s of heated time at the step edges ``edges`` (M + 1,) s: the clock of
    optics that change only while the laser heats (a step counts as heated when ``power``
    is > 0 at its middle, as the filter's walk does)."""
    edges = np.asarray(edges, float)
    mid = 0.5 * (edges[:-1] + edges[1:])
    on = np.array([power(float(t)) > 0 for t in mid], dtype=float)
    return np.r_[0.0, np.cumsum(on * np.diff(edges))]


def _knot_values(V: np.ndarray, tk: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """(M, N, n_par): the members' parameters at the heated times ``tau`` (M,), linear in
    the values ``V`` (N, K, n_par) between the knots ``tk`` (K,)."""
    n_knots = V.shape[1]
    if n_knots == 1:
        return np.broadcast_to(V[:, 0], (tau.size, *V[:, 0].shape))
    j = np.clip(np.searchsorted(tk, tau, side="right") - 1, 0, n_knots - 2)
    w = np.clip((tau - tk[j]) / (tk[j + 1] - tk[j]), 0.0, 1.0)[:, None, None]
    return (1 - w) * V[:, j].transpose(1, 0, 2) + w * V[:, j + 1].transpose(1, 0, 2)


def _knots_of(U: np.ndarray, drift: np.ndarray, n_knots: int) -> np.ndarray:
    """(N, K, n_par) knot values from the logs ``U`` (N, n_const + K * n_drift): the
    constant parameters' first, then the drifting ones' knot by knot."""
    n_c = int((~drift).sum())
    V = np.empty((U.shape[0], n_knots, drift.size))
    V[:, :, ~drift] = np.exp(U[:, :n_c])[:, None, :]
    V[:, :, drift] = np.exp(U[:, n_c:]).reshape(U.shape[0], n_knots, -1)
    return V


#: readings beyond which the discrepancy's dense covariance is refused (8 x this^2 bytes)
MAX_DISCREPANCY_READINGS = 20_000


def check_discrepancy_size(n_readings: int, discrepancy: float, where: str = "") -> None:
    """Refuse a ``discrepancy`` > 0 over more than :data:`MAX_DISCREPANCY_READINGS`
    readings (its covariance is dense); ``where`` prefixes the message (e.g. the file)."""
    n = int(n_readings)
    if discrepancy > 0 and n > MAX_DISCREPANCY_READINGS:
        raise ValueError(f"{where}discrepancy = {discrepancy:g} with {n} readings needs a dense "
                         f"{n}^2 covariance ({8e-9 * n ** 2:.0f} GB): set discrepancy = 0 (e.g. "
                         f"for a camera's images) or use fewer readings (at most "
                         f"{MAX_DISCREPANCY_READINGS})")


def smooth_constant(setup: TissueFilterSetup, times, data, *, n_iter: int = 4,
                    seed: int | None = None, discrepancy: float = 0.0,
                    discrepancy_time: float = 2.0, importance: int = 0,
                    importance_rounds: int = 6, mode_search: int | None = None,
                    callback=None) -> SmootherEstimates:
    """Constant optics from all the readings at once (module doc).

    Parameters
    ----------
    setup : the filter's setup; ``parameter_model = "random_walk"`` (its walk is ignored:
        the parameters are constant), no sensor offsets, no coagulation
    times : (M,) s after 0, strictly increasing
    data : (M, p) deg C as for :func:`identify`; NaN readings are left out
    n_iter : ES-MDA updates (each re-runs the ensemble over the window)
    seed : the generator of the prior and the perturbations (default ``setup.seed``)
    discrepancy : relative sd of the model's error of the temperature rise (0: none)
    discrepancy_time : s, its correlation time
    importance : 0 (default): the ES-MDA ensemble is the answer. > 0: that many samples of
        adaptive importance sampling (:func:`enkf.importance.amis`), seeded by the
        ensemble, give the posterior itself (weighted samples): for parameters the data
        hardly determine, where the ensemble's bands are too narrow (``docs/enkf.md``)
    importance_rounds : the proposals the samples are split over
    mode_search : with ``importance``, that many quasi-random points of the prior box are
        screened for other modes of the posterior, the best searched by Levenberg-Marquardt
        (:mod:`enkf.modes`), and the modes found seed the sampler beside the ensemble; 0:
        none; default :data:`MODE_SEARCH` with ``importance``, else 0
    callback : ``callback(fraction, note)`` after each update and each round of the
        sampler: the share of the work done (progress)

    The update is ``setup.method``'s (:func:`enkf.smoother.es_mda`: ``"etkf"``, the
    default, without perturbed observations).
    """
    return _smooth(setup, times, data, n_iter, seed, 1, 0.0, discrepancy, discrepancy_time, (),
                   importance, importance_rounds, callback, mode_search)


def smooth_drifting(setup: TissueFilterSetup, times, data, *, knots: int = 3,
                    n_iter: int = 8, seed: int | None = None, drift_log_std: float = 1.0,
                    drifting=("mua", "mus"), discrepancy: float = 0.0,
                    discrepancy_time: float = 2.0, importance: int = 0,
                    importance_rounds: int = 6, mode_search: int | None = None,
                    callback=None) -> SmootherEstimates:
    """Optics that drift while heated, from all the readings at once (module doc).

    Each estimated parameter named in ``drifting`` (default the optics; the others are
    constant over the window, e.g. VHC and TC) is piecewise linear in heated time
    (:func:`heated_time`) through ``knots`` values spread evenly over the window's heated
    time (held while the laser is off, as the filter's default walk holds them). The
    first knot's prior is the filter's; each later knot's log is the previous one's plus a
    normal step, their sum over the window of sd ``drift_log_std``. Other arguments as
    :func:`smooth_constant`; ``n_iter`` 8 (more unknowns, a more curved map than for
    constant optics).

    ``theta`` of the result holds the parameters at the end of the window and ``knots``
    the values at ``knot_times``. Measured against independent truths:
    ``validation/reports/smoother_drifting.md``.
    """
    if not (isinstance(knots, (int, np.integer)) and knots >= 2):
        raise ValueError(f"knots must be an integer >= 2 (1: smooth_constant), got {knots!r}")
    if not (np.isfinite(drift_log_std) and drift_log_std > 0):
        raise ValueError(f"drift_log_std must be > 0 (log units), got {drift_log_std!r}")
    names = tuple(setup.parameters.names)
    unknown = [d for d in drifting if d not in names]
    if unknown or not drifting:
        raise ValueError(f"drifting must name estimated parameters {names}, got "
                         f"{tuple(drifting)!r}")
    return _smooth(setup, times, data, n_iter, seed, int(knots), float(drift_log_std),
                   discrepancy, discrepancy_time, tuple(drifting), importance,
                   importance_rounds, callback, mode_search)


def _smooth(setup, times, data, n_iter, seed, n_knots, drift_log_std, discrepancy,
            discrepancy_time, drifting, importance=0, importance_rounds=6, callback=None,
            mode_search=None) -> SmootherEstimates:
    if setup.parameters.kind != "random_walk":
        raise ValueError(f"the smoother needs parameter_model = 'random_walk' (constant or "
                         f"drifting optics), got {setup.parameters.kind!r}")
    if setup.sensors.n_offsets:
        raise ValueError("the smoother does not estimate sensor offsets: set "
                         "sensor_offset_std = 0")
    if not (np.isfinite(discrepancy) and discrepancy >= 0):
        raise ValueError(f"discrepancy must be >= 0 (relative sd), got {discrepancy!r}")
    if not (np.isfinite(discrepancy_time) and discrepancy_time > 0):
        raise ValueError(f"discrepancy_time must be > 0 s, got {discrepancy_time!r}")
    if not (isinstance(importance, (int, np.integer)) and importance >= 0):
        raise ValueError(f"importance must be an integer >= 0 (samples), got {importance!r}")
    if mode_search is None:
        mode_search = MODE_SEARCH if importance else 0
    if not (isinstance(mode_search, (int, np.integer)) and mode_search >= 0):
        raise ValueError(f"mode_search must be an integer >= 0 (points), got {mode_search!r}")
    if mode_search and not importance:
        raise ValueError(f"mode_search = {mode_search} needs importance > 0 (the modes seed "
                         "the importance sampler)")
    times = float_array(times, "times", 1)
    if times.size == 0 or times[0] <= 0 or np.any(np.diff(times) <= 0):
        raise ValueError("times must be strictly increasing and after 0 (s)")
    pieces = assemble(setup, warm_dt=float(times[0]))
    data = float_array(data, "data", 2, finite=False)
    if data.shape != (times.size, pieces.P_obs.shape[0]):
        raise ValueError(f"data must have shape {(times.size, pieces.P_obs.shape[0])} "
                         f"(readings x sensors and pixels), got {data.shape}")
    keep = np.isfinite(data).ravel()
    if not keep.any():
        raise ValueError("data has no finite reading")
    check_discrepancy_size(keep.sum(), discrepancy)
    rng = np.random.default_rng([setup.seed if seed is None else seed, 20240605])
    X0, theta0 = pieces.prior(rng, setup.n_members)
    model, P = pieces.model, pieces.P_obs
    edges = np.r_[0.0, times]
    drift = np.array([n in drifting for n in setup.parameters.names], dtype=bool)
    heated = heated_time(setup.power, edges)
    tau = 0.5 * (heated[:-1] + heated[1:])  # each step's optics: at its middle
    tk = np.linspace(0.0, heated[-1], n_knots)
    if n_knots > 1 and not tk[-1] > 0:
        raise ValueError("smooth_drifting needs readings while the laser heats (setup.power "
                         "> 0): no heated time in the window")
    U0 = [np.log(theta0[:, ~drift]), np.log(theta0[:, drift])]
    step = drift_log_std / np.sqrt(max(n_knots - 1, 1))
    for _ in range(1, n_knots):
        U0.append(U0[-1] + step * rng.standard_normal((theta0.shape[0], int(drift.sum()))))
    U0 = np.concatenate(U0, axis=1)

    def simulate(U: np.ndarray) -> np.ndarray:
        theta = _knot_values(_knots_of(U, drift, n_knots), tk, tau)
        # every member starts from the known initial field (the importance sampler's
        # batches have their own sizes)
        T = np.tile(X0[0], (U.shape[0], 1))
        out = np.empty((U.shape[0], times.size, P.shape[0]))
        for k in range(times.size):
            T = model(T, np.ascontiguousarray(theta[k]), float(edges[k]), float(edges[k + 1]))
            out[:, k] = (P @ T.T).T
        return out.reshape(U.shape[0], -1)[:, keep]

    noise = np.tile(np.asarray(pieces.noise_var, float), times.size)
    R = noise[keep]
    whiten = None
    if pieces.obs_error is not None:  # the camera's model error, as the filter reads it
        if discrepancy > 0:
            raise ValueError(f"discrepancy = {discrepancy:g} with the camera's model error "
                             f"(image.model_error_rel_std = {setup.sensors.image.model_error_rel_std:g}): "
                             "the camera's error stands for the model's; set discrepancy = 0")
        noise_var = np.asarray(pieces.noise_var, float)

        def whiten(Y: np.ndarray):
            """Each frame whitened by its error's factor at the members' mean prediction
            (the filter's forecast mean; the data's own rise would weigh the pixels that
            the noise pulled down most, a bias of 5-6% in mua and mus on the layered fine
            truth): unit noise, independent readings."""
            mean = np.full(data.shape, np.nan).ravel()
            mean[keep] = Y.mean(axis=0)
            factors = frame_factors(pieces.obs_error, noise_var, mean.reshape(data.shape))
            return lambda Z: whiten_frames(factors, Z)

        R = np.ones_like(R)
    elif discrepancy > 0:
        rise = np.abs(data - setup.T_initial)
        rise = np.where(np.isfinite(rise), rise, 0.0).ravel()[keep]
        t_obs = np.repeat(times, P.shape[0])[keep]
        corr = np.exp(-np.abs(t_obs[:, None] - t_obs[None, :]) / discrepancy_time)
        R = np.diag(R) + (discrepancy ** 2) * np.outer(rise, rise) * corr
    tic = time.perf_counter()
    y = data.ravel()[keep]
    # member runs over the window (the mode search's: about its points and, for each of
    # its starts, (d + 1) per iteration over 10 iterations)
    search = mode_search + (MODE_STARTS + 1) * (U0.shape[1] + 1) * 10 if mode_search else 0
    work = n_iter * U0.shape[0] + search + importance

    def es_done(i, _):
        if callback is not None:
            callback((i + 1) * U0.shape[0] / work, f"ES-MDA update {i + 1} of {n_iter}")

    def is_done(r, sample):
        if callback is not None:
            callback((n_iter * U0.shape[0] + search + len(sample.U)) / work,
                     f"importance round {r + 1} of {importance_rounds}, ESS {sample.ess:.0f}")

    U = es_mda(simulate, U0, y, R, rng, n_iter=n_iter, method=setup.method, callback=es_done,
               whiten=whiten)
    weights = ess = n_modes = None
    if importance and whiten is not None:  # the error at the smoother's mean prediction
        w = whiten(simulate(U))
        simulate_raw, y = simulate, w(y[None, :])[0]

        def simulate(U: np.ndarray) -> np.ndarray:
            return w(simulate_raw(U))
    if importance:
        lo, hi = (np.log(b) for b in setup.parameters.prior_bounds())
        lo, hi = np.r_[lo[~drift], lo[drift]], np.r_[hi[~drift], hi[drift]]
        residuals = _residuals(simulate, y, R, lo.size, int(drift.sum()), n_knots, step)
        log_post = _log_posterior(residuals, lo, hi)
        found = None
        if mode_search:
            found = _search_modes(residuals, U, lo, hi, int(drift.sum()), n_knots, step,
                                  mode_search, rng)
            n_modes = 0 if found is None else len(found[0])
            if callback is not None:
                callback((n_iter * U0.shape[0] + search) / work,
                         f"mode search: {n_modes} mode{'s' * (n_modes > 1)}")
        sample = amis(log_post, U, rng, n_samples=int(importance), n_rounds=importance_rounds,
                      callback=is_done, modes=found)
        live = sample.weights > 0
        U, weights, ess = sample.U[live], sample.weights[live], sample.ess
    wall = time.perf_counter() - tic
    V = _knots_of(U, drift, n_knots)
    names = tuple(setup.parameters.names)
    if n_knots == 1:
        return SmootherEstimates(names, V[:, 0].copy(), int(n_iter), wall, weights=weights,
                                 ess=ess, n_modes=n_modes)
    # the end of the window: the last knot
    return SmootherEstimates(names, np.ascontiguousarray(V[:, -1]), int(n_iter), wall,
                             knot_times=tk, knots=V, weights=weights, ess=ess,
                             n_modes=n_modes)


def frame_factors(obs_error, noise_var: np.ndarray, predicted: np.ndarray) -> list:
    """The readings' error by frame: a list over the frames of ``predicted`` (n_frames, p)
    deg C of ``(n_kept, L)``, ``L`` the lower Cholesky factor of the covariance of the
    frame's finite entries, the noise ``noise_var`` (p,) plus ``obs_error(frame)`` (the
    filter's forecast-dependent error, e.g. :attr:`FilterPieces.obs_error`: a camera's
    model error at that prediction)."""
    out = []
    for row in predicted:
        R = np.diag(noise_var) + obs_error(row)
        m = np.isfinite(row)
        out.append((int(m.sum()), np.linalg.cholesky(R[np.ix_(m, m)])))
    return out


def whiten_frames(factors, Y: np.ndarray) -> np.ndarray:
    """(M, n) readings, frame after frame as :func:`frame_factors` keeps them, each
    frame's block multiplied by its factor's inverse."""
    from scipy.linalg import solve_triangular

    out = np.empty_like(Y)
    a = 0
    for n, L in factors:
        out[:, a:a + n] = solve_triangular(L, Y[:, a:a + n].T, lower=True).T
        a += n
    return out


#: members re-run over the window at once by the importance sampler (memory: the window's
#: predictions of this many members)
IMPORTANCE_CHUNK = 250


#: the prior's points screened for modes by default (with importance sampling)
MODE_SEARCH = 256
#: the screened points' best that start a local search, beside the ensemble's mean
MODE_STARTS = 8
#: modes of less Laplace mass than this share of the largest's are not sampled
MIN_MODE_MASS = 1e-8


def _search_modes(residuals, U, lo, hi, n_drift, n_knots, step, n_points, rng):
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


def _residuals(simulate, y, R, n_box, n_drift, n_knots, step):
    """``residuals(U) -> (M, n)``: the smoother's whitened residuals of the logs ``U`` (its
    layout: :func:`_knots_of`): the readings ``y`` against the members' predictions with
    covariance ``R`` (p,) or (p, p), and each later knot's step from the previous (sd
    ``step``) for drifting parameters. Minus half their squared sum is the log posterior
    inside the box, but for the uniform prior's ``sum(U)`` (:func:`_log_posterior`)."""
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


def _log_posterior(residuals, lo, hi):
    """``log_post(U) -> (M,)``: the smoother's log posterior of the logs ``U`` up to a
    constant. The prior: uniform in each parameter between ``lo`` and ``hi`` (logs; the
    first knot's for drifting ones), so ``sum(U)`` in the logs inside the box and ``-inf``
    outside; the rest from ``residuals`` (:func:`_residuals`)."""
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
