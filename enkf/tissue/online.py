"""The filter one reading at a time, for a live sensor."""

from __future__ import annotations

import copy
import time
import warnings
from dataclasses import dataclass, replace

import numpy as np

from fem.threads import blas_threads, keep_freed_memory

from ..adaptive import InflationEstimator
from ..loop import run_filter
from .drift import mix_moments
from .estimates import laser_persistence
from .pieces import assemble
from .restart import restart_ensemble, restart_points
from .setup import TissueFilterSetup
from .setup.drift_bank import bank_weights, prior_weights

__all__ = ["OnlineEstimate", "OnlineIdentifier"]


@dataclass
class OnlineEstimate:
    """The filter's state after one reading (physical units; see TissueEstimates)."""

    time: float
    param_mean: np.ndarray  #: (n_par,)
    param_std: np.ndarray  #: (n_par,)
    tracked_mean: np.ndarray  #: (n_tracked,) deg C
    tracked_std: np.ndarray  #: (n_tracked,) deg C
    analysed: bool
    latency_s: float  #: wall time of this update
    #: (n_sensors,) deg C: the point sensors' estimated offsets (``sensor_offset_std > 0``)
    sensor_offset_mean: np.ndarray | None = None
    sensor_offset_std: np.ndarray | None = None
    #: (n_obs,) the reading's innovation over its forecast sd (NaN where not analysed;
    #: :func:`enkf.adaptive.normalized_innovation`), and whether the laser delivered
    #: energy since the reading before
    innovation_normalized: np.ndarray | None = None
    laser_on: bool | None = None
    #: log-density of the reading under the forecast (NaN where not analysed)
    innovation_loglik: float | None = None
    #: with a drift bank (``setup.parameters.drift``): the probability, after this reading, that the
    #: optics drift while heated
    drift_weight: float | None = None


class OnlineIdentifier:
    """The filter one reading at a time, for a live sensor (``identify --follow``).

    Each :meth:`update` forecasts the ensemble from the previous reading's time to the
    new one and assimilates the new reading (NaN entries are skipped), so the estimate
    is ready before the next frame arrives. The random numbers of reading ``k`` come
    from ``(setup.seed, k)``: a replay of the same readings gives the same estimates
    (they differ from :func:`identify`'s, which draws from one stream).

    With ``setup.parameters.drift`` (a :class:`~enkf.tissue.drift.DriftBank`) it runs the still and
    the drifting filter side by side and reports their mixture under the evidence, with
    ``drift_weight`` in each estimate (:mod:`enkf.tissue.drift`); a filter the health
    check stops drops out of the mixture.

    Raises :class:`~enkf.problem.FilterDivergence` when the health check stops the
    filter (with a bank: both; the estimates so far stay in :attr:`history`).
    """

    def __init__(self, setup: TissueFilterSetup, *, param_bounds=None, dt_hint: float = 0.1):
        self.setup = setup
        self._bank = None
        if setup.parameters.drift is not None:
            self._bank = {name: OnlineIdentifier(s, param_bounds=param_bounds, dt_hint=dt_hint)
                          for name, s in setup.parameters.drift.components(setup).items()}
            self._weights = prior_weights(setup.parameters.drift, list(self._bank))
            self._alive = np.ones(len(self._bank), bool)
            first = self._bank["still"]
            self.time, self.history, self.restart_times = 0.0, [], []
            self.names, self.n_obs = first.names, first.n_obs
            self._pieces = first._pieces
            comps = list(self._bank.values())
            for j, comp in enumerate(comps):
                if j:  # a drifting filter restarts where the data support it
                    comp._restart_gate = lambda t, ll, j=j: self._drift_supported(t, ll, j)
            #: the drifting filters after the first: the same filter as the first until its
            #: first restart, which they follow (run once) until then
            self._followers = list(range(2, len(comps))) if len(comps) > 2 and \
                comps[1].setup.restarts.times else []
            return
        self._restart_gate = None
        self._pieces = assemble(setup, param_bounds, dt_hint)
        rng = np.random.default_rng([setup.seed, 0])
        self._X, self._theta = self._pieces.prior(rng, setup.n_members)
        self.time = 0.0
        self.history: list[OnlineEstimate] = []
        self._readings: list = []  #: (t, y) of every reading, with smoother restarts
        #: s: the readings after which the filter restarted from the smoother
        #: (``setup.restarts.times``; the estimate of that reading is the restart's)
        self.restart_times: list[float] = []
        self.names = setup.parameters.names
        self.n_obs = self._pieces.P_obs.shape[0]
        # the time-correlated model error and the inflation estimate run across readings
        self._noise = self._pieces.model_noise()
        ai = self._pieces.config.adaptive_inflation
        self._inflation = InflationEstimator(ai) if ai is not None else None

    def _restart(self, t: float) -> bool:
        """Restart from the smoother over the readings so far (``setup.restarts.times``)
        where :func:`~enkf.tissue.restart.restart_points` allows it after this reading;
        a restart the smoother refuses (e.g. too many readings for the discrepancy's dense
        covariance) is skipped with a warning, and the filter goes on."""
        times = np.array([r[0] for r in self._readings])
        data = np.array([r[1] for r in self._readings])
        if restart_points(self.setup, times, data)[-1:] != [times.size]:
            return False
        try:
            self._X, self._theta, _ = restart_ensemble(self.setup, self._pieces, times, data)
        except ValueError as err:
            warnings.warn(f"the restart after the reading at t = {t:g} s is skipped: {err}",
                          RuntimeWarning, stacklevel=3)
            return False
        self.restart_times.append(t)
        # new members: their model error's time-correlated field starts afresh, as in
        # identify's segments (the inflation estimate runs on)
        if hasattr(self._noise, "reset"):
            self._noise.reset()
        return True

    @property
    def state_ensemble(self) -> np.ndarray:
        """(N, n_nodes) deg C: the members' temperatures after the last reading (with a
        drift bank, those of the filter the data support most)."""
        if self._bank is not None:
            return self._member_filter(int(np.argmax(np.where(self._alive, self._weights,
                                                               -1.0)))).state_ensemble
        return self._X

    @property
    def param_ensemble(self) -> np.ndarray:
        """(N, n_par) the members' parameters after the last reading, ``names`` first
        (with a drift bank, those of the filter the data support most)."""
        if self._bank is not None:
            return self._member_filter(int(np.argmax(np.where(self._alive, self._weights,
                                                               -1.0)))).param_ensemble
        return self._theta

    def _member_filter(self, j: int) -> OnlineIdentifier:
        """The bank's filter whose members filter ``j`` has (a follower: the first
        drifting filter's)."""
        return list(self._bank.values())[1 if j in self._followers else j]

    def filter_ensembles(self) -> list[tuple]:
        """``[(name, weight, X (N, n_nodes) deg C, theta (N, n_par)), ...]``: each filter's
        members after the last reading and its probability (one filter: name None, weight
        1; with a drift bank its filters by name, those the health check stopped left out,
        the weights of the others summing to 1). What a forecast from the members needs
        (:meth:`enkf.tissue.advice.Advisor.online`)."""
        if self._bank is None:
            return [(None, 1.0, self._X, self._theta)]
        w = np.where(self._alive, self._weights, 0.0)
        w = w / w.sum()
        return [(name, float(w[j]), self._member_filter(j)._X, self._member_filter(j)._theta)
                for j, name in enumerate(self._bank) if self._alive[j]]

    def innovation_persistence(self, laser: str = "off") -> tuple[float, int]:
        """Lag-1 correlation of the normalized innovations of the readings so far, while
        the laser is ``"off"`` (default), ``"on"``, or over ``"all"``, and the number of
        pairs it sums (:func:`~enkf.tissue.estimates.laser_persistence`, as
        :meth:`TissueEstimates.innovation_persistence`)."""
        return laser_persistence(np.array([h.innovation_normalized for h in self.history]),
                                 np.array([h.laser_on for h in self.history]), laser)

    def update(self, t: float, y) -> OnlineEstimate:
        """Assimilate the reading ``y`` ((p,) deg C, NaN = missing) taken at ``t`` (s)."""
        t = float(t)
        if not np.isfinite(t) or t <= self.time:
            raise ValueError(f"reading time must be finite and after {self.time} s, got {t!r}")
        y = np.asarray(y, float).reshape(-1)
        if y.shape != (self.n_obs,):
            raise ValueError(f"a reading must hold {self.n_obs} values (sensors then pixels), "
                             f"got {y.size}")
        if self._bank is not None:
            return self._update_bank(t, y)
        return self._finish(t, y, *self._step(t, y))

    def _step(self, t: float, y: np.ndarray):
        """The filter's forecast to ``t`` and its analysis of ``y``: the members change,
        nothing else does (:meth:`_finish` keeps the reading, restarts, reports)."""
        X, theta = self._X, self._theta
        problem = self._pieces.problem(np.array([t]), y[None, :],
                                       prior=lambda rng, N: (X, theta), t0=self.time,
                                       model_noise=self._noise)
        seed = int(np.random.SeedSequence([self.setup.seed, len(self.history) + 1])
                   .generate_state(1)[0])
        config = replace(self._pieces.config, seed=seed)
        tic = time.perf_counter()
        keep_freed_memory()  # ensemble-sized temporaries: reuse, not fresh page faults
        last = []  # the step's report: its forecast gives the camera's error at the points
        with blas_threads(1):
            res = run_filter(problem, config, health=self._pieces.health,
                             inflation_state=self._inflation, callback=last.append)
            # the camera's error at the tracked points factors the frame's (p, p) covariance:
            # with OpenBLAS's threads on 2 busy cores a 256-pixel one took 0.2 s, not 3 ms
            T_mean, T_std = self._pieces.tracked(last[-1])
        self._X, self._theta = res.state_ensemble, res.param_ensemble
        return res, last, T_mean, T_std, tic

    def _finish(self, t: float, y: np.ndarray, res, last, T_mean, T_std, tic) -> OnlineEstimate:
        """After :meth:`_step`: keep the reading, restart from the smoother where it is
        due, and report the estimate."""
        p_mean, p_std = res.param_mean[-1], res.param_std[-1]
        if self.setup.restarts.times:  # keep the readings for the smoother's restarts
            self._readings.append((t, y.copy()))
            with blas_threads(1):  # the smoother's small factors: as the filter's
                if self.setup.restart_after(self.time, t) and (
                        self._restart_gate is None or self._restart_gate(
                            t, float(res.innovation_loglik[-1]))) and self._restart(t):
                    p_mean, p_std = self._theta.mean(axis=0), self._theta.std(axis=0, ddof=1)
                    last[-1] = replace(last[-1], state_ensemble=self._X, forecast=None)
                    T_mean, T_std = self._pieces.tracked(last[-1])
        n = self._pieces.n
        n_off = self.setup.sensors.n_offsets
        est = OnlineEstimate(t, p_mean[:n], p_std[:n], T_mean, T_std, bool(res.analysed[-1]),
                             time.perf_counter() - tic,
                             res.param_mean[-1, -n_off:] if n_off else None,
                             res.param_std[-1, -n_off:] if n_off else None,
                             res.innovation_normalized[-1].copy(),
                             bool(self.setup.mean_power(self.time, t) > 0),
                             float(res.innovation_loglik[-1]))
        self.time = t
        self.history.append(est)
        return est

    def _step_weights(self, t: float, lls, weights=None, alive=None
                      ) -> tuple[np.ndarray, float]:
        """The bank's weights (or ``weights``, of the filters ``alive``) after the
        reading at ``t`` with the filters' log-densities ``lls`` (K,), and the mixture's
        log-density (:func:`~enkf.tissue.drift.bank_weights`)."""
        weights = self._weights if weights is None else weights
        alive = self._alive if alive is None else alive
        ll = np.where(alive, np.asarray(lls, float), -np.inf)
        heated = bool(self.setup.mean_power(self.time, t) > 0)
        w, _, mix = bank_weights(ll[None], weights, self.setup.parameters.drift.switch_prob,
                                 np.array([heated]))
        return w[-1], float(mix[0])

    def _drift_supported(self, t: float, ll_drifting: float, j: int) -> bool:
        """Whether drifting filter ``j``'s restart after the reading at ``t`` goes ahead:
        its weight against still optics, with this reading, above
        ``drift.restart_weight``."""
        still = self._bank["still"]
        ll_still = still.history[-1].innovation_loglik if self._alive[0] and \
            still.history and still.history[-1].time == t else -np.inf
        pair = self._weights[[0, j]]
        w, _ = self._step_weights(t, [ll_still, ll_drifting], pair / pair.sum(),
                                  np.ones(2, bool))
        return bool(w[1] > self.setup.parameters.drift.restart_weight)

    def _update_followed(self, comp: OnlineIdentifier, t: float, y: np.ndarray):
        """The first drifting filter's update while the others follow it: at a reading
        where a restart is due, each follower takes the members, readings, model error and
        inflation it had before the restart and restarts in its own form (the same numbers
        as each run from the first reading); where none restarted they follow on. Returns
        its estimate and ``{j: estimate}`` of the followers that branched off here."""
        step = comp._step(t, y)
        if not comp.setup.restart_after(comp.time, t):
            return comp._finish(t, y, *step), {}
        before = (comp._X, comp._theta, list(comp._readings), copy.deepcopy(comp._noise),
                  copy.deepcopy(comp._inflation), list(comp.history), comp.time,
                  comp._pieces.model.clamp_counts)
        e = comp._finish(t, y, *step)
        comps, out = list(self._bank.values()), {}
        res, last, T_mean, T_std, tic = step
        for j in self._followers:
            f = comps[j]
            X, theta, readings, noise, inflation, history, t_before, clamps = before
            f._X, f._theta, f._readings = X.copy(), theta.copy(), list(readings)
            f._noise, f._inflation = copy.deepcopy(noise), copy.deepcopy(inflation)
            f.history, f.time, f._pieces.model.clamp_counts = list(history), t_before, clamps
            out[j] = f._finish(t, y, res, list(last), T_mean, T_std, tic)
        if not comp.restart_times and not any(comps[j].restart_times for j in self._followers):
            return e, {}  # no restart went ahead: the followers still follow
        self._followers = []
        return e, out

    def _update_bank(self, t: float, y: np.ndarray) -> OnlineEstimate:
        from ..problem import FilterDivergence

        tic = time.perf_counter()
        ests, lls, errors = [], [], []
        forked = {}  # the followers' estimates at the first drifting filter's restart
        for j, comp in enumerate(self._bank.values()):
            e = None
            if j in self._followers:
                e = ests[1]  # the first drifting filter's: the same filter so far
                self._alive[j] = self._alive[1]
            elif j in forked:
                e = forked[j]
            elif self._alive[j]:
                try:
                    if j == 1 and self._followers:
                        e, forked = self._update_followed(comp, t, y)
                    else:
                        e = comp.update(t, y)
                except FilterDivergence as err:
                    self._alive[j] = False
                    errors.append(err)
            ests.append(e)
            lls.append(np.nan if e is None or e.innovation_loglik is None
                       else e.innovation_loglik)
        if not self._alive.any():
            raise errors[-1]
        pred = self._weights
        self._weights, mix = self._step_weights(t, lls)
        live = [j for j in range(len(ests)) if self._alive[j]]
        w = self._weights[live] / self._weights[live].sum()
        E = [ests[j] for j in live]

        def mix_of(a, b):
            if getattr(E[0], a) is None:
                return None, None
            return mix_moments(np.array([getattr(e, a) for e in E]),
                                np.array([getattr(e, b) for e in E]), w)

        p_mean, p_std = mix_of("param_mean", "param_std")
        T_mean, T_std = mix_of("tracked_mean", "tracked_std")
        o_mean, o_std = mix_of("sensor_offset_mean", "sensor_offset_std")
        lead = ests[int(np.argmax(np.where(self._alive, pred, -1)))] or E[0]
        est = OnlineEstimate(t, p_mean, p_std, T_mean, T_std, any(e.analysed for e in E),
                             time.perf_counter() - tic, o_mean, o_std,
                             lead.innovation_normalized, lead.laser_on, mix,
                             float(1.0 - self._weights[0]))
        self.restart_times = sorted({t for j, c in enumerate(self._bank.values()) if j
                                     for t in c.restart_times})
        self.time = t
        self.history.append(est)
        return est
