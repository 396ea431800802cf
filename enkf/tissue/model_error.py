r"""A model error shaped like the coarse heat model's real discrepancy.

The filter's forecast (emulator absorption on a 20 x 20 x 10 FEM heat model) differs
from any real tissue, and from any other model of it, by errors that are not white:
a wrong absorbed-power profile or conduction near the beam is wrong at every step
while the laser is on, more so where the heating and the gradients are, and it is
wrong in a smooth way over depth. A white noise of 0.002 deg C per step spreads the
ensemble by a few thousandths of a degree where the real error is tenths
(issue #18: coverage 0.2-0.5 at depth).

:class:`StructuredModelError` perturbs each member's *tendency* of the step (the
stochastically perturbed parametrization tendencies of Buizza, Miller & Palmer 1999,
SPPT), plus a small white floor:

.. math::

    v^n = r^n(\mathbf{x}, t)\,\big(\mathcal{F}(x^n) - x^n\big) + \sigma_0\,\eta^n,
    \qquad r^n_{k+1} = \phi\,r^n_k + \sqrt{1-\phi^2}\,\sigma_r\,\zeta^n_{k+1},
    \quad \phi = e^{-\Delta t/\tau},

where :math:`\zeta` is a Gaussian random field on the mesh nodes with a separable
squared-exponential correlation (lengths ``length_xy`` across and ``length_z`` down),
drawn as :math:`(L_x\otimes L_y\otimes L_z)\,\xi` from the Cholesky factors of the
three 1-D correlation matrices. The error is therefore proportional to what the step
does (zero where nothing happens, largest in the heated zone; during cooling it
follows the diffusion, which is largest where the gradients are), correlated over
depth and persistent over ``time_scale`` seconds, so it accumulates over a pulse as a
real model bias does.

Sizing (``validation/reports/model_error_coverage.md``): the filter's model at the true
optics against two independent models (another Monte Carlo estimator, other grids,
another heat solver, a cylinder for the box) differs by 2-5 % of the temperature rise
at 0-0.2 cm, persistently over the pulse; against the 100 x 100 x 50 fine grid of the
same Monte Carlo by 0.1 % (``coarse_model_error.md``); the emulator's interpolation
and photon noise add 1-3 % (``emulator_accuracy.md``). ``rel_std = 0.05`` with a 3 s
time scale gives a spread of about 5 % of the rise over a 5 s pulse. The adaptive
inflation (:mod:`enkf.adaptive`) then rescales the forecast spread to what the
innovations show.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..random import standard_normal
from ._kernels import sppt_step

__all__ = ["StructuredModelError", "squared_exponential_root"]


def squared_exponential_root(x: np.ndarray, length: float) -> np.ndarray:
    """Lower Cholesky factor (n, n) of the correlation ``exp(-(dx/length)^2 / 2)`` of the
    points ``x`` (n,), with a small jitter; the identity for ``length == 0``."""
    x = np.asarray(x, float)
    if length <= 0:
        return np.eye(x.size)
    C = np.exp(-0.5 * ((x[:, None] - x[None, :]) / length) ** 2)
    return np.linalg.cholesky(C + 1e-8 * np.eye(x.size))


@dataclass
class StructuredModelError:
    """Tendency-proportional, space- and time-correlated model error (SPPT) on a node grid.

    Parameters
    ----------
    nodes_x, nodes_y, nodes_z : ndarray
        cm, the coordinates of the node grid along each axis; the state is the node
        values in C order of ``(len(nodes_x), len(nodes_y), len(nodes_z))``.
    rel_std : float
        :math:`\\sigma_r`, standard deviation of the relative error of a step's tendency.
    time_scale : float
        :math:`\\tau` (s), correlation time of the relative error (0: white in time).
    length_xy, length_z : float
        cm, correlation lengths of the relative error across and down (0: white).
    floor_std : float
        :math:`\\sigma_0`, deg C per step, white additive noise on every node.
    extra_rel_std : callable, optional
        ``extra_rel_std(theta, t0) -> (N,)``: a member's own addition to ``rel_std`` at the
        start ``t0`` (s) of a step, from its parameters ``theta`` (N, n_par) in physical
        units; e.g. the damage-driven optics' mean-field error, which grows with each
        member's coagulated fraction (:class:`enkf.tissue.Coagulation`).
    """

    nodes_x: np.ndarray
    nodes_y: np.ndarray
    nodes_z: np.ndarray
    rel_std: float = 0.05
    time_scale: float = 3.0
    length_xy: float = 0.1
    length_z: float = 0.05
    floor_std: float = 0.002
    extra_rel_std: Callable | None = None

    def __post_init__(self):
        for name in ("rel_std", "time_scale", "length_xy", "length_z", "floor_std"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        self.roots = [squared_exponential_root(self.nodes_x, self.length_xy),
                      squared_exponential_root(self.nodes_y, self.length_xy),
                      squared_exponential_root(self.nodes_z, self.length_z)]
        self.shape = tuple(r.shape[0] for r in self.roots)
        self.reset()

    def reset(self) -> None:
        """Forget the relative errors (a new run)."""
        self._r: np.ndarray | None = None
        self._t: float | None = None

    def field(self, rng: np.random.Generator, N: int) -> np.ndarray:
        """(N, n_nodes) unit-variance correlated Gaussian fields."""
        Lx, Ly, Lz = self.roots
        nx, ny, nz = self.shape
        xi = standard_normal(rng, (N, *self.shape))
        # (L_x (x) L_y (x) L_z) xi one axis at a time, each a single matrix product
        a = (xi.reshape(-1, nz) @ Lz.T).reshape(N, nx, ny, nz)
        a = np.tensordot(Ly, a, axes=(1, 2))  # (y, N, x, z)
        a = np.tensordot(Lx, a, axes=(1, 2))  # (x, y, N, z)
        return np.ascontiguousarray(a.transpose(2, 0, 1, 3)).reshape(N, -1)

    def __call__(self, rng: np.random.Generator, X0: np.ndarray, X1: np.ndarray, theta,
                 t0: float, t1: float) -> np.ndarray:
        """The model noise ``v`` (N, n_nodes) deg C of the step ``X0 -> X1`` from ``t0`` to
        ``t1`` (s) (the ``model_noise`` callable of :class:`enkf.FilterProblem`)."""
        N = X0.shape[0]
        fresh = self._r is None or self._r.shape[0] != N or self._t is None or t0 < self._t - 1e-9
        rel = np.full(N, float(self.rel_std))
        if self.extra_rel_std is not None:
            extra = np.asarray(self.extra_rel_std(theta, t0), float)
            if extra.shape != (N,) or not np.all(np.isfinite(extra) & (extra >= 0)):
                raise ValueError(f"extra_rel_std must return {N} finite numbers >= 0, got "
                                 f"shape {extra.shape}")
            rel = rel + extra
        if not np.any(rel > 0):
            return (self.floor_std * standard_normal(rng, X1.shape) if self.floor_std > 0
                    else np.zeros(X1.shape))
        field = self.field(rng, N)
        if fresh:
            r, phi, scale = field, 0.0, 1.0
        else:
            phi = np.exp(-(t1 - t0) / self.time_scale) if self.time_scale > 0 else 0.0
            r, scale = self._r, np.sqrt(1 - phi * phi)
        v = np.empty(X1.shape)
        eta = standard_normal(rng, X1.shape) if self.floor_std > 0 else v  # v: not read
        sppt_step(r, field, phi, scale, rel, X0, X1, float(self.floor_std), eta, v)
        self._r, self._t = r, t1
        return v
