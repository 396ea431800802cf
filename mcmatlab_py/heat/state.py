"""The state of a heat run at its ends: the start temperature (``HS.T`` set MCmatlab's
way), the heat source, and the results written into ``model.HS``."""

from __future__ import annotations

import numpy as np

from ..geometry.media_bins import state_field
from ..monte_carlo.broadband import total
from .mesh import voxels_to_nodes
from .simulation import T_INITIAL_RANGE, HeatSimulation

__all__ = ["heat_source", "sensor_series", "start_from_T", "store_heat_results"]


def sensor_series(t_start, T0, readings, probes, interval):
    """The sensor times (s) and readings (n, n_sensors) of an error-controlled run.

    Every accepted step's end; with ``interval``, only the steps that end on its multiples
    (the steps land on them) and the run's end.
    """
    t = np.array([t_start] + [r[0] for r in readings])
    n_sensors = 0 if probes is None else probes.shape[0]
    v = np.empty((t.size, n_sensors))
    if n_sensors:
        v[0] = probes @ T0
        for i, (_, r) in enumerate(readings):
            v[i + 1] = r
    if interval is None:
        return t, v
    k = (t - t_start) / interval
    keep = np.abs(k - np.round(k)) < 1e-6
    keep[-1] = True
    return t[keep], v[keep]


def start_from_T(HS, G, S, chained) -> np.ndarray | None:
    """(npoints,) deg C: the start temperature given as ``HS.T``, MCmatlab's way, or None.

    MCmatlab's ``HS.T`` is both the start temperature (a number or (nx, ny, nz) on the
    voxels; this port also takes (nx+1, ny+1, nz+1) on the nodes of the default mesh, the
    shape of its own ``HS.T``) and the result. ``HS.T`` is taken as set by the user when no
    run has filled it, or when it no longer holds the last run's nodal field (a chained run
    then continues from it, with the damage and clock of the previous run, as MCmatlab's).
    Before a first run, ``HS.T_initial`` is set to it (so that ``HS.reset()`` and the
    figures' rise above ``T_initial`` agree); a ``T_initial`` of its own that differs raises.
    """
    T = HS.T
    if T is None:
        return None
    node_shape = tuple(n + 1 for n in S.mesh_grid.shape)
    is_nodal = np.shape(T) == node_shape and np.shape(T) != (G.nx, G.ny, G.nz)
    if chained and is_nodal and HS.T_nodes is not None \
            and np.array_equal(np.asarray(T, dtype=float).ravel(), HS.T_nodes):
        return None  # the previous run's result: chain from it
    lo, hi = T_INITIAL_RANGE
    if is_nodal:
        value = state_field("HS.T", T, node_shape, lower=lo, upper=hi)
        T0 = np.asarray(value, dtype=float).ravel().copy()
        voxel_value = S.to_voxels(T0)
    else:
        value = state_field("HS.T", T, (G.nx, G.ny, G.nz), lower=lo, upper=hi)
        T0, voxel_value = voxels_to_nodes(S.L, value), value
    if not chained:
        default = HeatSimulation.__dataclass_fields__["T_initial"].default
        own = HS.T_initial
        if not (np.ndim(own) == 0 and own == default):
            # both are numbers or (nx, ny, nz) arrays here (HS.validate ran): they broadcast
            if is_nodal or not np.all(np.asarray(own) == np.asarray(value)):
                raise ValueError(f"HS.T = {_short(T)} and HS.T_initial = {_short(own)} both give "
                                 "the start temperature and differ: set HS.T_initial only (or "
                                 "HS.T = None), or MCmatlab's HS.T with HS.T_initial left at "
                                 f"{default}")
        HS.T_initial = voxel_value
    return T0


def _short(v) -> str:
    if np.ndim(v) == 0:
        return repr(v)
    a = np.asarray(v)
    return f"array of shape {a.shape}" + (f" ({a.min():g}..{a.max():g})" if a.size and
                                           np.issubdtype(a.dtype, np.number) else "")


def heat_source(model) -> np.ndarray:
    """(nx, ny, nz) power turned into heat per W incident, W/cm^3/W: ``MC.NA``, and with a
    fluorescence run (``FMC.NA`` set) minus the fluorescence emitted plus the fluorescence
    absorbed (MCmatlab's ``calcdTdtArrays``): the energy re-emitted as light leaves the
    voxel, and heats where it is absorbed."""
    MC, FMC = model.MC, model.FMC
    NA = total(MC.NA)  # broadband runs heat with the sum over their wavelengths, as MCmatlab
    if FMC.NA is None:
        return NA
    if np.shape(FMC.NA)[:3] != np.shape(NA):
        raise ValueError(f"FMC holds a run on another grid ({np.shape(FMC.NA)}, MC.NA "
                         f"{np.shape(MC.NA)}): run model.run_monte_carlo('fluorescence') again, "
                         "or set model.FMC = FluorescenceMonteCarloSimulation()")
    return NA - total(FMC.source_distribution) + total(FMC.NA)


def store_heat_results(HS, S, T, Omega, times, sensor, chained, coupling) -> None:
    n_sensors = len(HS.temp_sensor_positions)
    sensor = sensor if sensor is not None else np.empty((len(times), 0))
    if chained and HS.sensor_times is not None and HS.sensor_temps.shape[1] == n_sensors:
        HS.sensor_times = np.concatenate([HS.sensor_times[:-1], times])
        HS.sensor_temps = np.concatenate([HS.sensor_temps[:-1], sensor])
    else:
        HS.sensor_times, HS.sensor_temps = times, sensor
    HS.mesh = S.mesh
    HS.T_nodes = T
    shape = tuple(n + 1 for n in S.mesh_grid.shape)
    HS.T = T.reshape(shape)
    HS.Omega = Omega.reshape(shape)
    HS.T_voxels = S.to_voxels(T)
    HS.media_properties, HS.M = coupling.thermal, coupling.thermal.M
