r"""Whether the optics drift while the laser heats: filters weighed by their evidence.

A user rarely knows beforehand whether the tissue's optics will change while it is
heated; finding out is one reason to measure. :class:`DriftBank` (the default of
``tissue-enkf identify``) runs several filters on the same readings:

``"still"``
    the setup as given: optics that hold still (its own small random walk, 0.002 log
    units per step by default);
``"drifting-K"``, one for each ``K`` of :attr:`DriftBank.restart_knots`
    the same setup with optics that drift while the laser heats: a random walk of
    :attr:`DriftBank.walk_std` log units per heated step (none while the laser is off,
    when nothing holds a walk back), restarted from the smoother after each pulse with
    optics piecewise linear in heated time through ``K`` knots (2: a straight line; 6: a
    path that can turn, e.g. a step at the onset of coagulation), and relaxation of the
    temperatures' spread to the prior's (:attr:`DriftBank.rtps`). Before its first
    restart each drifting filter is the same filter; the cooling readings after the
    restarts tell the forms of the drift apart.

Each reading's density under each filter's forecast,
:math:`\ell_{k,j} = \log p(y_k \mid y_{1:k-1}, \text{model } j)`
(:func:`enkf.adaptive.innovation_loglik`, the prediction-error decomposition of the
evidence), updates the models' probabilities as the mode probabilities of the
interacting-multiple-model filter (Blom & Bar-Shalom 1988, IEEE TAC 33):

.. math::

    \tilde w_{k,j} = (1 - \pi)\, w_{k-1,j} + \frac{\pi}{K - 1} (1 - w_{k-1,j}),
    \qquad w_{k,j} \propto \tilde w_{k,j}\, e^{\ell_{k,j}},

with a switch probability :math:`\pi` per heated reading (:attr:`DriftBank.switch_prob`),
so that optics that start to drift late are still taken up. The reported estimates are
the mixture of the ensembles under these weights (means, spreads, and the quantile bands
of the weighted members), and the probability of a drift, one less the still filter's
weight, is reported at every reading (``drift_weight``). A drifting filter restarts from
the smoother only where the data support it against still optics (its weight in that
pair above :attr:`DriftBank.restart_weight`): constant optics cost no smoother run.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["STILL", "DriftBank", "bank_weights", "identify_bank", "mixture_estimates",
           "weighted_quantiles"]

#: the name of the bank's filter with still optics (the drifting ones: ``"drifting-K"``)
STILL = "still"
#: the parameters whose walk :attr:`DriftBank.walk_std` sets: mua's value for the
#: absorption coefficients, mus's for the scattering ones
_WALKED = {"mua": 0, "mua2": 0, "mus": 1, "mus2": 1}


@dataclass
class DriftBank:
    """The drifting filter of the bank and how the two filters are weighed.

    Parameters
    ----------
    walk_std : (2,) log units per heated step
        The drifting filter's random walk of (mua, mus) (also of a second medium's
        mua2, mus2); other estimated parameters (VHC, TC, the beam's radius) are
        constants of the drifting filter (its restarts fit one value each).
    walk_std_thermal : (3,) log units per heated step
        The drifting filters' walk of mua, mus and of VHC and TC when the thermal
        properties are estimated too: with mua's walk of ``walk_std`` and none on VHC and
        TC, a lagging mua was made up for by them and the first reading after the
        paper's all-parameters pulse threw mus out of its bounds (every seed of 0-4
        stopped there); the paper's own walk (these values) gets every seed through.
    switch_prob : float
        Probability per heated reading that the optics' behaviour changes (the IMM's
        transition probability): it keeps either model's weight above about
        ``switch_prob`` while the laser heats, so that a drift that starts late is still
        taken up.
    prior_weight : float
        Probability of a drift before any reading.
    restart_weight : float
        The drifting filter restarts from the smoother after a pulse only while its
        weight is above this: below it, the data do not support a drift.
    restart_delay : float
        s after each pulse's end at which the drifting filter restarts (some cooling
        readings tell the optics' final values).
    restart_knots : tuple of int
        The forms of the drift, one drifting filter each: the knots of its restarts'
        piecewise-linear paths in heated time (each >= 2). A form with more free values
        (every knot of every drifting parameter) than the ensemble has members is left
        out (e.g. 6 knots of two media's four optics with 20 members).
    restart_discrepancy : float
        The restarts' model discrepancy (relative sd of the rise).
    rtps : float
        The drifting filter's relaxation to prior spread (in [0, 1]).
    """

    walk_std: Sequence[float] = (0.03, 0.10)
    walk_std_thermal: Sequence[float] = (0.05, 0.10, 0.01)
    switch_prob: float = 1e-3
    prior_weight: float = 0.5
    restart_weight: float = 0.05
    restart_delay: float = 2.5
    restart_knots: tuple = (2, 3, 6)
    restart_discrepancy: float = 0.01
    rtps: float = 0.1

    def __post_init__(self):
        try:
            w = tuple(float(v) for v in np.broadcast_to(np.asarray(self.walk_std, float), (2,)))
        except (TypeError, ValueError):
            raise ValueError(f"DriftBank.walk_std must be one or two numbers (log units per "
                             f"step, mua and mus), got {self.walk_std!r}") from None
        if not all(np.isfinite(v) and v > 0 for v in w):
            raise ValueError(f"DriftBank.walk_std must be > 0 (log units per step), got "
                             f"{self.walk_std!r}")
        self.walk_std = w
        try:
            wt = tuple(float(v) for v in np.broadcast_to(np.asarray(self.walk_std_thermal, float),
                                                         (3,)))
        except (TypeError, ValueError):
            raise ValueError(f"DriftBank.walk_std_thermal must be three numbers (mua, mus, "
                             f"VHC and TC), got {self.walk_std_thermal!r}") from None
        if not all(np.isfinite(v) and v >= 0 for v in wt):
            raise ValueError(f"DriftBank.walk_std_thermal must be >= 0, got "
                             f"{self.walk_std_thermal!r}")
        self.walk_std_thermal = wt
        for name, lo, hi in (("switch_prob", 0.0, 0.5), ("prior_weight", 0.0, 1.0),
                             ("restart_weight", 0.0, 1.0), ("rtps", 0.0, 1.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and lo <= v <= hi):
                raise ValueError(f"DriftBank.{name} must be in [{lo:g}, {hi:g}], got {v!r}")
        if not 0.0 < self.prior_weight < 1.0:
            raise ValueError(f"DriftBank.prior_weight must be strictly between 0 and 1, got "
                             f"{self.prior_weight!r}")
        for name in ("restart_delay", "restart_discrepancy"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and np.isfinite(v)
                                           and v >= 0):
                raise ValueError(f"DriftBank.{name} must be >= 0, got {v!r}")
        k = self.restart_knots
        k = tuple(k) if isinstance(k, (list, tuple)) else (k,)
        if not k or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool)
                            and v >= 2 for v in k) or len(set(k)) < len(k):
            raise ValueError(f"DriftBank.restart_knots must be different integers >= 2, got "
                             f"{self.restart_knots!r}")
        self.restart_knots = tuple(int(v) for v in k)

    def components(self, setup) -> dict:
        """``{"still": setup, "drifting-K": setup, ...}``: the bank's filters' setups from
        the user's ``setup`` (a :class:`~enkf.tissue.TissueFilterSetup` with ``drift``
        set), each without a bank of its own; one drifting filter for each ``K`` of
        :attr:`restart_knots`."""
        out = {STILL: replace(setup, drift=None)}
        names = setup.parameter_names
        # the optics drift (with VHC and TC estimated, those drift too: walk_std_thermal);
        # the beam's radius holds, fitted as a constant by the restarts
        thermal = "VHC" in names
        w = self.walk_std_thermal if thermal else self.walk_std
        walk = np.array([w[_WALKED[n]] if n in _WALKED else
                         (w[2] if n in ("VHC", "TC") else 0.0) for n in names])
        kw = dict(drift=None, random_walk_std=walk.tolist(), random_walk_when_off=0.0,
                  rtps=self.rtps)
        drifting = sum(n in _WALKED or walk[i] > 0 for i, n in enumerate(names))
        forms = [k for k in self.restart_knots if not setup.smoother_restart_gaussian
                 or setup.n_members > len(names) + (k - 1) * drifting]
        # forms with more free values than members cannot be redrawn: left out (the
        # smallest is kept, restarted as the setup allows)
        for k in forms or self.restart_knots[:1]:
            if setup.sensor_offset_std:  # the smoother does not estimate sensor offsets
                out[f"drifting-{k}"] = replace(setup, **kw, smoother_restarts=())
                break  # one drifting filter: without restarts the forms are the same
            out[f"drifting-{k}"] = replace(
                setup, **kw, smoother_restarts="laser_off",
                smoother_restart_delay=self.restart_delay, smoother_restart_knots=k,
                smoother_restart_discrepancy=self.restart_discrepancy)
        return out


def bank_weights(loglik: np.ndarray, prior: Sequence[float], switch_prob: float,
                 switching: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The models' probabilities over the readings (the IMM's mode probabilities).

    Parameters
    ----------
    loglik : (M, K)
        Log-density of each reading under each model's forecast; NaN where a reading was
        not analysed (the weights then only switch), ``-inf`` where a model had stopped.
    prior : (K,)
        Probabilities before the first reading.
    switch_prob : float
        Probability per reading of leaving a model, spread evenly over the others.
    switching : (M,) bool, optional
        The readings before which a switch can happen (default: all). The bank's models
        differ only while the laser heats, so it switches only then: with the laser off
        both predict alike and a switch would only move the weights towards even.

    Returns
    -------
    weights : (M + 1, K)
        Row 0 the prior, row ``k`` after reading ``k``.
    predicted : (M, K)
        The weights before each reading (after the switch).
    loglik_mix : (M,)
        Log-density of each reading under the mixture (NaN where not analysed): summed,
        the bank's log evidence.
    """
    ll = np.asarray(loglik, float)
    M, K = ll.shape
    w = np.asarray(prior, float).copy()
    out, pred, mix = np.zeros((M + 1, K)), np.zeros((M, K)), np.full(M, np.nan)
    out[0] = w
    alive = np.ones(K, bool)
    for k in range(M):
        alive &= ~np.isneginf(ll[k])
        pi = switch_prob if switching is None or switching[k] else 0.0
        p = (1.0 - pi) * w + pi * (1.0 - w) / max(K - 1, 1)
        p = np.where(alive, p, 0.0)
        p = p / p.sum() if p.sum() > 0 else p
        pred[k] = p
        row = ll[k]
        if np.all(np.isnan(row[alive])) or not alive.any():
            w = p
        else:
            lr = np.where(alive, np.nan_to_num(row, nan=0.0, neginf=-np.inf), -np.inf)
            with np.errstate(divide="ignore"):
                a = np.log(p) + lr
            top = np.max(a)
            w = np.exp(a - top)
            w /= w.sum()
            mix[k] = top + np.log(np.sum(np.exp(a - top)))
        out[k + 1] = w
    return out, pred, mix


def weighted_quantiles(values: Sequence[np.ndarray], weights: Sequence[float],
                       q: Sequence[float]) -> np.ndarray:
    """Quantiles ``q`` of the mixture of ensembles: ``values[j]`` (N_j, n) members of
    ensemble ``j``, which holds probability ``weights[j]`` spread evenly over its
    members. Returns (len(q), n); the inverse of the mixture's step CDF at the members'
    mid-probabilities (``np.quantile``'s Hazen rule for one ensemble)."""
    v = np.concatenate([np.asarray(x, float) for x in values])
    p = np.concatenate([np.full(len(x), float(wj) / len(x)) for x, wj in
                        zip(values, weights, strict=True)])
    p = p / p.sum()
    out = np.empty((len(q), v.shape[1]))
    for i in range(v.shape[1]):
        order = np.argsort(v[:, i], kind="stable")
        vi, pi = v[order, i], p[order]
        keep = pi > 0
        vi, pi = vi[keep], pi[keep]
        mid = np.cumsum(pi) - 0.5 * pi
        out[:, i] = np.interp(q, mid, vi)
    return out


def _mix_moments(means, stds, w):
    """Mean and sd of a mixture: ``means``/``stds`` (K, n), weights ``w`` (K,)."""
    m = np.einsum("k,kn->n", w, means)
    second = np.einsum("k,kn->n", w, stds ** 2 + means ** 2)
    return m, np.sqrt(np.maximum(second - m ** 2, 0.0))


def _component_loglik(est, M: int) -> np.ndarray:
    """(M,) the component's log-densities; -inf from the step its health check rejected."""
    ll = np.full(M, -np.inf)
    if est.innovation_loglik is not None:
        k = len(est.innovation_loglik) - (1 if est.diverged else 0)
        ll[:k] = est.innovation_loglik[:k]
    return ll


def mixture_estimates(parts: dict, weights: np.ndarray, predicted: np.ndarray,
                      loglik_mix: np.ndarray, wall_s: float):
    """One :class:`~enkf.tissue.TissueEstimates` from the bank's filters ``parts``
    (``{name: TissueEstimates}``, the still filter first, each with ``param_members``)
    under ``weights`` (M + 1, K) (:func:`bank_weights`)."""
    from .identify import TissueEstimates

    names = list(parts)
    ests = [parts[n] for n in names]
    M = weights.shape[0] - 1
    # a component's rows: up to its last accepted step (its weight is 0 beyond)
    rows = [len(e.times) - (1 if e.diverged else 0) for e in ests]
    k_end = max(len(e.times) for e in ests)
    longest = int(np.argmax([len(e.times) for e in ests]))
    times = ests[longest].times
    n = len(ests[0].names)
    nt = ests[0].tracked_mean.shape[1]

    def stack(attr, k, width):
        return np.array([getattr(e, attr)[k] if k < len(getattr(e, attr)) else np.zeros(width)
                         for e in ests])

    p_mean, p_std = np.zeros((k_end, n)), np.zeros((k_end, n))
    q_lo, q_hi = np.zeros((k_end, n)), np.zeros((k_end, n))
    t_mean, t_std = np.zeros((k_end, nt)), np.zeros((k_end, nt))
    off = ests[0].sensor_offset_mean is not None
    n_off = ests[0].sensor_offset_mean.shape[1] if off else 0
    o_mean, o_std = np.zeros((k_end, n_off)), np.zeros((k_end, n_off))
    w_rows = np.zeros((k_end, len(ests)))
    for k in range(k_end):
        w = weights[min(k, M)].copy()
        for j, r in enumerate(rows):
            if k >= r:
                w[j] = 0.0
        if w.sum() == 0:  # every component stopped here: the longest's rejected row
            w[longest] = 1.0
        w /= w.sum()
        w_rows[k] = w
        live = [j for j in range(len(ests)) if w[j] > 0]
        p_mean[k], p_std[k] = _mix_moments(stack("param_mean", k, n)[live],
                                           stack("param_std", k, n)[live], w[live])
        t_mean[k], t_std[k] = _mix_moments(stack("tracked_mean", k, nt)[live],
                                           stack("tracked_std", k, nt)[live], w[live])
        if off:
            o_mean[k], o_std[k] = _mix_moments(stack("sensor_offset_mean", k, n_off)[live],
                                               stack("sensor_offset_std", k, n_off)[live], w[live])
        q_lo[k], q_hi[k] = weighted_quantiles([ests[j].param_members[k] for j in live],
                                              w[live], [0.02275, 0.97725])
    # per step: the normalized innovations of the model that was more probable before it
    lead = np.argmax(predicted[:k_end - 1], axis=1) if k_end > 1 else np.zeros(0, int)
    z = None
    if all(e.innovation_normalized is not None for e in ests):
        z = np.stack([ests[j].innovation_normalized[i] if i < len(ests[j].innovation_normalized)
                      else np.full(ests[0].innovation_normalized.shape[1], np.nan)
                      for i, j in enumerate(lead)]) if lead.size else \
            ests[0].innovation_normalized[:0]
    final = int(np.argmax(w_rows[-1]))
    alive_to_end = [e for e in ests if not e.diverged]
    latency = np.zeros(k_end - 1)
    for e in {id(e): e for e in ests}.values():  # a filter that stands for several: once
        latency[:len(e.step_latency_s)] += e.step_latency_s[:k_end - 1]
    still = names.index(STILL)
    return TissueEstimates(
        times=times, names=ests[0].names, param_mean=p_mean, param_std=p_std,
        tracked_positions=ests[0].tracked_positions, tracked_mean=t_mean, tracked_std=t_std,
        analysed=ests[longest].analysed, step_latency_s=latency, filter_wall_s=wall_s,
        result=ests[final].result,
        diverged=None if alive_to_end else ests[longest].diverged,
        param_q_low=q_lo, param_q_high=q_hi, method=ests[0].method,
        clamped=None, innovation_loglik=loglik_mix[:k_end - 1],
        innovation_normalized=z, laser_on=ests[longest].laser_on,
        sensor_offset_mean=o_mean if off else None, sensor_offset_std=o_std if off else None,
        restarts=tuple({**r, "component": names[j]} for j, e in enumerate(ests)
                       for r in e.restarts),
        drift_weight=1.0 - w_rows[:, still], components=dict(parts),
        component_weights={n: w_rows[:, j] for j, n in enumerate(names)})


def prior_weights(bank: DriftBank, names) -> np.ndarray:
    """(K,) the filters' probabilities before any reading: ``1 - prior_weight`` for the
    still filter, ``prior_weight`` shared evenly by the drifting ones."""
    drifting = len(names) - 1
    return np.array([1.0 - bank.prior_weight if n == STILL else bank.prior_weight / drifting
                     for n in names])


def identify_bank(setup, times: np.ndarray, data: np.ndarray, *,
                  callback: Callable | None = None, param_bounds=None):
    """:func:`~enkf.tissue.identify` with ``setup.drift`` (a :class:`DriftBank`): the
    still and the drifting filters on the same readings, weighed by their evidence
    (module docstring). The callback sees each filter's steps, still first, with
    :attr:`~enkf.problem.StepReport.component` naming the filter."""
    from .identify import _identify_single

    bank: DriftBank = setup.drift
    setups = bank.components(setup)
    names = list(setups)
    times = np.asarray(times, float)
    M = len(times)
    prior = prior_weights(bank, names)
    tic = time.perf_counter()
    parts, lls, caught = {}, [], []

    def tagged(name):
        if callback is None:
            return None
        return lambda rep: callback(replace(rep, component=name))

    heated = np.array([setup.mean_power(float(a), float(b)) > 0
                       for a, b in zip(np.r_[0.0, times[:-1]], times, strict=True)], bool)
    for j, name in enumerate(names):
        if j > 1 and not parts[names[1]].restarts:
            # the drifting filters differ only in their restarts' form: with none, each is
            # the first one (the same seeds and settings, the same gates' decisions)
            parts[name], lls = parts[names[1]], [*lls, lls[1]]
            continue
        gate = None
        if j:
            pair = prior[[0, j]] / prior[[0, j]].sum()

            def gate(a, ll_so_far, still_ll=lls[0], pair=pair):
                # this drifting filter's weight against still optics after reading a
                ll = np.column_stack([still_ll[:a], np.r_[ll_so_far, np.full(
                    a - len(ll_so_far), np.nan)][:a]])
                w = bank_weights(ll, pair, bank.switch_prob, heated[:a])[0][-1, 1]
                return w > bank.restart_weight
        with warnings.catch_warnings(record=True) as rec:
            warnings.simplefilter("always")
            est = _identify_single(setups[name], times, data, callback=tagged(name),
                                   param_bounds=param_bounds, restart_gate=gate)
        caught.append((name, rec))
        parts[name] = est
        lls.append(_component_loglik(est, M))
    w, pred, mix = bank_weights(np.column_stack(lls), prior, bank.switch_prob, heated)
    est = mixture_estimates(parts, w, pred, mix, time.perf_counter() - tic)
    est.clamped = _bank_clamps(parts, est.component_weights)
    _reissue(caught, est)
    return est


def _bank_clamps(parts: dict, weights: dict) -> dict | None:
    """The emulator's clamps of each filter, with the filter's final weight: a clamp in a
    filter the data reject biased nothing that is reported."""
    out = {name: {**e.clamped, "final_weight": float(weights[name][-1])}
           for name, e in parts.items() if e.clamped}
    return out or None


def _reissue(caught, est) -> None:
    """The filters' warnings, once each, with the filter's name and final weight."""
    from .identify import persistence_summary

    for name, rec in caught:
        w = float(est.component_weights[name][-1])
        for r in rec:
            text = str(r.message)
            if "innovations persist" in text:  # said once below, for the mixture
                continue
            if "clamped" in text:
                share = ("the data reject it" if w < 0.05 else
                         f"it makes {w:.0%} of the reported estimates")
                text = f"the {name} filter (weight {w:.3g} at the end: {share}): {text}"
            warnings.warn(text, r.category, stacklevel=3)
    persistence = persistence_summary(est)
    if persistence["flagged"]:
        warnings.warn(persistence["advice"], RuntimeWarning, stacklevel=3)
