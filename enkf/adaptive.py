r"""Adaptive multiplicative inflation estimated from the innovations.

A filter whose model is not the truth's model is over-confident: its forecast spread
misses the model error. The innovations ``d = y - ȳ`` say by how much. For a linear
observation of a forecast whose covariance is :math:`\rho` times the ensemble's,

.. math::

    \mathbb{E}\,[\tilde d^\mathsf{T}\tilde d] = \rho\,\operatorname{tr}(\tilde H P \tilde H^\mathsf{T}) + p,
    \qquad \tilde d = L^{-1} d,\quad \tilde H P \tilde H^\mathsf{T} = S^\mathsf{T}S/(N-1),

(Desroziers et al. 2005, their eq. for :math:`d^o_b`; Li, Kalnay & Miyoshi 2009), with
:math:`R = LL^\mathsf{T}` and the whitened forecast anomalies :math:`S` of
:mod:`enkf.analysis`. One step gives the estimate
:math:`\rho^o = (\tilde d^\mathsf{T}\tilde d - p)/\operatorname{tr}(\tilde HP\tilde H^\mathsf{T})`,
which for a single sensor is a :math:`\chi^2_1` draw: far too noisy to use alone.
Miyoshi (2011) smooths it with a Gaussian prior that persists from step to step; with
few observations per step his gain is tiny and the factor hardly moves. We use the
time average of Li et al. (2009) instead, with exponential forgetting over
``time_scale`` analysed steps and a prior worth ``prior_steps`` steps at ``initial``:

.. math::

    \rho_k = \operatorname{clip}\Big(
        \frac{\sum_{j\le k}\gamma^{k-j}(\tilde d_j^\mathsf{T}\tilde d_j - p_j) + n_0\rho_0 t_k}
             {\sum_{j\le k}\gamma^{k-j}\, t_j + n_0 t_k},\ \rho_\min,\ \rho_\max\Big),
    \qquad t_j = \operatorname{tr}(\tilde H P_j \tilde H^\mathsf{T}),\ \gamma = 1 - 1/\tau.

:math:`\rho` multiplies the *covariance* of the forecast (prior inflation, before the
analysis), i.e. the anomalies by :math:`\sqrt\rho`, of the state part only by default:
the parameters keep the spread of their random walk, so a factor above one cannot make
them grow without limit while they do not act on the data (laser off). The innovations
are those of the forecast before this step's inflation, so the estimate is of the
factor the raw forecast needs. Bounds keep a run of unlucky innovations from collapsing
or exploding the ensemble: by default :math:`1 \le \rho \le 25` (a forecast spread at
most 5 times the ensemble's).

References
----------
Desroziers, G., Berre, L., Chapnik, B. & Poli, P. (2005). Diagnosis of observation,
background and analysis-error statistics in observation space. QJRMS 131, 3385-3396.

Li, H., Kalnay, E. & Miyoshi, T. (2009). Simultaneous estimation of covariance
inflation and observation errors within an ensemble Kalman filter. QJRMS 135, 523-533.

Miyoshi, T. (2011). The Gaussian approach to adaptive covariance inflation and its
implementation with the local ensemble transform Kalman filter. MWR 139, 1519-1535.

Anderson, J. L. (2009). Spatially and temporally varying adaptive covariance inflation
for ensemble filters. Tellus A 61, 72-83.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

__all__ = ["PERSISTENCE_THRESHOLD", "AdaptiveInflation", "InflationEstimator",
           "innovation_loglik", "innovation_persistence", "innovation_statistics",
           "normalized_innovation", "persistence_flagged"]

#: lag-1 correlation of the normalized innovations above which a run is flagged
#: (:func:`persistence_flagged`; docs/beyond.md, "A model that misses the truth's physics")
PERSISTENCE_THRESHOLD = 0.3


@dataclass(frozen=True)
class AdaptiveInflation:
    """Settings of the adaptive prior inflation (see the module docstring).

    Parameters
    ----------
    initial : float
        :math:`\\rho_0`, the factor on the forecast covariance before any data (1: none).
    time_scale : float
        :math:`\\tau`, analysed steps over which old innovations are forgotten
        (:math:`\\gamma = 1 - 1/\\tau`); ``inf`` averages over the whole run.
    prior_steps : float
        :math:`n_0`, weight of :math:`\\rho_0` in analysed steps.
    bounds : (float, float)
        :math:`(\\rho_\\min, \\rho_\\max)`; below 1 allows deflation.
    target : {"state", "all"}
        What is inflated: the state part of the augmented ensemble (default), or the
        parameters too.
    """

    initial: float = 1.0
    time_scale: float = 30.0
    prior_steps: float = 5.0
    bounds: tuple[float, float] = (1.0, 25.0)
    target: str = "state"

    def __post_init__(self):
        lo, hi = (float(b) for b in self.bounds)
        if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi):
            raise ValueError(f"bounds must be (lo, hi) with 0 < lo <= hi, got {self.bounds!r}")
        object.__setattr__(self, "bounds", (lo, hi))
        if not (isinstance(self.initial, numbers.Real) and lo <= self.initial <= hi):
            raise ValueError(f"initial must lie within bounds {self.bounds}, got {self.initial!r}")
        if not (isinstance(self.time_scale, numbers.Real) and self.time_scale >= 1):
            raise ValueError(f"time_scale must be >= 1 (analysed steps), got {self.time_scale!r}")
        if not (isinstance(self.prior_steps, numbers.Real) and np.isfinite(self.prior_steps)
                and self.prior_steps > 0):
            raise ValueError(f"prior_steps must be > 0, got {self.prior_steps!r}")
        if self.target not in ("state", "all"):
            raise ValueError(f"target must be 'state' or 'all', got {self.target!r}")


def _whitened_innovations(Y: np.ndarray, y: np.ndarray, R: np.ndarray):
    """``(d̃, S̃, log det R, p)``: the innovation of the forecast mean and the forecast
    anomalies (N, p) whitened by ``R``, NaN components of ``y`` dropped; ``None`` when
    none is left."""
    ok = ~np.isnan(y)
    p = int(ok.sum())
    if p == 0:
        return None
    Y, y = Y[:, ok], y[ok]
    d = y - Y.mean(axis=0)
    B = Y - Y.mean(axis=0)
    R = np.asarray(R, float)
    if R.ndim == 1:
        sd = np.sqrt(R[ok])
        return d / sd, B / sd, 2.0 * float(np.sum(np.log(sd))), p
    L = np.linalg.cholesky(R[np.ix_(ok, ok)])
    return (np.linalg.solve(L, d), np.linalg.solve(L, B.T).T,
            2.0 * float(np.sum(np.log(np.diag(L)))), p)


def innovation_statistics(Y: np.ndarray, y: np.ndarray, R: np.ndarray) -> tuple[float, float, int]:
    """``(d̃ᵀd̃, tr(H̃PH̃ᵀ), p)`` of a forecast ``Y`` (N, p) against data ``y`` (p,), NaN
    components dropped; ``R`` (p,) variances or (p, p) covariance."""
    w = _whitened_innovations(Y, y, R)
    if w is None:
        return 0.0, 0.0, 0
    dt, S, _, p = w
    return float(dt @ dt), float(np.sum(S * S) / (Y.shape[0] - 1)), p


def innovation_loglik(Y: np.ndarray, y: np.ndarray, R: np.ndarray, rho: float = 1.0) -> float:
    r"""Log-density of the data ``y`` (p,) under the forecast ``Y`` (N, p): the Gaussian
    predictive :math:`\mathcal N(y;\ \bar y,\ \rho\,B^\mathsf{T}B/(N-1) + R)`,
    :math:`B = Y - \bar y`, NaN components dropped (0 when none is left).

    Summed over a run, it is the log evidence of the model under the filter's Gaussian
    approximation (the prediction-error decomposition of the likelihood; e.g. Carrassi
    et al. 2017, "Estimating model evidence using data assimilation", QJRMS 143): two
    models run on the same data are compared by the difference of their sums. Evaluated
    with the whitened anomalies :math:`\tilde S = B L^{-\mathsf T}\sqrt{\rho/(N-1)}`
    and the determinant lemma, so only a ``min(N, p)`` square system is solved.
    """
    w = _whitened_innovations(Y, y, R)
    if w is None:
        return 0.0
    dt, S, logdet_R, p = w
    N = Y.shape[0]
    S = S * np.sqrt(rho / max(N - 1, 1))
    # C = L (I_p + S'S) L': factor the smaller of I_p + S'S and I_N + SS' (equal
    # determinants; Woodbury for the solve), so a large ensemble or many pixels stay cheap
    if p <= N:
        c = np.linalg.cholesky(np.eye(p) + S.T @ S)
        z = np.linalg.solve(c, dt)
        quad = float(z @ z)
    else:
        c = np.linalg.cholesky(np.eye(N) + S @ S.T)
        Sd = np.linalg.solve(c, S @ dt)
        quad = float(dt @ dt - Sd @ Sd)
    logdet = logdet_R + 2.0 * float(np.sum(np.log(np.diag(c))))
    return -0.5 * (quad + logdet + p * np.log(2.0 * np.pi))


class InflationEstimator:
    """The running estimate :math:`\\rho_k` of one filter run."""

    def __init__(self, settings: AdaptiveInflation):
        self.s = settings
        tau = float(settings.time_scale)
        self.gamma = 1.0 if not np.isfinite(tau) else 1 - 1 / tau
        self.num = 0.0
        self.den = 0.0
        self.rho = float(settings.initial)

    def update(self, Y: np.ndarray, y: np.ndarray, R: np.ndarray) -> float:
        """Take one step's forecast ``Y`` (N, p) and data ``y``; return the new factor."""
        dd, tr, p = innovation_statistics(Y, y, R)
        if p == 0 or not np.isfinite(dd) or not np.isfinite(tr) or tr <= 0:
            return self.rho
        self.num = self.gamma * self.num + (dd - p)
        self.den = self.gamma * self.den + tr
        n0 = self.s.prior_steps * tr
        rho = (self.num + n0 * self.s.initial) / (self.den + n0)
        self.rho = float(np.clip(rho, *self.s.bounds))
        return self.rho


def normalized_innovation(Y: np.ndarray, y: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Each component of the innovation over its forecast sd, ``(y - ȳ) / sqrt(var(Y) +
    R_ii)`` (p,): unit variance when the forecast and ``R`` are right; NaN where ``y`` is.
    ``Y`` (N, p) the forecast ensemble in observation space, ``R`` (p,) variances or
    (p, p) covariance."""
    Y = np.asarray(Y, float)
    R = np.asarray(R, float)
    var = Y.var(axis=0, ddof=1) + (R if R.ndim == 1 else np.diag(R))
    with np.errstate(invalid="ignore", divide="ignore"):
        return (np.asarray(y, float) - Y.mean(axis=0)) / np.sqrt(var)


def innovation_persistence(z: np.ndarray, steps: np.ndarray | None = None) -> tuple[float, int]:
    r"""Lag-1 correlation of the normalized innovations from one reading to the next.

    ``z`` (M, p): :func:`normalized_innovation` of each step (a row of NaN where nothing
    was analysed); ``steps`` (M,) bool: the steps to use (default all). Over the pairs of
    consecutive steps ``(k - 1, k)`` both in ``steps``, and the components finite in both,

    .. math::

        r = \frac{\sum z_{k,i}\, z_{k-1,i}}{\sqrt{\sum z_{k,i}^2\,\sum z_{k-1,i}^2}}.

    The filter's innovations are white when its model is right: each analysis takes out
    what the data had to say. An error of the model that persists from step to step (a
    wrong geometry, boundary or heat transport) leaves innovations that persist with it.
    Returns ``(r, n)``, ``n`` the number of component pairs summed (``(nan, 0)`` without
    any); with white innovations ``r`` scatters about 0 with sd ``1/sqrt(n)``.
    """
    z = np.asarray(z, float)
    if z.ndim != 2:
        raise ValueError(f"z must be (M, p) normalized innovations, got shape {z.shape}")
    use = np.ones(z.shape[0], bool) if steps is None else np.asarray(steps, bool)
    if use.shape != (z.shape[0],):
        raise ValueError(f"steps must be ({z.shape[0]},) booleans, got shape {use.shape}")
    pair = use[1:] & use[:-1]
    a, b = z[1:][pair], z[:-1][pair]
    ok = np.isfinite(a) & np.isfinite(b)
    n = int(ok.sum())
    if n == 0:
        return float("nan"), 0
    a, b = a[ok], b[ok]
    den = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
    return (float(np.sum(a * b) / den) if den > 0 else float("nan")), n


def persistence_flagged(r: float, n: int, threshold: float = PERSISTENCE_THRESHOLD) -> bool:
    """Whether a persistence ``r`` over ``n`` pairs (:func:`innovation_persistence`)
    says the model misses something: above ``threshold`` and above 3 sd of white
    innovations' ``r`` (``3 / sqrt(n)``)."""
    return bool(n > 0 and np.isfinite(r) and r > max(threshold, 3.0 / np.sqrt(n)))
