"""Time marching: one loop over the steps of a run, recording the probes.

Every heat run of the project (MCmatlab's heat simulation, the paper's sensitivity
study, the identical twin of the filter) is the same loop: step the temperatures
from each time to the next, read the probes, and let the caller do its own work
(damage, snapshots, a progress bar) after each step.  The step itself is the
caller's callable, so the loop serves a plain :class:`fem.HeatStepper` with a
time-dependent load as well as the filter's forward model::

    def step(T, t0, t1):
        power = laser_power(0.5 * (t0 + t1))
        return stepper.step(T, power * f if power else None)

    T, readings = march(step, T0, times, probes=P)
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["march"]


def march(step: Callable, T0, times, probes=None, on_step: Callable | None = None
          ) -> tuple[np.ndarray, np.ndarray | None]:
    """Step temperatures through ``times`` and read the probes at each of them.

    Parameters
    ----------
    step : callable ``step(T, t0, t1) -> T``
        Temperatures (deg C) at ``t1`` from those at ``t0`` (s); the shape of
        ``T0`` is kept.
    T0 : array (npoints,) or (N, npoints)
        deg C, temperatures at ``times[0]``.
    times : array (n_times,)
        s, increasing; ``n_times - 1`` steps are taken.
    probes : sparse or dense matrix (n_probes, npoints), optional
        E.g. :func:`fem.probe_matrix`: the readings are ``probes @ T``.
    on_step : callable ``on_step(k, t1, T_old, T_new)``, optional
        Called after step ``k`` (1, ..., n_times - 1) that ended at ``t1``, with
        the temperatures before and after it (not to be modified).

    Returns
    -------
    T : array, the shape of ``T0``
        deg C, temperatures at ``times[-1]``.
    readings : array (n_times, n_probes) or (n_times, N, n_probes), or None
        deg C, the probes at every time (``times[0]`` included); None without
        ``probes``.
    """
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or times.size < 1 or not np.all(np.isfinite(times)):
        raise ValueError(f"times must be a finite 1-d array (s), got shape {times.shape}")
    if np.any(np.diff(times) <= 0):
        raise ValueError("times must increase")
    T = np.asarray(T0, dtype=float)

    def read(X):
        return (probes @ X.T).T

    readings = [read(T)] if probes is not None else None
    for k in range(1, times.size):
        t0, t1 = float(times[k - 1]), float(times[k])
        T_new = step(T, t0, t1)
        if on_step is not None:
            on_step(k, t1, T, T_new)
        T = T_new
        if readings is not None:
            readings.append(read(T))
    return T, (np.array(readings) if readings is not None else None)
