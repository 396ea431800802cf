"""Constant optics from a whole window of readings: the ES-MDA smoother (:mod:`enkf.smoother`).

:func:`identify` is the online filter: one linear update per reading. Where the optics
are constant over the window (no drift, no coagulation) the whole window can be
analysed at once, as often as wanted afterwards: :func:`smooth_constant` starts from
the same prior ensemble as the filter and runs ES-MDA over all the readings, each
member's temperatures re-run from ``T_initial`` with its own optics for every update.
On the layered twin (``docs/layered.md``) it brings the error of the dermis's mus from
1.9 times the Cramér-Rao bound (the filter) to about the bound.

What it assumes: constant parameters and the filter's coarse model without model
error (the smoother has no model noise). On data from another model its bands are
those of a perfect model: read them as the noise's share only (the filter's structured
model error is the honest one there).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..checks import float_array
from ..smoother import es_mda
from .identify import assemble
from .setup import TissueFilterSetup

__all__ = ["SmootherEstimates", "smooth_constant"]


@dataclass
class SmootherEstimates:
    """The parameter ensemble after ES-MDA.

    ``names`` (n_par,); ``theta`` (N, n_par) physical units (cm^-1 for mua and mus, the
    setup's units for VHC and TC); ``n_iter`` updates; ``wall_s`` s.
    """

    names: tuple
    theta: np.ndarray
    n_iter: int
    wall_s: float

    @property
    def mean(self) -> np.ndarray:
        """(n_par,) the ensemble mean."""
        return self.theta.mean(axis=0)

    @property
    def std(self) -> np.ndarray:
        """(n_par,) the ensemble standard deviation."""
        return self.theta.std(axis=0, ddof=1)

    def band(self, i: int, q: float = 0.02275) -> tuple[float, float]:
        """The ``q`` and ``1 - q`` quantiles of parameter ``i`` (default: +-2 sd of a
        normal; positive like the members)."""
        return (float(np.quantile(self.theta[:, i], q)),
                float(np.quantile(self.theta[:, i], 1 - q)))


def smooth_constant(setup: TissueFilterSetup, times, data, *, n_iter: int = 4,
                    seed: int | None = None) -> SmootherEstimates:
    """Constant optics from all the readings at once (module doc).

    Parameters
    ----------
    setup : the filter's setup; ``parameter_model = "random_walk"`` (its walk is ignored:
        the parameters are constant), no sensor offsets, no coagulation
    times : (M,) s after 0, strictly increasing
    data : (M, p) deg C as for :func:`identify`; NaN readings are left out
    n_iter : ES-MDA updates (each re-runs the ensemble over the window)
    seed : the generator of the prior and the perturbations (default ``setup.seed``)

    The update is ``setup.method``'s (:func:`enkf.smoother.es_mda`: ``"etkf"``, the
    default, without perturbed observations).
    """
    if setup.parameter_model != "random_walk":
        raise ValueError(f"smooth_constant needs constant parameters (parameter_model = "
                         f"'random_walk'), got {setup.parameter_model!r}")
    if setup.n_sensor_offsets:
        raise ValueError("smooth_constant does not estimate sensor offsets: set "
                         "sensor_offset_std = 0")
    times = float_array(times, "times", 1)
    if times.size == 0 or times[0] <= 0 or np.any(np.diff(times) <= 0):
        raise ValueError("times must be strictly increasing and after 0 (s)")
    pieces = assemble(setup, warm_dt=float(times[0]))
    data = float_array(data, "data", 2, finite=False)
    if data.shape != (times.size, pieces.P_obs.shape[0]):
        raise ValueError(f"data must have shape {(times.size, pieces.P_obs.shape[0])} "
                         f"(readings x sensors and pixels), got {data.shape}")
    keep = np.isfinite(data).ravel()
    if not keep.any():
        raise ValueError("data has no finite reading")
    rng = np.random.default_rng([setup.seed if seed is None else seed, 20240605])
    X0, theta0 = pieces.prior(rng, setup.n_members)
    model, P = pieces.model, pieces.P_obs
    edges = np.r_[0.0, times]

    def simulate(U: np.ndarray) -> np.ndarray:
        theta = np.exp(U)
        T = X0.copy()
        out = np.empty((U.shape[0], times.size, P.shape[0]))
        for k in range(times.size):
            T = model(T, theta, float(edges[k]), float(edges[k + 1]))
            out[:, k] = (P @ T.T).T
        return out.reshape(U.shape[0], -1)[:, keep]

    R = np.tile(np.asarray(pieces.noise_var, float), times.size)[keep]
    tic = time.perf_counter()
    U = es_mda(simulate, np.log(theta0), data.ravel()[keep], R, rng, n_iter=n_iter,
               method=setup.method)
    return SmootherEstimates(tuple(setup.parameter_names), np.exp(U), int(n_iter),
                             time.perf_counter() - tic)
