"""The drift bank's settings and weights (:class:`DriftBank`, :func:`bank_weights`).

The part of a :class:`~enkf.tissue.TissueFilterSetup` that asks whether the optics drift
(``setup.parameters.drift``), and the interacting-multiple-model weights of its filters;
the bank's run is :func:`enkf.tissue.drift.identify_bank`, whose module docstring gives
the method. Kept apart from it so that the setup can check a bank without importing the
filter.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..paths import check_form, free_values

__all__ = ["STILL", "DriftBank", "bank_weights", "prior_weights"]

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
    restart_knots : tuple of int or "logistic"
        The forms of the drift, one drifting filter each (:mod:`enkf.tissue.paths`): the
        knots of its restarts' piecewise-linear paths in heated time (each >= 2), or
        ``"logistic"``, a logistic's segment between a value before and one after the
        drift. A form with more free values (every knot of every drifting parameter)
        than the ensemble has members is left out (e.g. 6 knots of two media's four
        optics with 20 members). The default: a line; a path whose knots are an eighth of
        the heated time apart, fine enough for a step of the optics over a tenth of it
        (with 6 knots, the step of ``validation/drift_bank.py`` left the restarts' end
        values on the wrong side of the mua-mus ridge on 9 of 20 seeds); and the
        logistic, which follows a ramp, a step or a saturating rise with four unknowns
        where the 9 knots need 18: its bound on mus at the end is 1-2% of the value
        against 14-28% (``validation/reports/drift_identifiability.md``).
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
    restart_delay: float = 1.0
    restart_knots: tuple = (2, 9, "logistic")
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
        k = tuple(check_form(v, "DriftBank.restart_knots") for v in k)
        if not k or len(set(k)) < len(k):
            raise ValueError(f"DriftBank.restart_knots must be different forms (integers >= 2, "
                             f"'logistic'), got {self.restart_knots!r}")
        self.restart_knots = k

    def components(self, setup) -> dict:
        """``{"still": setup, "drifting-K": setup, ...}``: the bank's filters' setups from
        the user's ``setup`` (a :class:`~enkf.tissue.TissueFilterSetup` with ``drift``
        set), each without a bank of its own; one drifting filter for each ``K`` of
        :attr:`restart_knots`."""
        out = {STILL: setup.with_(drift=None)}
        names = setup.parameters.names
        # the optics drift (with VHC and TC estimated, those drift too: walk_std_thermal);
        # the beam's radius holds, fitted as a constant by the restarts
        thermal = "VHC" in names
        w = self.walk_std_thermal if thermal else self.walk_std
        walk = np.array([w[_WALKED[n]] if n in _WALKED else
                         (w[2] if n in ("VHC", "TC") else 0.0) for n in names])
        kw = dict(drift=None, random_walk_std=walk.tolist(), random_walk_when_off=0.0,
                  rtps=self.rtps)
        drifting = sum(n in _WALKED or walk[i] > 0 for i, n in enumerate(names))
        forms = [k for k in self.restart_knots if not setup.restarts.gaussian
                 or setup.n_members > free_values(k, len(names), drifting)]
        # forms with more free values than members cannot be redrawn: left out (the
        # smallest is kept, restarted as the setup allows)
        for k in forms or self.restart_knots[:1]:
            if setup.sensors.offset_std:  # the smoother does not estimate sensor offsets
                out[f"drifting-{k}"] = setup.with_(**kw, smoother_restarts=())
                break  # one drifting filter: without restarts the forms are the same
            out[f"drifting-{k}"] = setup.with_(
                **kw, smoother_restarts="laser_off",
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


def prior_weights(bank: DriftBank, names) -> np.ndarray:
    """(K,) the filters' probabilities before any reading: ``1 - prior_weight`` for the
    still filter, ``prior_weight`` shared evenly by the drifting ones."""
    drifting = len(names) - 1
    return np.array([1.0 - bank.prior_weight if n == STILL else bank.prior_weight / drifting
                     for n in names])
