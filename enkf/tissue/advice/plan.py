"""What the advice is asked and what it answers: the laser's plan, one member's advice, one
reading's advice (:mod:`enkf.tissue.advice`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["DRIFT_FORECASTS", "RISKS", "REGION_POINTS", "SURFACE_POINTS", "AdviceRow",
           "MemberAdvice", "Plan"]

#: the risks reported: (region, scenario); "at_target": stopped at the member's stop time
RISKS = tuple(f"{r}_{s}" for r in ("protected", "surface") for s in ("plan", "off", "at_target"))
#: how the forecast moves each member's optics (module docstring)
DRIFT_FORECASTS = ("walk+trend", "walk", "hold")
#: most points kept of a region (the hottest of a protected one, the coldest of a target)
#: and of the surface (its hottest nodes), ranked under the plan at the nominal optics
REGION_POINTS, SURFACE_POINTS = 8, 4


@dataclass
class Plan:
    """The laser schedule of the forecast: ``power`` W during the ``pulses`` (s)."""

    power: float  #: W while a pulse is on
    pulses: tuple  #: ((start, end), ...) s, increasing and not overlapping

    def __post_init__(self):
        if isinstance(self.power, bool) or not (np.isfinite(self.power) and self.power >= 0):
            raise ValueError(f"Plan.power must be a finite number >= 0 (W), got {self.power!r}")
        try:
            p = tuple((float(a), float(b)) for a, b in self.pulses)
        except (TypeError, ValueError):
            raise ValueError(f"Plan.pulses must be [(start, end), ...] in s, got "
                             f"{self.pulses!r}") from None
        for i, (a, b) in enumerate(p):
            if not (np.isfinite(a) and np.isfinite(b) and 0 <= a < b):
                raise ValueError(f"Plan.pulses[{i}] = {[a, b]} must have 0 <= start < end (s)")
            if i and a < p[i - 1][1]:
                raise ValueError(f"Plan.pulses[{i}] = {[a, b]} starts before the pulse "
                                 f"before it ends ({p[i - 1][1]:g} s)")
        self.power, self.pulses = float(self.power), p

    @classmethod
    def from_heat_simulation(cls, hs) -> Plan:
        """The schedule of a :class:`mcmatlab_py.heat.HeatSimulation` (a number ``P``)."""
        if callable(hs.P):
            raise ValueError("a plan needs a constant power: HS.P is a function; give the "
                             "plan's power")
        period = hs.duration_on + hs.duration_off
        return cls(float(hs.P), tuple((i * period, i * period + hs.duration_on)
                                      for i in range(int(hs.n_pulses))))

    @property
    def end(self) -> float:
        """s: when the last pulse ends (0 without pulses)."""
        return self.pulses[-1][1] if self.pulses else 0.0

    def on_time(self, t0: float, t1: float) -> float:
        """s of ``[t0, t1)`` with a pulse on (the heated time the optics drift over)."""
        return sum(max(0.0, min(t1, b) - max(t0, a)) for a, b in self.pulses) \
            if self.power > 0 else 0.0

    def mean_power(self, t0: float, t1: float) -> float:
        """W averaged over ``[t0, t1)``: the energy the pulses deliver in it over its length."""
        on = sum(max(0.0, min(t1, b) - max(t0, a)) for a, b in self.pulses)
        return self.power * on / (t1 - t0)


@dataclass
class MemberAdvice:
    """One filter's members at one reading: their times (s) and which risks they run."""

    time: float  #: s, the reading
    horizon_end: float  #: s, the forecast's end
    target_time: np.ndarray  #: (N,) s, the target's Omega >= 1 under the plan (inf: not)
    stop_time: np.ndarray  #: (N,) s, the earliest switch-off that still reaches it (inf)
    risks: dict  #: {name in RISKS: (N,) bool}, the risks with a limit
    wall_s: float  #: s spent on the forecast
    #: {"protected" | "surface": (N,) deg C}: the hottest the region gets under the plan
    #: (so far or within the horizon)
    peak_T: dict = field(default_factory=dict)


@dataclass
class AdviceRow:
    """The advice at one reading: the members' (weighted) distribution."""

    time: float  #: s
    target_time: tuple  #: s, (median, lower, upper quantile); inf: beyond the horizon
    p_target: float  #: probability the target reaches Omega >= 1 under the plan
    stop_time: tuple  #: s, (median, lower, upper quantile)
    risks: dict  #: {name: probability}
    wall_s: float  #: s, the forecast of every filter mixed here
    #: {"protected" | "surface": (median, lower, upper quantile) deg C}: the region's
    #: hottest under the plan
    peak_T: dict = field(default_factory=dict)

    def as_dict(self, quantiles) -> dict:
        """Flat ``{column: value}`` (advice.csv's columns, times in s)."""
        out = {"time_s": self.time}
        for what, v in (("target_time", self.target_time), ("stop_time", self.stop_time)):
            out[f"{what}_median_s"] = v[0]
            for q, x in zip(quantiles, v[1:], strict=True):
                out[f"{what}_q{100 * q:g}_s".replace(".", "p")] = x
            if what == "target_time":
                out["p_target"] = self.p_target
        out.update({f"p_{k}": v for k, v in self.risks.items()})
        for region, v in self.peak_T.items():
            out[f"{region}_peak_T_median_C"] = v[0]
            for q, x in zip(quantiles, v[1:], strict=True):
                out[f"{region}_peak_T_q{100 * q:g}_C".replace(".", "p")] = x
        out["advice_ms"] = 1e3 * self.wall_s
        return out
