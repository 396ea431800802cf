"""Heat simulation front end (MCmatlab's ``model.HS``): filled in by the heat issue."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class HeatSimulation:
    """Heat simulation settings and results (MCmatlab's ``model.HS``)."""

    P: float = 1.0  #: W, laser power (or a callable P(t))
    duration_on: float = 0.1  #: s
    duration_off: float = 0.0  #: s
    n_pulses: int = 1
    dt: float = 0.01  #: s
    T_initial: float = 37.0  #: deg C
    heat_boundary_type: int = 0
    temp_sensor_positions: list = field(default_factory=list)


def simulate_heat_distribution(model) -> None:
    raise NotImplementedError("heat simulation is not available yet")
