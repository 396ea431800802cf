"""The paper's sensitivity study: the sensor temperature against mua and mus."""

from __future__ import annotations

import functools

import numpy as np

import fem
from mcmatlab_py.distributed import run_tasks

from .scenarios import TABLE, paper_model

__all__ = ["sensitivity_study"]

def _sensitivity_na(grid, n_photons: int, seed: int,
                    coefficients: tuple[float, float]) -> np.ndarray:
    """NA of one sensitivity case (a task body: the same seed on any worker)."""
    m = paper_model(grid, n_photons=n_photons, seed=seed, progress=False)
    m.G.media[0].mua, m.G.media[0].mus = coefficients
    return m.run_monte_carlo().MC.NA


def sensitivity_study(grid=(100, 100, 50), n_photons: int = 10**6, *, progress=True,
                      mua_values=(1.0, 2.0, 3.0, 4.0, 5.0),
                      mus_values=(100.0, 200.0, 300.0, 400.0, 500.0), client=None,
                      seed: int = 1) -> dict:
    """The paper's sensitivity study (its Fig. "sens"): sensor temperature against mua and mus.

    One Monte Carlo per case on ``grid`` (mus fixed at 100 while mua varies, mua at 1
    while mus varies; one task per case on ``client``, a ``dask.distributed`` client, when
    given; every case's Monte Carlo with ``seed``), then all cases stepped together as one
    batch of heat fields.

    Returns ``{"times": (n,), "mua": {value: (n,)}, "mus": {value: (n,)}}`` (deg C).
    """
    base = paper_model(grid, n_photons=n_photons, progress=False)
    HS = base.HS
    cases = [("mua", v, v, TABLE["mus"]) for v in mua_values]
    cases += [("mus", v, TABLE["mua"], v) for v in mus_values]
    g = fem.BoxGrid(*grid, 0.5, 0.5, 0.25)
    mesh = g.mesh()
    L = fem.voxel_load_matrix(mesh, g)
    maps = run_tasks(functools.partial(_sensitivity_na, tuple(grid), n_photons, seed),
                     [(mua, mus) for _, _, mua, mus in cases], client=client,
                     progress=progress, label="sensitivity: Monte Carlo")
    loads = np.array([L @ na.ravel() for na in maps])
    stepper = fem.HeatStepper(mesh, TABLE["VHC"], TABLE["TC"], HS.dt)
    probe = fem.probe_matrix(mesh, np.zeros((3, 1)))
    times = np.r_[0.0, HS.step_times()]

    def step(T, t0, t1):
        power = HS.laser_power(t1 - 0.5 * HS.dt)
        return stepper.step(T, power * loads if power else None)

    _, readings = fem.march(step, np.zeros((len(cases), mesh.p.shape[1])), times, probe)
    out = readings[:, :, 0]  # (n_times, n_cases)
    res = {"times": times, "mua": {}, "mus": {}}
    for i, (which, v, _, _) in enumerate(cases):
        res[which][v] = out[:, i]
    return res
