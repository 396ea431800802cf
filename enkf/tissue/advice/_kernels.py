"""Numba kernel of the advice's forecast: the laser's responses summed over the steps."""

from __future__ import annotations

import numba


@numba.njit(cache=True)
def superpose(Y, G, P, c, seg):  # pragma: no cover - compiled
    """Add to ``Y`` (N, K+1, p) deg C, in place, the responses ``G`` (N, S, K, p) to the
    powers ``P`` (K,) W over each member's first ``c`` (N,) steps, step ``j`` with the
    responses of set ``seg[j]``: ``Y_k += sum_(j < min(k, c)) P_j G_(seg_j, k-1-j)``,
    the steps ``j`` in increasing order (as :func:`~enkf.tissue.advice.forecast.heat`)."""
    N, _, K, p = G.shape
    for n in range(N):
        for j in range(min(c[n], K)):
            Pj = P[j]
            if Pj == 0.0:
                continue
            s = seg[j]
            for k in range(j + 1, K + 1):
                for i in range(p):
                    Y[n, k, i] += Pj * G[n, s, k - 1 - j, i]
