"""Steps shared by the white Monte Carlo kernels (:mod:`mcmatlab_py._white_kernel`,
:mod:`mcmatlab_py._white_uniform`): the decay of the weights over a path and its deposit."""

import math

import numba
import numpy as np

from ._mc_tally import W_ONE

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
def flush(q, w, e, mua, ds, dst):  # mua: (K,) the decay rates of the current medium
    """Advance each live weight by a path ``ds``: ``e_k *= exp(-mua_k ds)``, then
    ``q_k = W_ONE w_k e_k``; add what it lost into ``dst`` (K,). Returns the number of
    weights still above the fixed-point resolution."""
    alive = 0
    for k in range(q.size):
        if q[k] == 0:
            continue
        e[k] *= exp_neg(mua[k] * ds)
        qn = np.int64(W_ONE * w[k] * e[k])
        dst[k] += q[k] - qn
        q[k] = qn
        if qn > 0:
            alive += 1
    return alive
