r"""Whether the optics drift while the laser heats: filters weighed by their evidence.

A user rarely knows beforehand whether the tissue's optics will change while it is
heated; finding out is one reason to measure. :class:`DriftBank` (the default of
``tissue-enkf identify``) runs several filters on the same readings:

``"still"``
    the setup as given: optics that hold still (its own small random walk, 0.002 log
    units per step by default);
``"drifting-K"``, one for each form ``K`` of :attr:`DriftBank.restart_knots`
    the same setup with optics that drift while the laser heats: a random walk of
    :attr:`DriftBank.walk_std` log units per heated step (none while the laser is off,
    when nothing holds a walk back), restarted from the smoother after each pulse with
    optics piecewise linear in heated time through ``K`` knots (2: a straight line; 9: a
    path that can turn, its knots an eighth of the heated time apart) or, for ``K =
    "logistic"``, a logistic's segment (a ramp, a step at the onset of coagulation, a
    rise that saturates: :mod:`enkf.tissue.paths`), and relaxation of the
    temperatures' spread to the prior's (:attr:`DriftBank.rtps`). Before its first
    restart each drifting filter is the same filter, run once: the later forms resume
    the first one's run there (:class:`~enkf.tissue.identify.RunHead`,
    ``component_forks``); the cooling readings after the restarts tell the forms of
    the drift apart.

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
from dataclasses import replace

import numpy as np

from .estimates import TissueEstimates, persistence_summary
from .setup.drift_bank import STILL, DriftBank, bank_weights, prior_weights

__all__ = ["STILL", "DriftBank", "bank_weights", "identify_bank", "mixture_estimates",
           "weighted_quantiles"]


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


def mix_moments(means, stds, w):
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
                      loglik_mix: np.ndarray, wall_s: float, forks: dict | None = None):
    """One :class:`~enkf.tissue.TissueEstimates` from the bank's filters ``parts``
    (``{name: TissueEstimates}``, the still filter first, each with ``param_members``)
    under ``weights`` (M + 1, K) (:func:`bank_weights`); ``forks`` ``{name: (source,
    readings)}``: filter ``name`` resumed ``source``'s run after that many readings
    (:class:`~enkf.tissue.identify.RunHead`), whose steps it did not compute again."""
    forks = forks or {}
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
        p_mean[k], p_std[k] = mix_moments(stack("param_mean", k, n)[live],
                                           stack("param_std", k, n)[live], w[live])
        t_mean[k], t_std[k] = mix_moments(stack("tracked_mean", k, nt)[live],
                                           stack("tracked_std", k, nt)[live], w[live])
        if off:
            o_mean[k], o_std[k] = mix_moments(stack("sensor_offset_mean", k, n_off)[live],
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
    for name, e in {id(e): (n, e) for n, e in zip(names, ests, strict=True)}.values():
        # a filter that stands for several: once; a resumed one from where it resumed
        first = forks[name][1] if name in forks else 0
        latency[first:len(e.step_latency_s)] += e.step_latency_s[first:k_end - 1]
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
        component_weights={n: w_rows[:, j] for j, n in enumerate(names)},
        component_forks=dict(forks) or None)


def identify_bank(setup, times: np.ndarray, data: np.ndarray, run_single: Callable, *,
                  callback: Callable | None = None, param_bounds=None):
    """:func:`~enkf.tissue.identify` with ``setup.parameters.drift`` (a :class:`DriftBank`):
    the still and the drifting filters on the same readings, weighed by their evidence
    (module docstring). ``run_single(setup, times, data, *, callback, param_bounds,
    restart_gate)`` runs one filter (:func:`enkf.tissue.identify.identify_single`). The
    callback sees each filter's steps, still first, with
    :attr:`~enkf.problem.StepReport.component` naming the filter."""
    bank: DriftBank = setup.parameters.drift
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
    heads = []  # the first drifting filter's run up to its first restart
    for j, name in enumerate(names):
        if j > 1 and not parts[names[1]].restarts:
            # the drifting filters differ only in their restarts' form: with none, each is
            # the first one (the same seeds and settings, the same gates' decisions)
            parts[name], lls = parts[names[1]], [*lls, lls[1]]
            continue
        # with restarts, each resumes the first one's run at its first restart
        shared = dict(head=heads[0]) if j > 1 and heads else \
            dict(on_head=heads.append) if j == 1 else {}
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
            est = run_single(setups[name], times, data, callback=tagged(name),
                             param_bounds=param_bounds, restart_gate=gate, **shared)
        caught.append((name, rec))
        parts[name] = est
        lls.append(_component_loglik(est, M))
    w, pred, mix = bank_weights(np.column_stack(lls), prior, bank.switch_prob, heated)
    forks = {n: (names[1], heads[0].readings) for n in names[2:]
             if heads and parts[n] is not parts[names[1]]}
    est = mixture_estimates(parts, w, pred, mix, time.perf_counter() - tic, forks)
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
