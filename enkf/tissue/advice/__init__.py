r"""How long to keep the laser on: each member forecast to the target's coagulation.

Every member of the filter carries its optics :math:`\theta_n`, its temperature field
:math:`T_n` and (followed here along its analysed trajectory) its Arrhenius damage
:math:`\Omega_n` at a few points: the **target** (every point of it must reach
:math:`\Omega \ge 1`), the **protected** tissue (none of it may pass its damage or
temperature limit) and the **surface** (its temperature limit). At each reading each
member is forecast under the planned laser schedule and under "laser off now", its optics
carried forward as its filter's parameter model moves them (below); from its forecast come

* the **target time**: when :math:`\min_\text{target}\Omega_n` reaches 1 under the plan
  (``inf``: not within the horizon, the plan's last pulse plus ``tail``);
* the **stop time**: the earliest switch-off (at the end of a forecast step, interpolated
  in :math:`\log\Omega`) after which the target still reaches :math:`\Omega \ge 1` as the
  tissue cools, at or before the target time;
* whether the protected points or the surface pass their limits (so far or within the
  horizon) under the plan, with the laser off now, and with the laser stopped at the
  member's own stop time ("at target": what coagulating the target costs).

Across the members (weighted, for a bank of filters) these are the medians and
quantiles of the times and the probabilities of the risks (:class:`AdviceRow`).

**The optics in the forecast.** A filter whose random walk models still optics (below
``hold_below`` log units a step, the still filter's 0.002) holds each member's optics at
their present values, the walk's expectation. A filter whose optics drift (the drift
bank's drifting filters, or any filter with a larger walk) carries each member's walk on:
over the forecast's heated steps (the walk's own ``random_walk_when_off`` factor for the
others) the member's log optics take the filter's own walk std a step, drawn afresh at
each reading, plus the member's own recent trend: the slope of its log optics against
heated time over the last ``trend_window`` s of heating (a member's track, as the
filter's analyses moved it, tells which way its optics have been going; the members'
trends scatter, and the interval with them, while the filter is still learning)
(:attr:`Advisor.drift`: ``"walk+trend"``, ``"walk"`` or ``"hold"``). The optics only act
through the load while the laser heats, so they are set piecewise constant over
``drift_step`` s of the plan's pulses, at the middle of each piece: the forecast's
temperatures then sum the responses to each piece's load (:func:`~enkf.tissue.
advice.forecast.heat`). Under the bank's weights the still filter's members hold and the
drifting ones drift, so the interval widens with the evidence of a drift.

``parameter_model = "coagulation"`` is refused: its optics follow each member's damage at
every node that absorbs (a light-weighted coagulated fraction), which the few points'
forecast does not carry; stepping every member's whole field over the horizon would take
about the filter's own step a forecast step, far beyond a reading's 100 ms.

Each member's point temperatures come from :class:`~enkf.tissue.advice.forecast.
PointForecast`: the forecast is linear in the state and the absorbed power, so rows
computed once by the adjoint of the heat step (and stored as a low-rank product) turn
any member's state and optics into its temperatures at the points after every step of
the horizon: two small matrix products a reading. The drifting optics' loads (a piece's
optics for each member: up to ten times the members early in a 5 s pulse) take their
product over the nodes in single precision (within about 1e-6 of the largest response,
the times within 1e-6 s of double precision's); after the plan's last pulse no load is
forecast. Members with their own heat capacity and conductivity are stepped forward one
by one instead. The forecast steps as the
filter does (``setup.heat.max_dt``, the readings' 0.1 s by default), with the plan's power
averaged over each step (:meth:`Plan.mean_power`), and the damage is the trapezoid in
the Arrhenius rate over those steps, as :class:`~enkf.tissue.risk.RiskTracker`'s.

The drift bank (``setup.parameters.drift``) runs several filters: the advice mixes their members,
each filter's weight (its probability after the reading) shared evenly by its members,
as the bank's own estimates do; online, a filter below ``min_weight`` is not forecast.

Use it as the callback of :func:`enkf.tissue.identify` (then :meth:`Advisor.table`
with the bank's weights), or after each :meth:`OnlineIdentifier.update` with
:meth:`Advisor.online`.
"""

from .advisor import Advisor, online_ensembles
from .plan import DRIFT_FORECASTS, RISKS, AdviceRow, MemberAdvice, Plan
from .report import advice_line, advice_summary, plot_advice

__all__ = ["DRIFT_FORECASTS", "RISKS", "AdviceRow", "Advisor", "MemberAdvice", "Plan",
           "advice_line", "advice_summary", "online_ensembles", "plot_advice"]
