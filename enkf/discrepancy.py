r"""What a model error in the observations says about quantities the filter reports.

A filter whose observation-error covariance holds a *model* error (the model's prediction
of each observation is wrong by a correlated field :math:`\delta`, e.g.
:meth:`enkf.tissue.image.ThermalImage.error_covariance`) asserts that the model's
prediction of any other quantity of the same kind is wrong by the same field: a
camera's pixels are uncertain by a few percent of the rise, and so is the model's
temperature at a point of the surface between them. The ensemble does not carry
:math:`\delta` (it lives in :math:`R`), so the reported quantity :math:`z = Gx` misses it.

With :math:`z = Gx + \delta_z`, :math:`y = Hx + \delta_y + \varepsilon`, the model errors
jointly Gaussian with covariances :math:`k_{zz}`, :math:`k_{zy}` and independent of the
forecast, the Kalman update of the pair gives (Kennedy & O'Hagan 2001, the
discrepancy's posterior given the data)

.. math::

    \bar z^a = G\bar x^a + k_{zy}\,\hat S^{-1} d, \qquad
    \operatorname{var} z^a = G P^a G^\mathsf{T} + k_{zz}
        - k_{zy}\hat S^{-1}k_{yz} - 2\,G P^f H^\mathsf{T}\hat S^{-1}k_{yz},

with :math:`d = y - H\bar x^f`, :math:`\hat S = HP^fH^\mathsf{T} + R` (:math:`R` holding
the noise and :math:`k_{yy}`) and :math:`P^a` the analysis covariance of the ensemble
(exact for the ETKF, whose analysis has the Kalman moments). The last term is the
covariance the analysis builds between the state and the model error: data that pull the
state one way say the model error went the other.

References
----------
Kennedy, M. C. & O'Hagan, A. (2001). Bayesian calibration of computer models. JRSS B 63,
425-464.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

__all__ = ["discrepancy_posterior"]


def discrepancy_posterior(G_f: np.ndarray, Y_f: np.ndarray, y: np.ndarray, R: np.ndarray,
                          k_zy: np.ndarray, k_zz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""The model error's share of the reported quantities after one analysis.

    Parameters
    ----------
    G_f : (N, q)
        The forecast ensemble of the reported quantities :math:`Gx` (as the analysis saw it).
    Y_f : (N, p)
        The forecast ensemble in observation space.
    y : (p,)
        The data (NaN: missing, dropped as the analysis drops them).
    R : (p, p) or (p,)
        The observation-error covariance the analysis used (noise and model error).
    k_zy : (q, p)
        Covariance of the model errors of the reported quantities and of the observations.
    k_zz : (q,)
        Variance of the model error of each reported quantity.

    Returns
    -------
    shift : (q,)
        :math:`k_{zy}\hat S^{-1}d`, to add to the analysis ensemble's mean of :math:`Gx`.
    var : (q,)
        :math:`k_{zz} - k_{zy}\hat S^{-1}k_{yz} - 2\,GP^fH^\mathsf{T}\hat S^{-1}k_{yz}`, to add
        to its variance (the sum is a posterior variance, >= 0 up to rounding).
    """
    G_f, Y_f = np.asarray(G_f, float), np.asarray(Y_f, float)
    y, R = np.asarray(y, float), np.asarray(R, float)
    k_zy, k_zz = np.atleast_2d(np.asarray(k_zy, float)), np.asarray(k_zz, float)
    N, p = Y_f.shape
    q = G_f.shape[1]
    if G_f.shape[0] != N or y.shape != (p,) or k_zy.shape != (q, p) or k_zz.shape != (q,):
        raise ValueError(f"shapes do not agree: G_f {G_f.shape}, Y_f {Y_f.shape}, y {y.shape}, "
                         f"k_zy {k_zy.shape}, k_zz {k_zz.shape}")
    seen = ~np.isnan(y)
    if not seen.any():
        return np.zeros(q), k_zz.copy()
    Y = Y_f[:, seen]
    y_mean = Y.mean(axis=0)
    A_y = Y - y_mean
    A_g = G_f - G_f.mean(axis=0)
    S = A_y.T @ A_y / (N - 1)
    if R.ndim == 1:
        S[np.diag_indices_from(S)] += R[seen]
    else:
        S += R[np.ix_(seen, seen)]
    k = k_zy[:, seen]
    rhs = np.column_stack([y[seen] - y_mean, k.T])
    sol = sla.cho_solve(sla.cho_factor(S, lower=True), rhs)  # S^-1 [d, k_yz]
    shift = k @ sol[:, 0]
    B = sol[:, 1:]  # (p, q)
    cross = (A_g.T @ A_y) / (N - 1)  # G P^f H^T, (q, p)
    var = k_zz - np.einsum("qp,pq->q", k, B) - 2.0 * np.einsum("qp,pq->q", cross, B)
    return shift, var
