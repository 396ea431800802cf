"""Input checks shared by the filter modules.

Every check raises a ``ValueError`` that names the offending field and shows the
bad value (or its shape), as the project style asks.
"""

from __future__ import annotations

import numbers

import numpy as np

__all__ = ["as_generator", "cov_sqrt", "covariance", "float_array", "fraction", "rows_times",
           "variances"]


def as_generator(rng: np.random.Generator | int, name: str = "rng") -> np.random.Generator:
    """Return ``rng`` as a Generator; an int is taken as a seed.

    ``None`` is refused on purpose: a draw from OS entropy would make results
    impossible to reproduce.
    """
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, numbers.Integral) and not isinstance(rng, bool) and rng >= 0:
        return np.random.default_rng(int(rng))
    raise ValueError(f"{name} must be a numpy.random.Generator or a non-negative int seed, got {rng!r}")


def fraction(x, name: str) -> float:
    """``x`` as a float in [0, 1]; else a ``ValueError`` that names ``name`` and the value."""
    if isinstance(x, bool) or not isinstance(x, numbers.Real) or not 0.0 <= x <= 1.0:
        raise ValueError(f"{name} must be a number in [0, 1], got {x!r}")
    return float(x)


def float_array(x, name: str, ndim: int | tuple[int, ...], finite: bool = True) -> np.ndarray:
    """``x`` as a float64 array with the given number(s) of dimensions."""
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} must be a numeric array, got {type(x).__name__}") from err
    ndims = (ndim,) if isinstance(ndim, int) else ndim
    if a.ndim not in ndims:
        raise ValueError(f"{name} must have {' or '.join(map(str, ndims))} dimension(s), got shape {a.shape}")
    if finite and not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {np.count_nonzero(~np.isfinite(a))} non-finite entries")
    return a


def variances(x, name: str, n: int | None = None, allow_zero: bool = True) -> np.ndarray:
    """A scalar or ``(n,)`` vector of variances, broadcast to ``(n,)`` when ``n`` is given."""
    a = float_array(x, name, (0, 1))
    if n is not None:
        if a.ndim == 1 and a.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
        a = np.broadcast_to(a, (n,)).copy()
    bad = a < 0 if allow_zero else a <= 0
    if np.any(bad):
        rel = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be {rel}, got min {a.min()!r}")
    return a


def covariance(x, name: str, n: int, allow_singular: bool = True) -> np.ndarray:
    """A variance vector ``(n,)`` (or scalar) or a full symmetric ``(n, n)`` covariance.

    A diagonal is returned 1-D (the fast path everywhere); a full matrix is checked
    for symmetry and for a non-negative (``allow_singular``) or positive spectrum.
    """
    a = float_array(x, name, (0, 1, 2))
    if a.ndim < 2:
        return variances(a, name, n, allow_zero=allow_singular)
    if a.shape != (n, n):
        raise ValueError(f"{name} must have shape ({n},) or ({n}, {n}), got {a.shape}")
    scale = max(float(np.abs(a).max()), np.finfo(float).tiny)
    if not np.allclose(a, a.T, rtol=1e-10, atol=1e-12 * scale):
        raise ValueError(
            f"{name} must be symmetric, got max |{name} - {name}^T| = {np.abs(a - a.T).max():.3g}"
        )
    a = 0.5 * (a + a.T)
    lam_min = float(np.linalg.eigvalsh(a)[0]) if n else 0.0
    if lam_min < -1e-12 * scale or (not allow_singular and lam_min <= 0):
        rel = "positive semi-definite" if allow_singular else "positive definite"
        raise ValueError(f"{name} must be {rel}, got smallest eigenvalue {lam_min:.3g}")
    return a


def cov_sqrt(C: np.ndarray) -> np.ndarray:
    """A square root ``L`` with ``L L^T = C`` (full PSD ``C``), or the std vector (diagonal).

    The symmetric root (eigen-decomposition) is used instead of Cholesky so that
    singular covariances (e.g. a random walk on only some parameters) work.
    """
    if C.ndim == 1:
        return np.sqrt(C)
    lam, V = np.linalg.eigh(C)
    return (V * np.sqrt(np.clip(lam, 0.0, None))) @ V.T


def rows_times(H, X: np.ndarray) -> np.ndarray:
    """``X @ H.T`` (N, p) for an operator ``H`` (p, n), dense or scipy-sparse, and the
    members ``X`` (N, n), which may be a strided view.

    A sparse ``H`` with few entries (sensor probes: a handful of weights per row) is
    applied by gathering the columns it touches, ``O(N nnz)``; scipy's ``H @ X.T`` would
    first copy ``X.T`` into C order, a pass over the whole ensemble (0.5-0.8 ms per call
    at N = 50, n = 4851).
    """
    if not hasattr(H, "tocsr"):
        return np.asarray(X @ np.asarray(H).T, dtype=float)
    H = H.tocsr()
    if H.nnz == 0:
        return np.zeros((X.shape[0], H.shape[0]))
    if H.nnz > X.shape[1]:
        return np.asarray(H @ np.ascontiguousarray(X.T), dtype=float).T
    G = X[:, H.indices] * H.data  # (N, nnz)
    starts = H.indptr[:-1]
    Y = np.add.reduceat(G, np.minimum(starts, H.nnz - 1), axis=1)
    Y[:, starts == H.indptr[1:]] = 0.0  # reduceat gives an entry, not 0, for empty rows
    return Y
