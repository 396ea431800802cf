"""The ensemble's spread around an analysis: multiplicative inflation (:func:`inflate`),
relaxation to the prior's spread (:func:`relax_to_prior_spread`, RTPS) and a random
rotation of the anomalies (:func:`random_rotation`); pure array math on ``(N, n)``
ensembles, as :mod:`enkf.analysis`."""

from __future__ import annotations

import numpy as np

from .checks import as_generator, float_array, fraction

__all__ = ["inflate", "random_rotation", "relax_to_prior_spread"]


def inflate(E: np.ndarray, factor: float | np.ndarray) -> np.ndarray:
    r"""Multiplicative inflation of the ensemble anomalies.

    .. math::

        E \leftarrow \mathbf{1}\bar{x}^\mathsf{T} + \lambda\,(E - \mathbf{1}\bar{x}^\mathsf{T}),

    which multiplies the sample covariance by :math:`\lambda^2` (Anderson &
    Anderson 1999; the ``infl`` of Sakov & Oke 2008 and DAPPER).

    Parameters
    ----------
    E : ndarray, shape (N, n)
        Ensemble.
    factor : float or ndarray, shape (n,)
        :math:`\lambda > 0`, one for all components or one per component.

    Returns
    -------
    ndarray, shape (N, n)
        Inflated ensemble (a new array).
    """
    E = float_array(E, "E", 2, finite=False)
    lam = float_array(factor, "factor", (0, 1))
    if lam.ndim == 1 and lam.shape != (E.shape[1],):
        raise ValueError(f"factor must be a scalar or have shape ({E.shape[1]},), got {lam.shape}")
    if np.any(lam <= 0):
        raise ValueError(f"factor must be positive, got min {lam.min()!r}")
    x_mean = E.mean(axis=0)
    return x_mean + lam * (E - x_mean)


def relax_to_prior_spread(Ef: np.ndarray, Ea: np.ndarray, alpha: float) -> np.ndarray:
    r"""Relaxation to prior spread (RTPS; Whitaker & Hamill 2012, Mon. Wea. Rev. 140).

    Each component's analysis anomalies are scaled so that its spread moves back a
    fraction :math:`\alpha` of the way to the forecast's:

    .. math::

        A^a_j \leftarrow A^a_j \left(1 + \alpha\,\frac{\sigma^f_j - \sigma^a_j}
        {\sigma^a_j}\right), \qquad \sigma^a_j \leftarrow (1 - \alpha)\,\sigma^a_j
        + \alpha\,\sigma^f_j .

    It inflates only where the data reduced the spread, in proportion: the remedy for
    the spread an analysis with few members removes too much of (sampling error,
    nonlinearity), and it leaves unobserved components alone (unlike a multiplicative
    factor on every component). The mean is unchanged.

    Parameters
    ----------
    Ef, Ea : ndarray, shape (N, n)
        Forecast and analysis ensembles of the same components.
    alpha : float
        Relaxation in [0, 1] (0: none; 1: the forecast's spread restored). Whitaker &
        Hamill found 0.5-0.9 best in their global model.

    Returns
    -------
    ndarray, shape (N, n)
        The relaxed analysis (a new array). A component with no analysis spread is kept.
    """
    Ef = float_array(Ef, "Ef", 2, finite=False)
    Ea = float_array(Ea, "Ea", 2, finite=False)
    if Ef.shape != Ea.shape:
        raise ValueError(f"Ef and Ea must have the same shape, got {Ef.shape} and {Ea.shape}")
    alpha = fraction(alpha, "alpha")
    if alpha == 0.0 or Ea.shape[0] < 2:
        return Ea.copy()
    x_mean = Ea.mean(axis=0)
    A = Ea - x_mean
    sf = Ef.std(axis=0, ddof=1)
    sa = np.sqrt(np.einsum("ij,ij->j", A, A) / (A.shape[0] - 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(sa > 0, 1.0 + alpha * (sf - sa) / sa, 1.0)
    A *= factor
    A += x_mean
    return A


def random_rotation(E: np.ndarray, rng: np.random.Generator | int) -> np.ndarray:
    r"""Rotate the anomalies by a random mean-preserving orthogonal matrix.

    .. math::

        E \leftarrow \mathbf{1}\bar{x}^\mathsf{T} + \Omega A, \qquad
        \Omega = \tfrac{1}{N}\mathbf{1}\mathbf{1}^\mathsf{T} + B\,O\,B^\mathsf{T},

    with :math:`B` an orthonormal basis of :math:`\mathbf{1}^\perp` and :math:`O`
    Haar-distributed in :math:`O(N-1)`, so :math:`\Omega\mathbf{1} = \mathbf{1}` and
    the mean and sample covariance are unchanged. Used after the deterministic
    ETKF it spreads the ensemble over its subspace and prevents the outlier
    members that can make a symmetric square-root filter diverge on long runs
    (Sakov & Oke 2008; DAPPER's ``rot=True``). Cost :math:`O(N^3 + N^2 n)`.

    Parameters
    ----------
    E : ndarray, shape (N, n)
    rng : numpy.random.Generator or int

    Returns
    -------
    ndarray, shape (N, n)
    """
    rng = as_generator(rng)
    E = float_array(E, "E", 2)
    N = E.shape[0]
    if N < 2:
        raise ValueError(f"E must hold at least 2 members (rows), got N = {N}")
    # Orthonormal basis of the complement of 1: QR of [1, I] minus its first column.
    B = np.linalg.qr(np.column_stack([np.ones(N), np.eye(N)[:, : N - 1]]))[0][:, 1:]
    q, r = np.linalg.qr(rng.standard_normal((N - 1, N - 1)))
    O = q * np.sign(np.diag(r))  # sign fix makes O Haar-distributed (Mezzadri 2007)
    x_mean = E.mean(axis=0)
    A = E - x_mean
    return x_mean + B @ (O @ (B.T @ A))
