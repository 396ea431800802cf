"""Steps shared by the white Monte Carlo kernels (:mod:`mcmatlab_py.emulator._white_kernel`,
:mod:`mcmatlab_py.emulator._white_uniform`): the decay of the weights over a path and its deposit."""

import math

import numba
import numpy as np

from ..monte_carlo._tally import W_ONE

_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def exp_neg(x):
    """exp(-x) for x >= 0: Taylor to x^9 below 1/4 (error < 3e-13, a third of libm's time
    on the short steps between voxel faces), else ``math.exp``."""
    if x < 0.25:
        return 1.0 - x * (1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x * (
            1.0 / 120.0 - x * (1.0 / 720.0 - x * (1.0 / 5040.0 - x * (
                1.0 / 40320.0 - x * (1.0 / 362880.0)))))))))
    return math.exp(-x)


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def flush(q, w, e, mua, ds, dst, done):  # mua: (K,) the decay rates of the current medium
    """Advance each live weight by the part of a path ``ds`` it has not had yet
    (``ds - done_k``, :func:`settle`): ``e_k *= exp(-mua_k (ds - done_k))``, then
    ``q_k = W_ONE w_k e_k``; add what it lost into ``dst`` (K,); ``done`` back to 0.
    Returns the number of weights still above the fixed-point resolution."""
    alive = 0
    for k in range(q.size):
        d = ds - done[k]
        done[k] = 0.0
        if q[k] == 0:
            continue
        e[k] *= exp_neg(mua[k] * d)
        qn = np.int64(W_ONE * w[k] * e[k])
        dst[k] += q[k] - qn
        q[k] = qn
        if qn > 0:
            alive += 1
    return alive


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def settle(q, w, e, mua, k, ds, dst, done):
    """Advance weight ``k`` alone to the path ``ds`` (before its roulette), the others
    left pending: each weight's decay is then split at the same path lengths whatever
    other weights run with it, so its numbers are the same bit for bit."""
    e[k] *= exp_neg(mua[k] * (ds - done[k]))
    done[k] = ds
    qn = np.int64(W_ONE * w[k] * e[k])
    dst[k] += q[k] - qn
    q[k] = qn
