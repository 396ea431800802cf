r"""Parameter transforms: the filter works on :math:`u = g(\theta)`, the user on :math:`\theta`.

The Kalman update is linear and Gaussian in the filter variables, so a positive
quantity (absorption, scattering, heat capacity, conductivity) can be pushed
negative by an update or by the random walk of Arnold & Fichera (their eq. for
:math:`\theta_{j+1\mid j}`). Filtering :math:`u = \log\theta` keeps every
member positive, turns the random-walk variance into a *relative* step size
(:math:`\sigma_u = 0.05` is about 5 % per step) and matches the usual lognormal
description of optical properties. :class:`LogitTransform` does the same for a
parameter confined to an interval.

The filter state holds transformed parameters. Statistics that are reported
(mean, standard deviation) are computed from the back-transformed ensemble
:math:`\theta_n = g^{-1}(u_n)`, never by transforming the filter mean (which
would give the median of a lognormal, not its mean).

Each transform is a small frozen dataclass with vectorised ``forward``
(:math:`\theta \to u`) and ``inverse`` (:math:`u \to \theta`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from scipy.special import expit

__all__ = [
    "IdentityTransform",
    "LogTransform",
    "LogitTransform",
    "Transform",
    "as_transforms",
    "to_filter_space",
    "to_physical",
]


@runtime_checkable
class Transform(Protocol):
    """What the driver needs from a transform: ``forward`` and ``inverse``."""

    def forward(self, theta: np.ndarray) -> np.ndarray: ...

    def inverse(self, u: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class IdentityTransform:
    """:math:`u = \\theta` (parameters that may take any sign)."""

    def forward(self, theta: np.ndarray) -> np.ndarray:
        return np.asarray(theta, dtype=float)

    def inverse(self, u: np.ndarray) -> np.ndarray:
        return np.asarray(u, dtype=float)


@dataclass(frozen=True)
class LogTransform:
    r""":math:`u = \log\theta`, :math:`\theta = e^{u} > 0`."""

    def forward(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        if np.any(~(theta > 0)):
            raise ValueError(f"theta must be positive for LogTransform, got min {np.min(theta)!r}")
        return np.log(theta)

    def inverse(self, u: np.ndarray) -> np.ndarray:
        # exp underflows to 0 below u ~ -745; the smallest normal double keeps theta > 0
        # (and forward(inverse(u)) finite). Overflow to inf is left to the health check.
        with np.errstate(over="ignore"):
            return np.maximum(np.exp(np.asarray(u, dtype=float)), np.finfo(float).tiny)


@dataclass(frozen=True)
class LogitTransform:
    r"""Logit: :math:`u = \log\frac{\theta - a}{b - \theta}`,
    :math:`\theta = a + (b - a)\,\sigma(u) \in (a, b)`.

    Parameters
    ----------
    lo, hi : float
        The open interval :math:`(a, b)`, in the parameter's physical unit.
    """

    lo: float
    hi: float

    def __post_init__(self):
        if not (np.isfinite(self.lo) and np.isfinite(self.hi)):
            raise ValueError(f"lo and hi must be finite, got lo={self.lo!r}, hi={self.hi!r}")
        if not self.lo < self.hi:
            raise ValueError(f"hi must exceed lo, got lo={self.lo!r}, hi={self.hi!r}")

    def forward(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        if np.any(~((theta > self.lo) & (theta < self.hi))):
            raise ValueError(
                f"theta must lie in ({self.lo}, {self.hi}) for LogitTransform, "
                f"got range [{np.min(theta)!r}, {np.max(theta)!r}]"
            )
        # log(x - lo) - log(hi - x) keeps precision near either end.
        return np.log(theta - self.lo) - np.log(self.hi - theta)

    def inverse(self, u: np.ndarray) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        s = expit(u)
        theta = self.lo + (self.hi - self.lo) * s
        # Rounding can land exactly on an end point; stay inside the open interval.
        return np.clip(theta, np.nextafter(self.lo, self.hi), np.nextafter(self.hi, self.lo))


def as_transforms(transforms: Transform | Sequence[Transform], n_par: int) -> tuple:
    """One transform per parameter: a single transform is repeated ``n_par`` times."""
    if isinstance(transforms, Transform):
        return (transforms,) * n_par
    transforms = tuple(transforms)
    if len(transforms) != n_par:
        raise ValueError(f"transforms must be one transform or {n_par} of them, got {len(transforms)}")
    for i, tr in enumerate(transforms):
        if not isinstance(tr, Transform):
            raise ValueError(f"transforms[{i}] must have forward() and inverse(), got {tr!r}")
    return transforms


def to_filter_space(transforms: Sequence[Transform], theta: np.ndarray) -> np.ndarray:
    """Columns of ``theta`` ``(N, n_par)`` (physical units) mapped to the filter variables."""
    theta = np.asarray(theta, dtype=float)
    out = np.empty_like(theta)
    for i, tr in enumerate(transforms):
        out[:, i] = tr.forward(theta[:, i])
    return out


def to_physical(transforms: Sequence[Transform], u: np.ndarray) -> np.ndarray:
    """Columns of ``u`` ``(N, n_par)`` (filter variables) mapped back to physical units."""
    u = np.asarray(u, dtype=float)
    out = np.empty_like(u)
    for i, tr in enumerate(transforms):
        out[:, i] = tr.inverse(u[:, i])
    return out
