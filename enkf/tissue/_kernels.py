"""Numba kernels of the tissue application: the structured model error's per-node update."""

from __future__ import annotations

import numba


@numba.njit(cache=True, nogil=True)
def sppt_step(r, field, phi, fresh_scale, rel, X0, X1, floor, eta, v):
    """The model error of one step, in one pass over the members' nodes.

    ``r`` (N, n) the relative errors, updated in place to ``phi * r + fresh_scale *
    field``; ``v`` (N, n) deg C set to ``rel[i] * r * (X1 - X0) + floor * eta`` (``eta``
    (N, n) standard normals, read only when ``floor > 0``); ``rel`` (N,) each member's
    relative standard deviation. ``X0``, ``X1`` may be strided views (the state part of
    an augmented ensemble)."""
    N, n = v.shape
    for i in range(N):
        ri = rel[i]
        for j in range(n):
            x = phi * r[i, j] + fresh_scale * field[i, j]
            r[i, j] = x
            e = ri * x * (X1[i, j] - X0[i, j])
            if floor > 0.0:
                e += floor * eta[i, j]
            v[i, j] = e
