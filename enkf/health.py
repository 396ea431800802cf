"""The filter's health check: stop a run whose ensemble is no longer meaningful."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import float_array, variances

__all__ = ["HealthCheck"]


@dataclass(frozen=True)
class HealthCheck:
    """The default health check, called after every step with ``(E_state, theta)``.

    Non-finite values anywhere in the ensemble always fail. Optional checks:

    Parameters
    ----------
    param_bounds : ndarray, shape (n_par, 2), optional
        ``[lo, hi]`` per parameter in physical units; fails when an ensemble
        *mean* leaves the interval (single members may wander; the mean is the
        estimate). Use ``-inf``/``inf`` for an open side.
    min_param_std : float or ndarray, shape (n_par,), optional
        Fails when a parameter's ensemble std (physical units) falls below it:
        a collapsed ensemble no longer learns from data.
    state_bounds : (lo, hi), optional
        Fails when the ensemble mean of any state component leaves ``[lo, hi]``: a
        physical range of the state (e.g. temperatures) that no real run leaves, so a
        state that runs away (a compounding inflation, an unstable model) stops the
        run instead of being reported.

    Any callable ``health(E_state, theta) -> str | None`` can replace this class in
    :func:`run_filter`; a returned string describes the failure.
    """

    param_bounds: np.ndarray | None = None
    min_param_std: float | np.ndarray | None = None
    state_bounds: tuple[float, float] | None = None

    def __post_init__(self):
        if self.param_bounds is not None:
            b = float_array(self.param_bounds, "param_bounds", 2, finite=False)
            if b.shape[1] != 2 or np.any(np.isnan(b)) or np.any(b[:, 0] >= b[:, 1]):
                raise ValueError(f"param_bounds must be (n_par, 2) with lo < hi, got {b!r}")
            object.__setattr__(self, "param_bounds", b)
        if self.min_param_std is not None:
            object.__setattr__(self, "min_param_std", variances(self.min_param_std, "min_param_std"))
        if self.state_bounds is not None:
            b = float_array(self.state_bounds, "state_bounds", 1, finite=False)
            if b.shape != (2,) or np.any(np.isnan(b)) or b[0] >= b[1]:
                raise ValueError(f"state_bounds must be (lo, hi) with lo < hi, got "
                                 f"{self.state_bounds!r}")
            object.__setattr__(self, "state_bounds", (float(b[0]), float(b[1])))

    def __call__(self, E_state: np.ndarray, theta: np.ndarray) -> str | None:
        for name, X in (("state", E_state), ("parameter", theta)):
            bad = ~np.isfinite(X)
            if bad.any():
                cols = np.flatnonzero(bad.any(axis=0))
                return (
                    f"non-finite {name} values in {bad.any(axis=1).sum()} member(s), "
                    f"{name} columns {cols[:10].tolist()}{'...' if cols.size > 10 else ''}"
                )
        if self.param_bounds is not None:
            if self.param_bounds.shape[0] != theta.shape[1]:
                raise ValueError(
                    f"param_bounds must have {theta.shape[1]} rows, got {self.param_bounds.shape[0]}"
                )
            m = theta.mean(axis=0)
            out = (m < self.param_bounds[:, 0]) | (m > self.param_bounds[:, 1])
            if out.any():
                i = int(np.flatnonzero(out)[0])
                return (
                    f"parameter {i} mean {m[i]:.6g} outside bounds "
                    f"[{self.param_bounds[i, 0]:.6g}, {self.param_bounds[i, 1]:.6g}]"
                )
        if self.state_bounds is not None and E_state.shape[1]:
            m = E_state.mean(axis=0)
            lo, hi = self.state_bounds
            out = (m < lo) | (m > hi)
            if out.any():
                j = int(np.flatnonzero(out)[0])
                return (f"state column {j} mean {m[j]:.6g} outside bounds [{lo:.6g}, {hi:.6g}] "
                        f"({int(out.sum())} column(s))")
        if self.min_param_std is not None and theta.shape[1]:
            s = theta.std(axis=0, ddof=1)
            low = s < np.broadcast_to(self.min_param_std, s.shape)
            if low.any():
                i = int(np.flatnonzero(low)[0])
                return (
                    f"parameter {i} spread collapsed: std {s[i]:.3g} < "
                    f"{np.broadcast_to(self.min_param_std, s.shape)[i]:.3g}"
                )
        return None
