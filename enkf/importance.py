r"""Adaptive multiple importance sampling (AMIS): the posterior the ensemble only approximates.

An ensemble smoother (:mod:`enkf.smoother`) moves the members by linear updates. Where
the map from parameters to readings curves strongly within the posterior, or a parameter
is hardly determined by the data (its posterior as wide as its bounded prior), the
ensemble's spread misstates the posterior: on the layered block with both layers
estimated from one sensor its +-2 sd bands held the truth on 45-70% of seeds
(``validation/reports/layered_both.md``).

Where the parameters are few and the log posterior can be evaluated for a batch of them
(the model re-run over the window, as the smoother does anyway), importance sampling
gives the posterior itself, with the ensemble as its first guess. AMIS (Cornuet, Marin,
Mira & Robert 2012, Scand. J. Statist. 39, 798-812) draws ``n_rounds`` batches, each from
a multivariate Student-t proposal fitted to the weighted samples so far, and weighs every
sample against the mixture of all the proposals used (the deterministic-mixture weights
of Owen & Zhou 2000):

.. math::

    w_i \propto \frac{\pi(u_i)}{\sum_r (M_r / M)\, q_r(u_i)}.

The weighted samples are consistent for the posterior ``pi`` whatever the proposals,
provided the proposals' tails are heavier than the posterior's: hence the Student-t (``df``
degrees of freedom) and the covariance widened by ``spread`` squared. The effective sample
size :math:`(\sum w)^2 / \sum w^2` says how much the estimate is worth; a small one
(``ess < min_ess``) warns.

The first guess shows the sampler one mode. Where the posterior has others, ``modes``
(from :func:`enkf.modes.find_modes`) adds a Student-t kernel on each to every round's
proposal, a share ``mode_share`` of the samples split by the modes' masses.

Cost: ``n_samples`` evaluations of the log posterior (samples where it is ``-inf``, e.g.
outside a bounded prior, are left to ``log_target`` to skip cheaply), a handful of
ensemble runs for a few parameters.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular
from scipy.special import gammaln, logsumexp

from .checks import as_generator, float_array

__all__ = ["ImportanceSample", "amis", "student_t_logpdf", "weighted_quantile"]


@dataclass
class ImportanceSample:
    """Weighted samples of a posterior.

    ``U`` (M, d) the samples; ``weights`` (M,) their normalised weights (sum 1);
    ``log_target`` (M,) the unnormalised log posterior at each (``-inf`` outside its
    support); ``ess`` the effective sample size; ``n_rounds`` proposals used.
    """

    U: np.ndarray
    weights: np.ndarray
    log_target: np.ndarray
    ess: float
    n_rounds: int

    @property
    def mean(self) -> np.ndarray:
        """(d,) the weighted mean."""
        return self.weights @ self.U

    @property
    def cov(self) -> np.ndarray:
        """(d, d) the weighted covariance."""
        return _weighted_cov(self.U, self.weights)

    def quantile(self, q, i: int) -> np.ndarray:
        """The weighted ``q`` quantiles of coordinate ``i`` (linear between samples)."""
        return weighted_quantile(self.U[:, i], self.weights, q)

    def resample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, d) equally weighted draws (systematic resampling)."""
        edges = np.cumsum(self.weights)
        edges[-1] = 1.0
        idx = np.searchsorted(edges, (rng.uniform() + np.arange(n)) / n)
        return self.U[idx]


def weighted_quantile(x: np.ndarray, w: np.ndarray, q) -> np.ndarray:
    """``q`` quantiles of ``x`` (M,) under weights ``w`` (M,) >= 0; each sample
    stands at the middle of its weight (so equal weights give the sample quantiles'
    Hazen definition)."""
    keep = w > 0  # a sample of no weight is no point of the distribution
    order = np.argsort(x[keep])
    x, w = x[keep][order], w[keep][order] / w.sum()
    mid = np.cumsum(w) - 0.5 * w
    return np.interp(q, mid, x)


def student_t_logpdf(U: np.ndarray, mu: np.ndarray, L: np.ndarray, df: float) -> np.ndarray:
    """(M,) log density of the multivariate Student-t with location ``mu`` (d,), scale
    matrix ``L L^T`` (``L`` (d, d) lower triangular) and ``df`` degrees of freedom."""
    return _mixture_logpdf(U, np.atleast_2d(mu), L, df)


def _mixture_logpdf(U, C, L, df) -> np.ndarray:
    """(M,) log density of the equal mixture of Student-t kernels at the centres ``C``
    (K, d), each of scale matrix ``L L^T``."""
    d = C.shape[1]
    W = solve_triangular(L, U.T, lower=True)  # (d, M)
    Z = solve_triangular(L, C.T, lower=True)  # (d, K)
    maha = np.maximum((W * W).sum(0)[:, None] + (Z * Z).sum(0)[None, :] - 2 * W.T @ Z, 0.0)
    const = (gammaln(0.5 * (df + d)) - gammaln(0.5 * df) - 0.5 * d * np.log(df * np.pi)
             - np.sum(np.log(np.diag(L))))
    return const + logsumexp(-0.5 * (df + d) * np.log1p(maha / df), axis=1) - np.log(len(C))


def _mixture_draw(rng, n, C, L, df) -> np.ndarray:
    k = np.floor((rng.uniform() + np.arange(n)) / n * len(C)).astype(int)  # stratified
    z = rng.standard_normal((n, C.shape[1]))
    g = rng.chisquare(df, size=(n, 1)) / df
    return C[rng.permutation(k)] + (z @ L.T) / np.sqrt(g)


def _weighted_cov(U, w) -> np.ndarray:
    A = U - w @ U  # anomalies
    return (A * w[:, None]).T @ A


def _jittered(C) -> np.ndarray:
    """``C`` kept positive definite for its Cholesky factor."""
    return C + 1e-12 * np.trace(C) / C.shape[0] * np.eye(C.shape[0])


def amis(log_target: Callable[[np.ndarray], np.ndarray], U0: np.ndarray,
         rng: np.random.Generator | int, *, n_samples: int = 3000, n_rounds: int = 6,
         df: float = 5.0, spread: float = 1.5, n_kernels: int = 100, defensive: float = 0.2,
         min_ess: float = 100.0, modes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
         mode_share: float = 0.3, callback: Callable[[int, ImportanceSample], None] | None = None
         ) -> ImportanceSample:
    """The posterior ``exp(log_target)`` by AMIS from the first guess ``U0`` (module doc).

    Parameters
    ----------
    log_target : callable
        ``log_target(U) -> (M,)``: the unnormalised log posterior of the samples ``U``
        (M, d); ``-inf`` where it is zero (NaN is refused).
    U0 : (N, d) the first guess (an ensemble): the first proposal's kernel centres and
        (times ``spread`` squared) its kernels' covariance
    rng : generator or seed of the draws
    n_samples : the samples in all, split evenly over ``n_rounds`` proposals
    df : the kernels' Student-t degrees of freedom (> 0; heavy tails)
    spread : factor on the first proposal's kernel widths (>= 1)
    n_kernels : kernels of the later proposals, centred on draws from the weighted
        samples so far, each with their weighted covariance (shrunk towards the previous
        round's by the weight of 2 (d + 1) samples) times the squared bandwidth of
        Silverman's rule for the effective sample size
    defensive : the share of each later round's samples drawn from one Student-t with
        the weighted covariance times ``spread`` squared (0-1)
    min_ess : a RuntimeWarning below this effective sample size
    modes : ``(centres (K, d), covariances (K, d, d), masses (K,))``: other modes of the
        posterior (:func:`enkf.modes.find_modes`), each drawn in every round from a
        Student-t with its covariance times ``spread`` squared, a share ``mode_share`` of
        the samples split in proportion to ``masses``, so that AMIS does not depend on the
        first guess alone to find them
    mode_share : the share of each round drawn from ``modes`` (0-1)
    callback : ``callback(r, sample)`` after each round ``r``
    """
    U0 = float_array(U0, "U0", 2)
    rng = as_generator(rng)
    N, d = U0.shape
    if N < d + 1:
        raise ValueError(f"U0 must have more members than dimensions + 1 to fit a proposal, "
                         f"got shape {U0.shape}")
    if not (isinstance(n_rounds, (int, np.integer)) and n_rounds >= 1):
        raise ValueError(f"n_rounds must be an integer >= 1, got {n_rounds!r}")
    if not (isinstance(n_samples, (int, np.integer)) and n_samples >= 2 * n_rounds * (d + 1)):
        raise ValueError(f"n_samples must be an integer >= {2 * n_rounds * (d + 1)} (2 (d + 1) "
                         f"per round), got {n_samples!r}")
    if not (isinstance(n_kernels, (int, np.integer)) and n_kernels >= 1):
        raise ValueError(f"n_kernels must be an integer >= 1, got {n_kernels!r}")
    if not (np.isfinite(df) and df > 0):
        raise ValueError(f"df must be > 0, got {df!r}")
    if not (np.isfinite(spread) and spread >= 1):
        raise ValueError(f"spread must be >= 1, got {spread!r}")
    if not (np.isfinite(defensive) and 0 <= defensive < 1):
        raise ValueError(f"defensive must be in [0, 1), got {defensive!r}")
    if not (np.isfinite(mode_share) and 0 <= mode_share < 1 - defensive):
        raise ValueError(f"mode_share must be in [0, 1 - defensive), got {mode_share!r}")
    extra = []
    if modes is not None:
        C, S, mass = (np.asarray(a, float) for a in modes)
        if C.ndim != 2 or C.shape[1] != d or S.shape != (len(C), d, d) or mass.shape != (len(C),):
            raise ValueError(f"modes must be (centres (K, {d}), covariances (K, {d}, {d}), "
                             f"masses (K,)), got shapes {C.shape}, {S.shape}, {mass.shape}")
        if not (np.all(mass >= 0) and mass.sum() > 0):
            raise ValueError(f"modes' masses must be >= 0 and not all 0, got {mass}")
        share = mode_share * mass / mass.sum()
        extra = [(C[k:k + 1], np.linalg.cholesky(_jittered(S[k]) * spread ** 2), share[k])
                 for k in range(len(C)) if share[k] > 0]
    rest = 1.0 - sum(e[2] for e in extra)
    per_round = np.full(n_rounds, n_samples // n_rounds)
    per_round[: n_samples % n_rounds] += 1
    cov = _jittered(_weighted_cov(U0, np.full(N, 1.0 / N)))
    # a proposal: components (centres (K, d), scale's Cholesky factor, samples drawn)
    proposal = [(U0, np.linalg.cholesky(cov * spread ** 2), rest), *extra]
    components, Us, logp = [], [], []
    sample = None
    for r in range(n_rounds):
        counts = np.diff(np.round(np.cumsum([0.0] + [c[2] for c in proposal]) * per_round[r]))
        parts = []
        for (C, L, _), m in zip(proposal, counts.astype(int), strict=True):
            if m:
                components.append((C, L, m))
                parts.append(_mixture_draw(rng, m, C, L, df))
        U = np.vstack(parts)
        lp = np.asarray(log_target(U), float)
        if lp.shape != (U.shape[0],):
            raise ValueError(f"log_target must return shape {(U.shape[0],)}, got {lp.shape}")
        if np.any(np.isnan(lp)) or np.any(lp == np.inf):
            raise FloatingPointError(f"AMIS round {r + 1}: log_target gave NaN or +inf")
        Us.append(U)
        logp.append(lp)
        U_all, lp_all = np.vstack(Us), np.concatenate(logp)
        log_q = logsumexp(np.column_stack([np.log(m / len(U_all)) + _mixture_logpdf(U_all, C, L, df)
                                           for C, L, m in components]), axis=1)
        logw = lp_all - log_q
        if not np.any(np.isfinite(logw)):
            raise FloatingPointError(f"AMIS round {r + 1}: every sample has zero posterior "
                                     "density (is the first guess inside the support?)")
        w = np.exp(logw - np.max(logw))
        w /= w.sum()
        sample = ImportanceSample(U_all, w, lp_all, float(1.0 / np.sum(w ** 2)), r + 1)
        if callback is not None:
            callback(r, sample)
        if r + 1 < n_rounds:
            # the posterior's covariance from the weighted samples, shrunk towards the last
            # estimate with the weight of 2 (d + 1) samples (few effective samples in the
            # first rounds); kernels of Silverman's bandwidth on draws from the samples, and
            # a share ``defensive`` from one wide Student-t, so that no tail of the
            # posterior is left to the narrow kernels alone
            n0 = 2.0 * (d + 1)
            cov = (sample.ess * _jittered(sample.cov) + n0 * cov) / (sample.ess + n0)
            h = (4.0 / ((d + 2) * min(sample.ess, n_kernels))) ** (1.0 / (d + 4))
            proposal = [(sample.resample(int(n_kernels), rng), np.linalg.cholesky(cov * h ** 2),
                         rest - defensive),
                        (sample.mean[None, :], np.linalg.cholesky(cov * spread ** 2), defensive),
                        *extra]
    if sample.ess < min_ess:
        warnings.warn(f"AMIS: effective sample size {sample.ess:.0f} of {sample.U.shape[0]} "
                      f"samples is below {min_ess:g}: the posterior's estimate is noisy; use "
                      "more samples or rounds", RuntimeWarning, stacklevel=2)
    return sample
