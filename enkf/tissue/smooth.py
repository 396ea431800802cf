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
from dataclasses import dataclass

import numpy as np

from fem.threads import blas_threads

from ..checks import float_array
from ..importance import amis, weighted_quantile
from ..smoother import es_mda
from .paths import (
    LOGISTIC,
    LOGISTIC_KNOTS,
    check_form,
    fit_logistic,
    knot_values,
    knots_of,
    logistic_box,
    logistic_knots,
)
from .pieces import assemble
from .posterior import MODE_SEARCH, MODE_STARTS, log_posterior, residuals_of, search_modes
from .response import sensor_response
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
    #: a parametric form's unknowns (N, n) in log units (:mod:`enkf.tissue.paths`), and
    #: the map from them to ``knots``; None for knots
    params: np.ndarray | None = None
    from_params: object = None

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
        return knot_values(self.knots, self.knot_times, heated)

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


def smooth_drifting(setup: TissueFilterSetup, times, data, *, knots: int | str = 3,
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
    normal step, their sum over the window of sd ``drift_log_std``. ``knots =
    "logistic"``: a logistic's segment between a value before and one after the drift
    (:mod:`enkf.tissue.paths`), the value after a normal step of sd ``drift_log_std`` from
    the first; without importance sampling. Other arguments as :func:`smooth_constant`;
    ``n_iter`` 8 (more unknowns, a more curved map than for constant optics).

    ``theta`` of the result holds the parameters at the end of the window and ``knots``
    the values at ``knot_times``. Measured against independent truths:
    ``validation/reports/smoother_drifting.md``.
    """
    knots = check_form(knots, "knots")
    if not (np.isfinite(drift_log_std) and drift_log_std > 0):
        raise ValueError(f"drift_log_std must be > 0 (log units), got {drift_log_std!r}")
    names = tuple(setup.parameters.names)
    unknown = [d for d in drifting if d not in names]
    if unknown or not drifting:
        raise ValueError(f"drifting must name estimated parameters {names}, got "
                         f"{tuple(drifting)!r}")
    return _smooth(setup, times, data, n_iter, seed, knots, float(drift_log_std),
                   discrepancy, discrepancy_time, tuple(drifting), importance,
                   importance_rounds, callback, mode_search)


def _smooth(*args, **kw) -> SmootherEstimates:
    """:func:`_smooth_window` on one BLAS thread: its products are small (members by
    readings), and on 2 cores the threads' wake-ups cost more than they share (the drift
    bank's three restarts on the paper's ramps 1.6 s against 2.3 s)."""
    with blas_threads(1):
        return _smooth_window(*args, **kw)


def _smooth_window(setup, times, data, n_iter, seed, n_knots, drift_log_std, discrepancy,
                   discrepancy_time, drifting, importance=0, importance_rounds=6,
                   callback=None, mode_search=None) -> SmootherEstimates:
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
    logistic = n_knots == LOGISTIC
    if logistic and importance:
        raise ValueError(f"importance sampling is built for knots, not the {LOGISTIC!r} form: "
                         "set importance = 0")
    tk = np.linspace(0.0, heated[-1], LOGISTIC_KNOTS if logistic else n_knots)
    if tk.size > 1 and not tk[-1] > 0:
        raise ValueError("smooth_drifting needs readings while the laser heats (setup.power "
                         "> 0): no heated time in the window")
    if logistic:  # fitted by its modes (:func:`fit_logistic`), not ES-MDA
        logs = np.log(theta0)
        U0, step = np.hstack([logs[:, ~drift], logs[:, drift]]), None

        def path(U: np.ndarray) -> np.ndarray:
            return logistic_knots(U, drift, tk)
    else:
        U0 = [np.log(theta0[:, ~drift]), np.log(theta0[:, drift])]
        step = drift_log_std / np.sqrt(max(n_knots - 1, 1))
        for _ in range(1, n_knots):
            U0.append(U0[-1] + step * rng.standard_normal((theta0.shape[0], int(drift.sum()))))
        U0 = np.concatenate(U0, axis=1)

        def path(U: np.ndarray) -> np.ndarray:
            return knots_of(U, drift, n_knots)

    # the readings as a linear function of the sources where the heat model is linear
    # (:mod:`enkf.tissue.response`: the same numbers at a small share of the cost)
    response = sensor_response(model, P, times, X0[0])

    def simulate(U: np.ndarray) -> np.ndarray:
        theta = knot_values(path(U), tk, tau)
        if response is not None:
            return response.readings(theta).reshape(U.shape[0], -1)[:, keep]
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

    if logistic:
        U = _fit_logistic(setup, simulate, y, R, whiten, U0, drift, drift_log_std, rng)
    else:
        U = es_mda(simulate, U0, y, R, rng, n_iter=n_iter, method=setup.method,
                   callback=es_done, whiten=whiten)
    weights = ess = n_modes = None
    if importance and whiten is not None:  # the error at the smoother's mean prediction
        w = whiten(simulate(U))
        simulate_raw, y = simulate, w(y[None, :])[0]

        def simulate(U: np.ndarray) -> np.ndarray:
            return w(simulate_raw(U))
    if importance:
        lo, hi = (np.log(b) for b in setup.parameters.prior_bounds())
        lo, hi = np.r_[lo[~drift], lo[drift]], np.r_[hi[~drift], hi[drift]]
        residuals = residuals_of(simulate, y, R, lo.size, int(drift.sum()), n_knots, step)
        log_post = log_posterior(residuals, lo, hi)
        found = None
        if mode_search:
            found = search_modes(residuals, U, lo, hi, int(drift.sum()), n_knots, step,
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
    V = path(U)
    names = tuple(setup.parameters.names)
    if n_knots == 1:
        return SmootherEstimates(names, V[:, 0].copy(), int(n_iter), wall, weights=weights,
                                 ess=ess, n_modes=n_modes)
    # the end of the window: the last knot
    return SmootherEstimates(names, np.ascontiguousarray(V[:, -1]), int(n_iter), wall,
                             knot_times=tk, knots=V, weights=weights, ess=ess,
                             n_modes=n_modes, params=U if logistic else None,
                             from_params=path if logistic else None)


def _fit_logistic(setup, simulate, y, R, whiten, first, drift, drift_log_std, rng):
    """A logistic path's members (:func:`enkf.tissue.paths.fit_logistic`): the prior of
    the constant parameters and the first values the moments of the logs ``first``
    (N, n_par) of the filter's prior ensemble; a camera's frames whitened at the prior's
    mean prediction (a constant path)."""
    lo, hi = logistic_box(*(np.log(b) for b in setup.parameters.prior_bounds()), drift,
                          drift_log_std)
    mean = first.mean(axis=0)
    if whiten is not None:
        flat = np.r_[mean, mean[-int(drift.sum()):], 0.5, 0.0][None, :]
        w = whiten(simulate(flat))
        raw, y = simulate, w(y[None, :])[0]

        def simulate(U: np.ndarray) -> np.ndarray:
            return w(raw(U))
    data_residuals = residuals_of(simulate, y, R, first.shape[1], 0, 1, None)
    return fit_logistic(data_residuals, mean, first.std(axis=0, ddof=1), drift_log_std, lo,
                        hi, setup.n_members, rng)


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
