"""Numba kernel of the white Monte Carlo for a cuboid of one medium with escaping faces.

The general white kernel (:mod:`mcmatlab_py.emulator._white_kernel`) walks every voxel face a
packet crosses and settles each weight's loss in the voxel it was lost in (the
track-length estimator). On the emulator's 100 x 100 x 50 voxels that is 20 crossings per
free path at ``mus = 10`` cm^-1, each costing one exponential per ``mua_k``: the white
build of a low-``mus`` column then cost three times the direct table's twelve runs. When
one medium fills the grid and every face is escaping (``boundary_type`` 1, the case of
:mod:`mcmatlab_py.monte_carlo._uniform`), this kernel walks no faces:

* free paths are whole moves, and only a move that leaves the cuboid is cut at its face;
* while successive moves stay in one voxel the path is only added up; the losses
  ``W_k(L_a) - W_k(L_b)`` are settled in that voxel when the packet leaves it (exact, as
  the track-length estimator);
* the loss of ``k`` along a move that does cross voxel faces is put, whole, at one point
  of that move drawn from the density of where it was lost, ``mua_k exp(-mua_k l)`` on
  ``[0, s]`` (one uniform number shared by all ``k``, inverted per ``k``). The expected
  deposit in every voxel is then the track-length integral: unbiased, with the fixed-point
  bookkeeping of the general kernel, so every packet's deposits plus its escape still add
  up to its launch weight exactly, for every ``k``.

Launch, Fresnel reflection at the escaping faces (mismatched interfaces), per-``k``
roulette and the escape tallies are those of the general white kernel; the random
numbers are drawn as in :mod:`mcmatlab_py.monte_carlo._uniform` (ziggurat free paths, azimuths from
the unit disc), so a seed gives other (statistically equal) numbers than the general
kernel, still the same for any number of threads.
"""

import math

import numba
import numpy as np

from .._rng import counter_double, next_azimuth, next_double, next_exponential, photon_stream
from ..light._sources import SI_SURFACE, launch_from
from ..monte_carlo._steps import _cut_at_face, _enter_top, _fresnel, _hg_cos, _mirror, _spin_cs
from ..monte_carlo._tally import (
    T_BOTTOM,
    T_LAUNCHED,
    T_MISSED,
    T_ROULETTE,
    T_SIDES,
    T_SPECULAR,
    T_TOP,
    W_ONE,
)
from ._white_steps import exp_neg, flush, settle

_INF = np.inf
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


_SERIES_X = 0.25  # loss_point's series up to x^4 below this: error < 4e-7 of the move


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def loss_coefficients(u):
    """The coefficients of ``x``, ..., ``x^4`` of :func:`loss_point`'s series at ``u``
    (shared by every ``k`` of a move: one uniform number for all)."""
    v = u * (u - 1.0)
    h = 2.0 * u - 1.0
    w = 6.0 * v + 1.0  # 6u^2 - 6u + 1
    return 0.5 * v, v * h / 6.0, v * w / 24.0, v * h * (2.0 * w - 1.0) / 120.0


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def loss_point_c(u, x, lost, c1, c2, c3, c4):
    """:func:`loss_point` with the coefficients of :func:`loss_coefficients` at ``u``."""
    if x < _SERIES_X:
        return u + x * (c1 + x * (c2 + x * (c3 + x * c4)))
    return min(-math.log1p(-u * lost) / x, 1.0)


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def loss_point(u, x, lost):
    """Where along a move the loss of one weight is put, as a fraction of the move: the
    inverse of the distribution ``(1 - exp(-x t)) / (1 - exp(-x))`` on ``[0, 1]`` at ``u``,
    with ``x = mua s`` and ``lost = 1 - exp(-x)``; for ``x < 0.25`` its series in ``x`` to
    ``x^4`` (error below 4e-7 of the move; no logarithm for most moves)."""
    c1, c2, c3, c4 = loss_coefficients(u)
    return loss_point_c(u, x, lost, c1, c2, c3, c4)


@numba.njit(cache=True, inline="always")
def _voxel(px, py, pz, inv_dx, inv_dy, inv_dz, nx, ny, nz):
    """The voxel (C-order index) that holds a point of the cuboid (faces clamped)."""
    ix = min(max(int(px * inv_dx), 0), nx - 1)
    iy = min(max(int(py * inv_dy), 0), ny - 1)
    iz = min(max(int(pz * inv_dz), 0), nz - 1)
    return (ix * ny + iy) * nz + iz


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _spread(q, w, e, mua, s, u, px, py, pz, ux, uy, uz,
            inv_dx, inv_dy, inv_dz, nx, ny, nz, fold, acc):  # fmt: skip
    """The losses of a move of length ``s`` from ``(px, py, pz)`` along ``u`` that crosses
    voxel faces: each ``k``'s loss at its own point (:func:`loss_point` at ``u``).
    Returns the live weights."""
    alive = 0
    c1, c2, c3, c4 = loss_coefficients(u)
    last = -1  # the voxel of the previous deposit and its row: most k share one
    row = 0
    for k in range(q.size):
        if q[k] == 0:
            continue
        x = mua[k] * s
        f = exp_neg(x)
        e[k] *= f
        qn = np.int64(W_ONE * w[k] * e[k])
        d = q[k] - qn
        if d > 0:
            t = loss_point_c(u, x, 1.0 - f, c1, c2, c3, c4) * s
            v = _voxel(px + t * ux, py + t * uy, pz + t * uz, inv_dx, inv_dy, inv_dz, nx, ny, nz)
            if v != last:
                last = v
                row = fold[v]
            acc[row, k] += d
        q[k] = qn
        if qn > 0:
            alive += 1
    return alive


# The one-medium form of _white_kernel.white_batch (as monte_carlo._uniform is of the direct
# kernel): no voxel look-ups, the whole free path at once; the few lines they share (the
# settle and flush of the weights) are in _white_steps.
@numba.njit(cache=True, fastmath=_FASTMATH)
def white_uniform_batch(
    b, mua, kid, mus, g, nref, nx, ny, nz, dx, dy, dz, n_out, matched, roulette,
    weight_threshold, chance, si, sf, stab, svox, fold, seed, batch_size, n_total, acc, tally,
):  # fmt: skip
    """Run the photons of batch ``b`` for every absorption ``mua`` (K,) cm^-1 (all > 0)
    of the one medium (scattering ``mus`` cm^-1, anisotropy ``g``, index ``nref``) that
    fills the grid. ``fold``, ``acc`` (n_rows, K) and ``tally`` (N_TALLY, K) as
    :func:`mcmatlab_py.emulator._white_kernel.white_batch`."""
    K = mua.size
    Lx = nx * dx
    Ly = ny * dy
    Lz = nz * dz
    inv_dx = 1.0 / dx
    inv_dy = 1.0 / dy
    inv_dz = 1.0 / dz
    inv_mus = 1.0 / mus
    st = np.empty(4, dtype=np.uint64)
    surface = si[SI_SURFACE] == 1
    q = np.zeros(K, dtype=np.int64)
    w = np.zeros(K)
    lr = np.zeros(K)
    e = np.zeros(K)
    nr = np.zeros(K, dtype=np.int64)  # roulettes of each k so far in this photon
    done = np.zeros(K)  # the part of ``pend`` each k has had (settled for its roulette)
    first = b * batch_size
    last = min(first + batch_size, n_total)
    for _ip in range(first, last):
        # each photon its own path stream, and each weight its own roulette numbers: a
        # weight's deposits do not depend on which other weights run with it
        s0, s1, s2, s3 = photon_stream(seed, _ip)
        s0, s1, s2, s3, px, py, pz, ux, uy, uz, ok = launch_from(
            si, sf, stab, svox, nx, ny, nz, dx, dy, dz, st, s0, s1, s2, s3)
        for k in range(K):
            tally[T_LAUNCHED, k] += W_ONE
        if not (ok and 0.0 <= px <= Lx and 0.0 <= py <= Ly and 0.0 <= pz <= Lz):
            for k in range(K):
                tally[T_MISSED, k] += W_ONE
            continue
        w_start = np.int64(W_ONE)
        if not matched and surface:
            spec, ux, uy, uz = _enter_top(n_out, nref, ux, uy, uz, w_start)
            for k in range(K):
                tally[T_SPECULAR, k] += spec
            w_start -= spec
            if w_start == 0:
                continue
        for k in range(K):
            q[k] = w_start
            nr[k] = 0
            done[k] = 0.0
            e[k] = 1.0
            w[k] = w_start / W_ONE
            lr[k] = math.log(w[k] / weight_threshold) / mua[k]
        check = _INF
        for k in range(K):
            check = min(check, lr[k])
        vox = _voxel(px, py, pz, inv_dx, inv_dy, inv_dz, nx, ny, nz)
        L = 0.0
        pend = 0.0  # path in the voxel ``vox`` not settled yet
        alive = True
        while alive:
            s0, s1, s2, s3, tau = next_exponential(s0, s1, s2, s3)
            while True:  # one free path; only a move leaving the cuboid is cut at its face
                s = tau * inv_mus
                qx = px + s * ux
                qy = py + s * uy
                qz = pz + s * uz
                leaving = not (0.0 <= qx <= Lx and 0.0 <= qy <= Ly and 0.0 <= qz <= Lz)
                if leaving:
                    axis, s, ua, qx, qy, qz = _cut_at_face(px, py, pz, ux, uy, uz, Lx, Ly, Lz)
                nvox = _voxel(qx, qy, qz, inv_dx, inv_dy, inv_dz, nx, ny, nz)
                if nvox == vox:  # the move stayed in the voxel: add the path up
                    pend += s
                else:
                    if pend > 0.0:
                        flush(q, w, e, mua, pend, acc[fold[vox]], done)
                        pend = 0.0
                    s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                    n_alive = _spread(q, w, e, mua, s, r1, px, py, pz, ux, uy, uz,
                                      inv_dx, inv_dy, inv_dz, nx, ny, nz, fold, acc)
                    vox = nvox
                    if n_alive == 0:  # every weight below the fixed-point resolution
                        alive = False
                L += s
                px = qx
                py = qy
                pz = qz
                if not alive or not leaving:
                    break
                if not matched:
                    rf, cat = _fresnel(nref, n_out, abs(ua))
                    s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                    if r1 < rf:  # reflected back in: go on with the optical depth left
                        ux, uy, uz = _mirror(ux, uy, uz, axis)
                        tau = max(tau - mus * s, 0.0)
                        continue
                if pend > 0.0:
                    flush(q, w, e, mua, pend, acc[fold[vox]], done)
                    pend = 0.0
                slot = (T_TOP if uz < 0.0 else T_BOTTOM) if axis == 2 else T_SIDES
                for k in range(K):
                    tally[slot, k] += q[k]
                alive = False
                break
            if not alive:
                break
            # ------------------------------------------------------ scattering event
            s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
            cost = _hg_cos(g, r1)
            s0, s1, s2, s3, cosp, sinp = next_azimuth(s0, s1, s2, s3)
            ux, uy, uz = _spin_cs(ux, uy, uz, cost, cosp, sinp)
            if L > check:
                # some weights fell below the threshold: settle each of them up to here, then
                # roulette each of those weights on its own
                dst = acc[fold[vox]]
                for k in range(K):
                    if q[k] == 0 or L <= lr[k]:
                        continue
                    settle(q, w, e, mua, k, pend, dst, done)
                    if q[k] == 0:  # below the fixed-point resolution already
                        continue
                    if roulette:
                        r1 = counter_double(seed, _ip, kid[k], nr[k])
                        nr[k] += 1
                        if r1 < chance:
                            w[k] /= chance
                            lr[k] = math.log(w[k] / weight_threshold) / mua[k]
                            qn = np.int64(W_ONE * w[k] * e[k])
                            tally[T_ROULETTE, k] += qn - q[k]
                            q[k] = qn
                        else:
                            tally[T_ROULETTE, k] -= q[k]
                            q[k] = 0
                    else:  # no roulette: the last bit of weight is absorbed where it is
                        dst[k] += q[k]
                        q[k] = 0
                check = _INF
                for k in range(K):
                    if q[k] > 0:
                        check = min(check, lr[k])
                if check == _INF:
                    break
