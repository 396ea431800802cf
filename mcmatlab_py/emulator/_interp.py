"""Numba kernels of the emulator's interpolation: 4-point Lagrange in log mua and log mus."""

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _lagrange4(t, i0, grid_log):
    """Weights of the 4-point Lagrange interpolant at ``t`` on nodes ``grid_log[i0:i0+4]``."""
    x0 = grid_log[i0]
    x1 = grid_log[i0 + 1]
    x2 = grid_log[i0 + 2]
    x3 = grid_log[i0 + 3]
    w0 = (t - x1) * (t - x2) * (t - x3) / ((x0 - x1) * (x0 - x2) * (x0 - x3))
    w1 = (t - x0) * (t - x2) * (t - x3) / ((x1 - x0) * (x1 - x2) * (x1 - x3))
    w2 = (t - x0) * (t - x1) * (t - x3) / ((x2 - x0) * (x2 - x1) * (x2 - x3))
    w3 = (t - x0) * (t - x1) * (t - x2) / ((x3 - x0) * (x3 - x1) * (x3 - x2))
    return w0, w1, w2, w3


@numba.njit(cache=True)
def _stencil(t, grid_log):
    n = grid_log.size
    i = np.searchsorted(grid_log, t) - 1
    i0 = min(max(i - 1, 0), n - 4)
    return i0


@numba.njit(cache=True)
def stencil_starts(t, grid_log):
    """The first node of the 4-point stencil of each ``t`` (N,): the table points an
    interpolation at ``t`` reads (the emulator's on-demand points)."""
    out = np.empty(t.size, dtype=np.int64)
    for n in range(t.size):
        out[n] = _stencil(t[n], grid_log)
    return out


@numba.njit(cache=True, nogil=True)
def interpolate_log_na(table, lmua_grid, lmus_grid, lmua, lmus, offset, out):
    """``out[n] = exp(sum_ab w_a(lmua[n]) w_b(lmus[n]) table[a, b]) - offset`` (4 x 4 Lagrange).

    table : (n_mua, n_mus, nvox) float64 log NA; lmua, lmus : (N,) logs; out : (N, nvox).

    One thread on purpose: the filter calls it every step for 50 members (0.3 ms), and
    after a numba parallel region the OpenMP workers spin on the other core for
    milliseconds, which made the heat step that follows 1.3 ms (50%) slower.
    """
    N = lmua.size
    nvox = table.shape[2]
    for n in range(N):
        ia = _stencil(lmua[n], lmua_grid)
        ib = _stencil(lmus[n], lmus_grid)
        wa = _lagrange4(lmua[n], ia, lmua_grid)
        wb = _lagrange4(lmus[n], ib, lmus_grid)
        row = out[n]
        for v in range(nvox):
            row[v] = 0.0
        for a in range(4):
            for b in range(4):
                w = wa[a] * wb[b]
                src = table[ia + a, ib + b]
                for v in range(nvox):
                    row[v] += w * src[v]
        for v in range(nvox):
            row[v] = max(np.exp(row[v]) - offset, 0.0)
