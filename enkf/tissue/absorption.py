"""The absorption model the filter calls: one protocol for the emulator and the exact mode.

:class:`Absorption` is what :class:`~enkf.tissue.forward.TissueForwardModel` needs from
an absorption model; :class:`mcmatlab_py.emulator.AbsorptionEmulator` (interpolation in
a Monte Carlo table) and :class:`mcmatlab_py.emulator.DirectMonteCarloAbsorption` (one
Monte Carlo per member, the exact reference) implement it, and :func:`as_absorption`
wraps a plain function ``NA(mua, mus)`` (a stand-in in tests and studies).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["Absorption", "FunctionAbsorption", "as_absorption", "fill_prior_points"]


@runtime_checkable
class Absorption(Protocol):
    """Absorbed power per W incident as a function of the optics, for a batch of members.

    Attributes
    ----------
    kind : {"NA", "load"}
        ``"NA"``: values on the voxels (W/cm^3/W); ``"load"``: P1 nodal loads (W/W).
    shape : tuple of int
        The voxel grid ``(nx, ny, nz)`` or the node grid ``(mx+1, my+1, mz+1)``.
    inverse : ndarray of int, shape (prod(shape),)
        Index into :meth:`unique`'s columns of each voxel or node (symmetry orbits).
    exact : bool
        True when a call runs Monte Carlo (costly: no call without need).
    """

    kind: str
    shape: tuple
    inverse: np.ndarray
    exact: bool

    def unique(self, mua, mus) -> np.ndarray:
        """(N, n_unique) values at the orbit representatives, ``mua``, ``mus`` (N,) cm^-1."""

    def __call__(self, mua, mus) -> np.ndarray:
        """(N, *shape) values, ``mua``, ``mus`` (N,) cm^-1."""


@dataclass
class FunctionAbsorption:
    """A plain ``NA(mua (N,), mus (N,)) -> (N, nx, ny, nz)`` as an :class:`Absorption`."""

    function: Callable
    shape: tuple
    kind: str = "NA"
    exact: bool = False
    inverse: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        self.shape = tuple(int(n) for n in self.shape)
        self.inverse = np.arange(int(np.prod(self.shape)))

    def unique(self, mua, mus) -> np.ndarray:
        return np.asarray(self(mua, mus)).reshape(np.size(mua), -1)

    def __call__(self, mua, mus) -> np.ndarray:
        return self.function(mua, mus)


def as_absorption(absorption, voxel_shape: tuple) -> Absorption:
    """``absorption`` itself when it implements :class:`Absorption`, else a plain function
    of ``(mua, mus)`` on the voxels of ``voxel_shape`` wrapped in :class:`FunctionAbsorption`."""
    if isinstance(absorption, Absorption):
        return absorption
    if not callable(absorption):
        raise ValueError(f"absorption must be an Absorption or a function NA(mua, mus), "
                         f"got {type(absorption).__name__}")
    return FunctionAbsorption(absorption, voxel_shape)


def fill_prior_points(setup) -> None:
    """Before the filter starts: with an emulator built on demand
    (:meth:`mcmatlab_py.emulator.AbsorptionEmulator.fill`), run the table points that the
    prior's optics read (the first step would wait for them otherwise), so the filter's
    own time and progress are its own. ``setup``: a :class:`~enkf.tissue.TissueFilterSetup`.
    Anything else as absorption: nothing to do."""
    emu = setup.absorption
    if getattr(emu, "complete", True) or not hasattr(emu, "needed_box"):
        return
    lo, hi = setup.parameters.prior_bounds()
    names = setup.parameters.names
    box = []
    for name, (t_lo, t_hi) in (("mua", emu.spec.mua_range), ("mus", emu.spec.mus_range)):
        idx = [i for i, n in enumerate(names) if n in (name, f"{name}_coag")]
        if idx:  # damage-driven optics lie between the native and coagulated values
            b_lo, b_hi = min(lo[i] for i in idx), max(hi[i] for i in idx)
        else:
            b_lo = b_hi = float(setup.parameters.nominal[name])
        box.append((float(np.clip(b_lo, t_lo, t_hi)), float(np.clip(b_hi, t_lo, t_hi))))
    emu.fill(emu.needed_box(*box))
