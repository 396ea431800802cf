"""The ``[advice]`` table of an identification config: how long to keep the laser on.

::

    [advice]                       # enkf.tissue.advice: each member forecast to the target
    target_depth = 0.1             # cm below the beam's axis (x = y = 0); or
                                   # target_point = [x, y, z] or
                                   # target_region = [[x0, x1], [y0, y1], [z0, z1]] (cm):
                                   # every point of it must reach Omega >= 1
    protected_depth = 0.2          # tissue to spare (or protected_point, protected_region)
    protected_T = 50.0             # deg C it must stay below, and/or
    protected_omega = 1.0          # the damage it must stay below
    surface_T = 100.0              # deg C the surface must stay below
    plan_power = 1.0               # W: the plan (default HS.P)
    plan_pulses = [[0.0, 5.0]]     # s: its pulses (default HS's schedule)
    tail = 5.0                     # s forecast after the plan's last pulse
    max_horizon = 30.0             # s, the farthest a forecast reaches
    quantiles = [0.05, 0.95]       # the interval reported around the median
    step = 0.1                     # s, the forecast's heat step (default HS.dt, else 0.1)
    drift = "walk+trend"           # drifting filters' optics in the forecast: their walk
                                   # and each member's trend; "walk"; "hold"

The damage law is the estimated medium's (``G.media[i].E`` and ``.A``). Every value is
checked on load: a :class:`~mcmatlab_py.config.ConfigError` names the key and the value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fem.checks import check_number, shorten
from mcmatlab_py.config import ConfigError, check_keys

__all__ = ["ADVICE_KEYS", "AdviceSpec", "advice_settings"]

ADVICE_KEYS = {f"{w}_{k}" for w in ("target", "protected") for k in ("depth", "point", "region")}
ADVICE_KEYS |= {"protected_T", "protected_omega", "surface_T", "plan_power", "plan_pulses",
                "tail", "max_horizon", "quantiles", "step", "drift"}
#: the most heat steps a forecast may take (its stored rows grow with them)
MAX_STEPS = 5000


@dataclass
class AdviceSpec:
    """The parsed ``[advice]`` table: :class:`~enkf.tissue.advice.Advisor`'s arguments."""

    kw: dict  #: Advisor keywords (target, protected, limits, tail, ...)
    plan: tuple  #: (power W, ((start, end), ...) s)

    def advisor(self, setup):
        """The :class:`~enkf.tissue.advice.Advisor` of this table on ``setup``."""
        from ...tissue.advice import Advisor, Plan

        return Advisor(setup, plan=Plan(*self.plan), seed=setup.seed, **self.kw)


def _num(key, v, **kw):
    return check_number(f"advice.{key}", v, error=ConfigError, **kw)


def _place(table: dict, what: str, G):
    """The target's or the protected tissue's points (n, 3) cm or box (3, 2) cm, or None."""
    given = [k for k in ("depth", "point", "region") if f"{what}_{k}" in table]
    if len(given) > 1:
        raise ConfigError(f"advice: give one of advice.{what}_depth, {what}_point, "
                          f"{what}_region, got {', '.join(f'{what}_{k}' for k in given)}")
    if not given:
        return None
    key = f"{what}_{given[0]}"
    v, half = table[key], (G.Lx / 2, G.Ly / 2)
    if given[0] == "depth":
        return [[0.0, 0.0, _num(key, v, lo=0.0, hi=G.Lz)]]
    if given[0] == "point":
        if not (isinstance(v, list) and len(v) == 3):
            raise ConfigError(f"advice.{key} must be [x, y, z] in cm, got {shorten(repr(v))}")
        p = [_num(f"{key}[{i}]", c) for i, c in enumerate(v)]
        if not (abs(p[0]) <= half[0] and abs(p[1]) <= half[1] and 0 <= p[2] <= G.Lz):
            raise ConfigError(f"advice.{key} = {p} cm is outside the tissue (x, y in "
                              f"[-{half[0]}, {half[0]}], z in [0, {G.Lz}])")
        return [p]
    if not (isinstance(v, list) and len(v) == 3 and all(isinstance(r, list) and len(r) == 2
                                                        for r in v)):
        raise ConfigError(f"advice.{key} must be [[x0, x1], [y0, y1], [z0, z1]] in cm, got "
                          f"{shorten(repr(v))}")
    box = [[_num(f"{key}[{i}][{j}]", c) for j, c in enumerate(r)] for i, r in enumerate(v)]
    limits = ((-half[0], half[0]), (-half[1], half[1]), (0.0, G.Lz))
    for i, ((a, b), (lo, hi)) in enumerate(zip(box, limits, strict=True)):
        if not (lo <= a < b <= hi):
            raise ConfigError(f"advice.{key}[{i}] = {[a, b]} cm must have {lo:g} <= lo < hi <= "
                              f"{hi:g} (the tissue)")
    return box


def _nodes_in(box, G, grid) -> bool:
    """Whether the box holds a node of the filter's ``grid`` (voxels) on the block ``G``."""
    axes = (np.linspace(-G.Lx / 2, G.Lx / 2, grid[0] + 1),
            np.linspace(-G.Ly / 2, G.Ly / 2, grid[1] + 1), np.linspace(0.0, G.Lz, grid[2] + 1))
    return all(np.any((x >= a - 1e-9) & (x <= b + 1e-9)) for x, (a, b) in zip(axes, box, strict=True))


def _plan(table: dict, HS) -> tuple:
    if "plan_power" in table:
        power = _num("plan_power", table["plan_power"], lo=0.0, hi=1e6)
    elif callable(HS.P):
        raise ConfigError("advice.plan_power is needed: HS.P is not a number")
    else:
        power = float(HS.P)
    if "plan_pulses" not in table:
        period = HS.duration_on + HS.duration_off
        return power, tuple((i * period, i * period + HS.duration_on)
                            for i in range(int(HS.n_pulses)))
    v = table["plan_pulses"]
    if not (isinstance(v, list) and all(isinstance(r, list) and len(r) == 2 for r in v)):
        raise ConfigError(f"advice.plan_pulses must be a list of [start, end] in s, got "
                          f"{shorten(repr(v))}")
    pulses = []
    for i, r in enumerate(v):
        a, b = (_num(f"plan_pulses[{i}][{j}]", x, lo=0.0, hi=1e9) for j, x in enumerate(r))
        if not a < b:
            raise ConfigError(f"advice.plan_pulses[{i}] = {[a, b]} must have start < end (s)")
        if pulses and a < pulses[-1][1]:
            raise ConfigError(f"advice.plan_pulses[{i}] = {[a, b]} starts before the pulse "
                              f"before it ends ({pulses[-1][1]:g} s)")
        pulses.append((a, b))
    return power, tuple(pulses)


def advice_settings(table, model, medium: int, grid, setup_kw: dict) -> AdviceSpec | None:
    """``[advice]`` (None when absent), checked against the model (``G``, ``HS``, the
    estimated medium ``medium``) and the filter's ``grid`` and settings."""
    if table is None:
        return None
    table = check_keys("advice", table, ADVICE_KEYS)
    G, HS = model.G, model.HS
    m = G.media[medium]
    if m.E is None or m.A is None or callable(m.E) or callable(m.A) or not m.A > 0:
        raise ConfigError(f"[advice] needs the damage law of the estimated medium: set "
                          f"G.media[{medium}].E (J/mol) and .A (1/s, > 0), got E = "
                          f"{shorten(repr(m.E))}, A = {shorten(repr(m.A))}")
    if setup_kw.get("parameter_model", "random_walk") != "random_walk":
        raise ConfigError(f"[advice] needs filter.parameter_model = \"random_walk\", got "
                          f"{setup_kw['parameter_model']!r}: the forecast does not move the "
                          "optics with each member's damage (coagulation) or with filtered "
                          "rates (trend)")
    target = _place(table, "target", G)
    if target is None:
        raise ConfigError("[advice] needs a target: advice.target_depth, target_point or "
                          "target_region")
    protected = _place(table, "protected", G)
    for what, place in (("target", target), ("protected", protected)):
        if f"{what}_region" in table and not _nodes_in(place, G, grid):
            raise ConfigError(f"advice.{what}_region = {place} cm holds no node of the filter's "
                              f"mesh (filter.grid = {list(grid)}): make it larger")
    T0 = float(HS.T_initial)
    kw = {"E": float(m.E), "A": float(m.A), "target": target, "protected": protected}
    for key in ("protected_T", "surface_T"):
        if key in table:
            kw[key] = _num(key, table[key], hi=1e4)
            if kw[key] <= T0:
                raise ConfigError(f"advice.{key} = {kw[key]:g} deg C is not above the start "
                                  f"temperature (HS.T_initial = {T0:g}): the tissue would pass "
                                  "it before the laser starts")
    if "protected_omega" in table:
        kw["protected_omega"] = _num("protected_omega", table["protected_omega"], lo=0.0,
                                     hi=1e6, lo_open=True)
    if protected is not None and "protected_T" not in kw and "protected_omega" not in kw:
        raise ConfigError("advice: the protected tissue needs a limit: advice.protected_T "
                          "(deg C) and/or advice.protected_omega")
    if protected is None and ("protected_T" in kw or "protected_omega" in kw):
        raise ConfigError("advice.protected_T and protected_omega need the protected tissue: "
                          "advice.protected_depth, protected_point or protected_region")
    kw["tail"] = _num("tail", table.get("tail", 5.0), lo=0.0, hi=1e4)
    kw["max_horizon"] = _num("max_horizon", table.get("max_horizon", 30.0), lo=0.0, hi=1e4,
                             lo_open=True)
    step = table.get("step", setup_kw.get("max_dt") or 0.1)
    kw["step"] = _num("step", step, lo=0.0, hi=1e3, lo_open=True)
    q = table.get("quantiles", [0.05, 0.95])
    if not (isinstance(q, list) and len(q) == 2):
        raise ConfigError(f"advice.quantiles must be [lower, upper], got {shorten(repr(q))}")
    q = [_num(f"quantiles[{i}]", v, lo=0.0, hi=1.0, lo_open=True) for i, v in enumerate(q)]
    if not q[0] < 0.5 < q[1] < 1:
        raise ConfigError(f"advice.quantiles must have 0 < lower < 0.5 < upper < 1, got {q}")
    kw["quantiles"] = tuple(q)
    from ...tissue.advice import DRIFT_FORECASTS

    kw["drift"] = table.get("drift", "walk+trend")
    if kw["drift"] not in DRIFT_FORECASTS:
        raise ConfigError(f"advice.drift must be one of {', '.join(map(repr, DRIFT_FORECASTS))}, "
                          f"got {shorten(repr(kw['drift']))}")
    plan = _plan(table, HS)
    end = plan[1][-1][1] if plan[1] else 0.0
    steps = min(end + kw["tail"], kw["max_horizon"]) / kw["step"]
    if steps > MAX_STEPS:
        raise ConfigError(f"advice.step = {kw['step']:g} s makes {steps:.0f} forecast steps over "
                          f"the horizon (at most {MAX_STEPS}): raise advice.step or lower "
                          "advice.max_horizon")
    return AdviceSpec(kw, plan)
