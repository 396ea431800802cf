"""The heat simulation (MCmatlab's ``model.HS``): settings and schedule
(:mod:`~mcmatlab_py.heat.simulation`), the time loop (:mod:`~mcmatlab_py.heat.run`) on the
mesh of :mod:`~mcmatlab_py.heat.mesh`, error-controlled steps
(:mod:`~mcmatlab_py.heat.steps`) and the refusal of runs that cannot fit
(:mod:`~mcmatlab_py.heat.budget`)."""

from .budget import check_heat
from .run import BOILING_WARNING_C, run_heat, simulate_heat_distribution
from .simulation import T_INITIAL_RANGE, HeatSimulation, Schedule, auto_dt
from .state import heat_source

__all__ = ["BOILING_WARNING_C", "T_INITIAL_RANGE", "HeatSimulation", "Schedule", "auto_dt",
           "check_heat", "heat_source", "run_heat", "simulate_heat_distribution"]
