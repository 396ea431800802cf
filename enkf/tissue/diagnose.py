"""What the innovations say went wrong: the likely cause of a misfit, from the evidence.

A filter whose model misses something leaves innovations (the readings less their
forecasts, over the forecast's sd) that are not white. Their pattern points at the cause:

``"drifting optics"``
    the data support a drift (a :class:`~enkf.tissue.drift.DriftBank`'s weight above one
    half) and the innovations are white while the laser is off, or, with the filter
    alone, the innovations persist while the laser heats more than while it is off: the
    optics change under the beam.
``"sensor offset"``
    the first readings, taken before the laser has raised the temperature by more than
    a few tenths of a degree, already miss on one side: the sensor's zero is off.
``"model physics"``
    the innovations persist while the laser is off, when the forecast is heat conduction
    alone: the heat model misses the tissue's shape, boundaries, perfusion or conduction
    (or the beam's size, which sets where the heat starts).

:func:`likely_cause` returns the first that the evidence supports (the offset first, then
the physics: innovations that persist with the laser off are the heat model's, whatever
else the data support), and the advice for it; the command line writes both into summary.json and the warning.
"""

from __future__ import annotations

import numpy as np

from ..adaptive import persistence_flagged

__all__ = ["ADVICE", "EARLY_READINGS", "OFFSET_Z", "drift_weight_of", "likely_cause"]

#: readings at the start whose innovations tell a sensor's offset
EARLY_READINGS = 5
#: the early readings' mean normalized innovation, in absolute value, above which an offset
#: is likely
OFFSET_Z = 2.0

#: what to do about each cause ({r}: the lag-1 correlation while the laser is off)
ADVICE = {
    "drifting optics": (
        "the optics drift while heated (the data support it{how}): the estimates follow "
        "the drifting filters of [filter.drift], and the bands below the surface rest on "
        "their restarts from the smoother after each pulse; see docs/enkf.md, 'Drifting "
        "optics'"),
    "sensor offset": (
        "the first readings, before the laser has heated the tissue, already miss the "
        "known start temperature by {z:.1f} forecast sd on average: the sensor's zero is "
        "likely off. Set filter.sensor_offset_std = 0.5 (deg C) to estimate its offset "
        "with the optics (validation/reports/sensor_offset.md)"),
    "model physics": (
        "the filter's innovations persist from reading to reading while the laser is off "
        "(lag-1 correlation {r:.2f}; white when the model is right): the heat model misses "
        "something the data show (the tissue's shape, boundaries, perfusion, conduction, "
        "or the beam's size, which sets where the heat starts), and the temperature bands "
        "below the surface, and the optics' bands, may be too narrow. Check the geometry, "
        "the heat settings and the beam against the tissue (filter.estimate = [\"mua\", "
        "\"mus\", \"beam_radius\"] when the beam's radius is known only roughly); see "
        "docs/beyond.md, 'A model that misses the truth's physics'"),
}


def likely_cause(est, r_off: float, n_off: int, r_on: float, n_on: int) -> tuple[str | None, str | None]:
    """``(cause, advice)`` of the misfit of ``est`` (a
    :class:`~enkf.tissue.TissueEstimates` or an :class:`~enkf.tissue.OnlineIdentifier`),
    given the innovations' lag-1 correlation while the laser is off (``r_off`` over
    ``n_off`` pairs) and on (``r_on``, ``n_on``); ``(None, None)`` when nothing is
    flagged (module docstring). Innovations that persist while the laser is off are the
    heat model's, whatever a drift bank says: with the laser off the optics act on
    nothing."""
    w = drift_weight_of(est)
    flagged_off = persistence_flagged(r_off, n_off)
    flagged_on = persistence_flagged(r_on, n_on)
    z_early = _early_innovation(est)
    if (flagged_off or flagged_on) and np.isfinite(z_early) and abs(z_early) > OFFSET_Z \
            and getattr(est, "sensor_offset_mean", None) is None:
        return "sensor offset", ADVICE["sensor offset"].format(z=abs(z_early))
    if flagged_off:
        extra = "" if w is None else (f" (the data also support a drift of the optics while "
                                      f"heated, P = {w:.2g})")
        return "model physics", ADVICE["model physics"].format(r=r_off) + extra
    if w is not None and w > 0.5:
        return "drifting optics", ADVICE["drifting optics"].format(how=f", P = {w:.2g}")
    if w is None and flagged_on and (not np.isfinite(r_off) or r_on > r_off + 0.2):
        return "drifting optics", ADVICE["drifting optics"].format(
            how=": the innovations persist while heated") + (
            ". Set [filter.drift] mode = \"auto\" to let the data decide")
    return None, None


def drift_weight_of(est) -> float | None:
    """The drift bank's final probability of a drift in ``est`` (None without a bank)."""
    w = getattr(est, "drift_weight", None)
    if w is None:  # an online identifier: its last estimate's
        h = getattr(est, "history", None)
        w = h[-1].drift_weight if h else None
        return None if w is None else float(w)
    return float(w[-1]) if len(w) else None


def _early_innovation(est) -> float:
    """Mean normalized innovation of the first :data:`EARLY_READINGS` analysed readings."""
    z = getattr(est, "innovation_normalized", None)
    if z is None and getattr(est, "history", None):
        z = np.array([h.innovation_normalized for h in est.history])
    if z is None or not len(z):
        return float("nan")
    z = np.asarray(z, float).reshape(len(z), -1)
    rows = [r for r in z if np.isfinite(r).any()][:EARLY_READINGS]
    return float(np.nanmean(np.concatenate(rows))) if rows else float("nan")
