"""The tissue filter's output in physical units (:class:`TissueEstimates`) and the
persistence of its innovations (:func:`laser_persistence`, :func:`persistence_summary`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..adaptive import PERSISTENCE_THRESHOLD, innovation_persistence, persistence_flagged
from ..problem import FilterResult
from .diagnose import drift_weight_of, likely_cause

__all__ = ["TissueEstimates", "laser_persistence", "persistence_summary"]


@dataclass
class TissueEstimates:
    """Filter output in physical units (step 0 is the prior).

    ``param_mean``/``param_std``: (M+1, n_par) in the order of ``names``;
    ``tracked_mean``/``tracked_std``: (M+1, n_tracked) deg C at ``tracked_positions``.
    ``step_latency_s``: (M,) wall time of each filter step.
    ``param_q_low``/``param_q_high``: (M+1, n_par) the 2.3 % and 97.7 % quantiles of the
    ensemble (the +-2 sd points of a normal), positive like the members; None when not
    recorded (then :meth:`param_band` takes them from a log-normal of the same moments).
    ``clamped``: how often the absorption model clamped a member's optics to its table
    (:meth:`TissueForwardModel.clamp_report`), None when never.
    ``effective_mean``/``effective_std``: (M+1, 2) the ensemble's effective (mua, mus)
    cm^-1 and ``coagulated_fraction`` (M+1,) its mean ``F``, with
    ``parameter_model="coagulation"`` (:mod:`enkf.tissue.coagulation`); else None.
    ``innovation_loglik``: (M,) log-density of each reading under the forecast (NaN where
    none was analysed; :func:`enkf.adaptive.innovation_loglik`): the sums of two models on
    the same data compare them.
    ``innovation_normalized``: (M, p) each reading's innovation over its forecast sd
    (:func:`enkf.adaptive.normalized_innovation`, NaN where none was analysed), and
    ``laser_on``: (M,) whether the laser delivered energy during each step;
    :meth:`innovation_persistence` tells from them whether the model misses something.
    ``sensor_offset_mean``/``sensor_offset_std``: (M+1, n_sensors) deg C, the point
    sensors' estimated offsets with ``sensor_offset_std > 0``; else None.
    With restarts (``setup.restarts.times``) the row of a restart's reading holds the
    restarted ensemble; ``step_latency_s`` does not count the restarts (``restarts``).
    """

    times: np.ndarray
    names: tuple
    param_mean: np.ndarray
    param_std: np.ndarray
    tracked_positions: np.ndarray
    tracked_mean: np.ndarray
    tracked_std: np.ndarray
    analysed: np.ndarray
    step_latency_s: np.ndarray
    filter_wall_s: float
    result: FilterResult | None = None
    diverged: str | None = None  #: message when the filter stopped early
    param_q_low: np.ndarray | None = None
    param_q_high: np.ndarray | None = None
    method: str | None = None  #: "etkf" or "enkf"
    clamped: dict | None = None
    effective_mean: np.ndarray | None = None
    effective_std: np.ndarray | None = None
    coagulated_fraction: np.ndarray | None = None
    innovation_loglik: np.ndarray | None = None
    innovation_normalized: np.ndarray | None = None
    laser_on: np.ndarray | None = None
    #: (M+1, n_sensors) deg C: mean and sd of the point sensors' estimated offsets
    #: (``setup.sensors.offset_std > 0``), else None
    sensor_offset_mean: np.ndarray | None = None
    sensor_offset_std: np.ndarray | None = None
    #: the restarts from the smoother (``setup.restarts.times``), one dict each:
    #: ``time_s`` (the reading after which), ``readings`` (how many it read), ``wall_s``
    restarts: tuple = ()
    #: (M+1, N, n_par) the members' parameters at each step (the weighted bands of a
    #: :class:`~enkf.tissue.drift.DriftBank` pool them)
    param_members: np.ndarray | None = None
    #: (M+1,) with ``setup.parameters.drift`` (:class:`~enkf.tissue.drift.DriftBank`): the
    #: probability, after each reading, that the optics drift while heated; else None
    drift_weight: np.ndarray | None = None
    #: with ``setup.parameters.drift``: ``{"still": TissueEstimates, "drifting-2": ..., ...}``, the
    #: bank's filters (these estimates are their mixture); else None
    components: dict | None = None
    #: with ``setup.parameters.drift``: ``{name: (M+1,)}``, each filter's probability after each
    #: reading (their sum is 1); else None
    component_weights: dict | None = None
    #: with ``setup.parameters.drift``: ``{name: (source, readings)}``, the drifting filters
    #: that resumed ``source``'s run after ``readings`` readings (its first restart): their
    #: steps up to there are ``source``'s; None where none did
    component_forks: dict | None = None

    @property
    def leading_component(self) -> str | None:
        """With ``setup.parameters.drift``: the bank's filter of the largest final weight (its risk
        maps are the run's); None without a bank."""
        if not self.component_weights:
            return None
        return max(self.component_weights, key=lambda n: self.component_weights[n][-1])

    @property
    def drift_behaviour(self) -> str | None:
        """What the data support at the end, with ``setup.parameters.drift``: ``"drifting"`` or
        ``"still"`` (the more probable), None without a bank."""
        if self.drift_weight is None or not len(self.drift_weight):
            return None
        return "drifting" if self.drift_weight[-1] >= 0.5 else "still"

    def log_evidence(self) -> float:
        """Sum of :attr:`innovation_loglik` over the analysed readings (NaN if not recorded)."""
        if self.innovation_loglik is None:
            return float("nan")
        return float(np.nansum(self.innovation_loglik))

    def innovation_persistence(self, laser: str = "off") -> tuple[float, int]:
        """Lag-1 correlation of the normalized innovations from reading to reading, and the
        number of pairs it sums, over the steps where the laser is ``"off"`` (default),
        ``"on"``, or over ``"all"``: :func:`laser_persistence`."""
        return laser_persistence(self.innovation_normalized, self.laser_on, laser)

    def param_band(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of parameter ``i`` over time: the ensemble's 2.3 % and 97.7 %
        quantiles, or those of a log-normal with the recorded mean and std (the filter
        works on log parameters, so the band stays positive; mean +- 2 sd does not)."""
        if self.param_q_low is not None:
            return self.param_q_low[:, i], self.param_q_high[:, i]
        m, s = self.param_mean[:, i], self.param_std[:, i]
        with np.errstate(invalid="ignore", divide="ignore"):
            s2 = np.log1p((s / m) ** 2)
            mu = np.log(m) - 0.5 * s2
            return np.exp(mu - 2 * np.sqrt(s2)), np.exp(mu + 2 * np.sqrt(s2))


def laser_persistence(z: np.ndarray | None, laser_on: np.ndarray | None,
                      laser: str = "off") -> tuple[float, int]:
    """:func:`enkf.adaptive.innovation_persistence` of the normalized innovations ``z``
    (M, p) over the steps where the laser is ``"off"`` (``laser_on`` (M,) False), ``"on"``,
    or over ``"all"``; ``(nan, 0)`` when ``z`` was not recorded or no pair is left.

    With the laser off the forecast is heat conduction alone and the optics no longer take
    up what the model gets wrong, so a heat model that misses the tissue's physics (its
    shape, boundaries, conduction) leaves innovations that persist from frame to frame.
    """
    if laser not in ("off", "on", "all"):
        raise ValueError(f"laser must be 'off', 'on' or 'all', got {laser!r}")
    if z is None or len(z) == 0:
        return float("nan"), 0
    z = np.asarray(z, float)
    if laser == "all":
        return innovation_persistence(z)
    if laser_on is None:
        return float("nan"), 0
    return innovation_persistence(z, np.asarray(laser_on, bool)[: z.shape[0]] == (laser == "on"))


def persistence_summary(est) -> dict:
    """summary.json's ``innovation_persistence``: the lag-1 correlation of the normalized
    innovations while the laser is off and over all readings, whether it is flagged
    (:func:`enkf.adaptive.persistence_flagged`) and what that means (``advice``, also
    the warning's text), of ``est`` (a :class:`~enkf.tissue.TissueEstimates` or an
    :class:`~enkf.tissue.OnlineIdentifier`); ``likely_cause`` names what the evidence
    points at (:func:`enkf.tissue.diagnose.likely_cause`: drifting optics, a sensor
    offset, the model's physics), and ``advice`` what to do about it (None when nothing
    is to be done: no misfit, or a drift the drift bank has taken up)."""
    r_off, n_off = est.innovation_persistence("off")
    r_on, n_on = est.innovation_persistence("on")
    r_all, n_all = est.innovation_persistence("all")
    flagged = persistence_flagged(r_off, n_off)
    cause, advice = likely_cause(est, r_off, n_off, r_on, n_on)
    if cause == "drifting optics" and not flagged and drift_weight_of(est) is not None:
        advice = None  # a drift bank has taken the drift up: nothing to do

    def num(r):
        return round(float(r), 4) if np.isfinite(r) else None

    return {"laser_off": num(r_off), "laser_off_pairs": n_off,
            "laser_on": num(r_on), "laser_on_pairs": n_on,
            "all": num(r_all), "all_pairs": n_all,
            "threshold": PERSISTENCE_THRESHOLD, "flagged": flagged or advice is not None,
            "likely_cause": cause, "advice": advice}
