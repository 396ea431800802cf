r"""Toy models to verify the filter: a linear-Gaussian system with its exact Kalman
filter, and Lorenz-96.

Linear-Gaussian
    :math:`x_{k+1} = F x_k + q_k,\ q_k \sim \mathcal{N}(0, Q)`,
    :math:`y_k = H x_k + r_k,\ r_k \sim \mathcal{N}(0, R)`. For this system the
    Kalman filter gives the exact posterior, and a large-ensemble EnKF must agree
    with it to within sampling error (Evensen 2009, ch. 4).

Lorenz-96 (Lorenz 1996)
    :math:`\dot{x}_i = (x_{i+1} - x_{i-2})\,x_{i-1} - x_i + F` with cyclic indices,
    40 variables and :math:`F = 8` in the standard test of Sakov & Oke (2008).

All functions are batched over leading axes: a state is ``(..., n)``, so an
ensemble ``(N, n)`` is advanced in one call.

References
----------
Lorenz, E. N. (1996). Predictability: a problem partly solved. Proc. ECMWF Seminar
on Predictability, vol. 1, 1-18.

Kalman, R. E. (1960). A new approach to linear filtering and prediction problems.
J. Basic Engineering 82, 35-45.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.linalg as sla

from .checks import as_generator, covariance, float_array

__all__ = [
    "kalman_analysis",
    "kalman_filter",
    "kalman_forecast",
    "lorenz96_rhs",
    "lorenz96_step",
    "lorenz96_twin",
    "rk4_step",
    "simulate_linear_gaussian",
]


# --------------------------------------------------------------------------- Lorenz-96


def lorenz96_rhs(x: np.ndarray, force: float | np.ndarray = 8.0) -> np.ndarray:
    r"""Lorenz-96 tendency :math:`\dot{x}_i = (x_{i+1} - x_{i-2})x_{i-1} - x_i + F`.

    Parameters
    ----------
    x : ndarray, shape (..., n)
        States, ``n >= 4``, cyclic in the last axis.
    force : float or ndarray broadcastable to ``(..., 1)``
        Forcing :math:`F`; an array ``(N, 1)`` gives each member its own forcing
        (used to test parameter estimation).

    Returns
    -------
    ndarray, shape (..., n)
    """
    # np.roll on the last axis: roll(x, -1)[i] = x[i+1], roll(x, 2)[i] = x[i-2].
    return (np.roll(x, -1, axis=-1) - np.roll(x, 2, axis=-1)) * np.roll(x, 1, axis=-1) - x + force


def rk4_step(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, dt: float) -> np.ndarray:
    """One classical fourth-order Runge-Kutta step of the autonomous ODE ``dx/dt = f(x)``."""
    k1 = f(x)
    k2 = f(x + 0.5 * dt * k1)
    k3 = f(x + 0.5 * dt * k2)
    k4 = f(x + dt * k3)
    return x + (dt / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)


def lorenz96_step(x: np.ndarray, dt: float, force: float | np.ndarray = 8.0, n_steps: int = 1) -> np.ndarray:
    """Advance Lorenz-96 states ``(..., n)`` by ``n_steps`` RK4 steps of size ``dt``.

    A numpy implementation: for the 40-variable, 40-member test one step costs
    some tens of microseconds, so a numba kernel would not pay for its compile.
    """
    x = np.asarray(x, dtype=float)
    for _ in range(n_steps):
        x = rk4_step(lambda z: lorenz96_rhs(z, force), x, dt)
    return x


def lorenz96_twin(
    n_steps: int,
    rng: np.random.Generator | int,
    n: int = 40,
    dt: float = 0.05,
    obs_var: float = 1.0,
    force: float = 8.0,
    spinup_steps: int = 1000,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Twin experiment of Sakov & Oke (2008): a Lorenz-96 truth, every variable
    observed every step with error variance ``obs_var``.

    The truth starts from :math:`F + \mathcal{N}(0, I)` advanced ``spinup_steps``
    steps, so that it is on the attractor at time 0.

    Returns
    -------
    times : ndarray, shape (n_steps,)
        Observation times ``dt, 2 dt, ...``.
    truth : ndarray, shape (n_steps + 1, n)
        True states at times ``0, dt, ...``.
    obs : ndarray, shape (n_steps, n)
        ``truth[1:]`` plus Gaussian noise.
    """
    rng = as_generator(rng)
    truth = np.empty((n_steps + 1, n))
    truth[0] = lorenz96_step(force + rng.standard_normal(n), dt, force, spinup_steps)
    for k in range(n_steps):
        truth[k + 1] = lorenz96_step(truth[k], dt, force)
    obs = truth[1:] + np.sqrt(obs_var) * rng.standard_normal((n_steps, n))
    return dt * np.arange(1, n_steps + 1), truth, obs


# ------------------------------------------------------------------- linear-Gaussian


def kalman_forecast(
    mu: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    r"""Exact forecast :math:`\mu \leftarrow F\mu`, :math:`P \leftarrow FPF^\mathsf{T} + Q`."""
    return F @ mu, F @ P @ F.T + Q


def kalman_analysis(
    mu: np.ndarray, P: np.ndarray, H: np.ndarray, R: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    r"""Exact Kalman analysis, NaN observations dropped.

    .. math::

        K = PH^\mathsf{T}(HPH^\mathsf{T} + R)^{-1}, \quad
        \mu^a = \mu + K(y - H\mu), \quad
        P^a = (I - KH)P(I - KH)^\mathsf{T} + KRK^\mathsf{T},

    the Joseph form, which keeps :math:`P^a` symmetric positive semi-definite.

    Parameters
    ----------
    mu : ndarray, shape (n,)
    P : ndarray, shape (n, n)
    H : ndarray, shape (p, n)
    R : ndarray, shape (p, p) or (p,)
    y : ndarray, shape (p,)

    Returns
    -------
    mu_a : ndarray, shape (n,)
    P_a : ndarray, shape (n, n)
    """
    y = np.asarray(y, dtype=float)
    R = np.diag(R) if np.ndim(R) == 1 else np.asarray(R, dtype=float)
    obs = ~np.isnan(y)
    if not obs.any():
        return mu.copy(), P.copy()
    H, R, y = H[obs], R[np.ix_(obs, obs)], y[obs]
    C = H @ P @ H.T + R
    K = sla.solve(C, H @ P, assume_a="pos").T
    IKH = np.eye(len(mu)) - K @ H
    P_a = IKH @ P @ IKH.T + K @ R @ K.T
    return mu + K @ (y - H @ mu), 0.5 * (P_a + P_a.T)


def kalman_filter(
    mu0: np.ndarray,
    P0: np.ndarray,
    F: np.ndarray,
    Q: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    data: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact Kalman filter for the linear-Gaussian model, analysis after every forecast.

    Parameters
    ----------
    mu0 : ndarray, shape (n,)
        Prior mean at step 0.
    P0 : ndarray, shape (n, n)
        Prior covariance at step 0.
    F : ndarray, shape (n, n)
        Transition matrix.
    Q : ndarray, shape (n, n) or (n,)
        Model-noise covariance (or its diagonal), added at each forecast.
    H : ndarray, shape (p, n)
        Observation matrix.
    R : ndarray, shape (p, p) or (p,)
        Observation-error covariance (or its diagonal).
    data : ndarray, shape (M, p)
        Observations at steps 1..M; NaN entries are missing.

    Returns
    -------
    means : ndarray, shape (M + 1, n)
        Filtering means; row 0 is ``mu0``.
    covs : ndarray, shape (M + 1, n, n)
        Filtering covariances; row 0 is ``P0``.
    """
    mu = float_array(mu0, "mu0", 1)
    n = mu.shape[0]
    P = covariance(P0, "P0", n)
    P = np.diag(P) if P.ndim == 1 else P
    Qm = covariance(Q, "Q", n)
    Qm = np.diag(Qm) if Qm.ndim == 1 else Qm
    data = float_array(data, "data", 2, finite=False)
    means = np.empty((data.shape[0] + 1, n))
    covs = np.empty((data.shape[0] + 1, n, n))
    means[0], covs[0] = mu, P
    for k, y in enumerate(data, start=1):
        mu, P = kalman_forecast(mu, P, F, Qm)
        mu, P = kalman_analysis(mu, P, H, R, y)
        means[k], covs[k] = mu, P
    return means, covs


def simulate_linear_gaussian(
    x0: np.ndarray,
    F: np.ndarray,
    Q: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    n_steps: int,
    rng: np.random.Generator | int,
) -> tuple[np.ndarray, np.ndarray]:
    """A truth trajectory and its observations for the linear-Gaussian model.

    Returns
    -------
    x : ndarray, shape (n_steps + 1, n)
        True states, ``x[0] = x0``.
    y : ndarray, shape (n_steps, p)
        Observations of ``x[1:]``.
    """
    rng = as_generator(rng)
    x0 = float_array(x0, "x0", 1)
    n, p = x0.shape[0], H.shape[0]
    Qm = covariance(Q, "Q", n)
    Qm = np.diag(Qm) if Qm.ndim == 1 else Qm
    Rm = covariance(R, "R", p)
    Rm = np.diag(Rm) if Rm.ndim == 1 else Rm
    x = np.empty((n_steps + 1, n))
    x[0] = x0
    for k in range(n_steps):
        x[k + 1] = F @ x[k] + rng.multivariate_normal(np.zeros(n), Qm)
    y = x[1:] @ H.T + rng.multivariate_normal(np.zeros(p), Rm, size=n_steps)
    return x, y


def lorenz96_filter_problem(n_steps: int, rng: np.random.Generator | int):
    """Sakov & Oke's (2008) twin experiment as a :class:`enkf.driver.FilterProblem`.

    All 40 variables observed every 0.05 with unit variance; the prior is the truth's
    initial state plus N(0, I). Returns ``(problem, truth)``, truth ``(n_steps + 1, 40)``.
    """
    from .problem import FilterProblem

    times, truth, obs = lorenz96_twin(n_steps, rng)
    problem = FilterProblem(
        forecast=lambda X, theta, t0, t1: lorenz96_step(X, t1 - t0),
        observation=np.eye(40),
        obs_times=times,
        obs_data=obs,
        obs_cov=np.ones(40),
        prior=lambda r, n: (truth[0] + r.standard_normal((n, 40)), None),
        tracked=np.arange(40),
    )
    return problem, truth
