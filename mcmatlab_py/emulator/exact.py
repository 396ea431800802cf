"""The exact mode of the absorption model: direct Monte Carlo for every member and call
(:class:`DirectMonteCarloAbsorption`), the reference of the emulator."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..distributed import run_tasks
from .spec import EmulatorSpec
from .table import load_operator

__all__ = ["DirectMonteCarloAbsorption", "direct_member"]


@dataclass
class DirectMonteCarloAbsorption:
    """The exact mode: the same call as :class:`AbsorptionEmulator`, by direct Monte Carlo.

    Each call runs one Monte Carlo per member (``spec.n_photons`` photons, seed
    ``spec.seed + call index`` so that successive calls are independent), and projects
    onto the mesh nodes when ``spec.mesh_divisions`` is set.
    """

    spec: EmulatorSpec
    calls: int = 0
    client: object = None  #: a dask.distributed client: one task per member
    exact = True  #: every call runs Monte Carlo (enkf.tissue.absorption.Absorption)

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.spec.field_shape

    @property
    def kind(self) -> str:
        return "NA" if self.spec.mesh_divisions is None else "load"

    @property
    def inverse(self) -> np.ndarray:
        """Identity orbits: ``unique`` returns every entry."""
        return np.arange(int(np.prod(self.shape)))

    def unique(self, mua, mus) -> np.ndarray:
        return self(mua, mus).reshape(np.size(mua), -1)

    def __call__(self, mua, mus) -> np.ndarray:
        mua, mus = np.broadcast_arrays(np.atleast_1d(mua), np.atleast_1d(mus))
        members = [(float(a), float(s)) for a, s in zip(mua.ravel(), mus.ravel(), strict=True)]
        maps = run_tasks(functools.partial(direct_member, self.spec, self.spec.seed + self.calls),
                         members, client=self.client)
        self.calls += 1
        return np.stack(maps)


def direct_member(spec: EmulatorSpec, seed: int, coefficients: tuple[float, float]) -> np.ndarray:
    """NA (or the nodal load) of one member by direct Monte Carlo (a task body)."""
    mua, mus = coefficients
    na = spec.model(mua, mus, seed=seed).run_monte_carlo().MC.NA
    if spec.mesh_divisions is None:
        return na
    return (load_operator(spec) @ na.ravel()).reshape(spec.field_shape)
