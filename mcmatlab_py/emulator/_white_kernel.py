"""Numba kernel of the perturbation ("white") Monte Carlo: one run, many absorptions.

In a homogeneous block the scattering path of a packet does not depend on ``mua``:
sampling free paths with ``mus`` alone and treating absorption as a continuous loss
along the path (microscopic Beer-Lambert) gives, from the same path, an unbiased
estimate of the absorbed power for every ``mua_k`` at once (Sassaroli & Fantini 2004,
"Comment on the modified Beer-Lambert law for scattering media", Phys. Med. Biol.
49:N255; Alerstam et al. 2008, "White Monte Carlo for time-resolved photon
migration", J. Biomed. Opt. 13:041304). After a path length ``L`` the packet's weight
for ``mua_k`` is

.. math:: W_k(L) = w_k \\, e^{-\\mu_{a,k} L},

where ``w_k`` only changes at launch (specular loss) and in Russian roulette. Between
two voxel-face crossings at path lengths ``L_a < L_b`` the packet deposits
``W_k(L_a) - W_k(L_b)`` in the voxel it was in (the track-length estimator), so the
exponentials are evaluated once per voxel crossing, not per scattering event.

Roulette is per ``k``: when ``W_k`` falls below the weight threshold that weight alone
survives with the roulette chance (and is divided by it) or dies, so each ``k`` is
unbiased on its own and the strongly absorbing ones stop costing exponentials early;
the packet lives until its last weight dies or it escapes. The threshold test is on the
path length (``L > ln(w_k / threshold) / mua_k``), without an exponential.

Weights are fixed-point integers as in :mod:`mcmatlab_py.monte_carlo._kernel` (``W_ONE`` is 1):
``q_k = int(W_ONE w_k e^{-mua_k L})`` at every crossing, and the deposits are the
differences of successive ``q_k``, so a packet's deposits plus its escape add up to its
launch weight exactly for every ``k``, and the integer sums make the result for a seed
bit-identical for any number of threads. Voxel walk, sources, Fresnel reflection at the
escaping faces (mismatched interfaces), the boundary types and the kill range are those
of :mod:`mcmatlab_py.monte_carlo._kernel`.

Several media (issue #19, part 2): the scattering path then depends on every medium's
``mus`` and ``g`` but still on no ``mua``, so one run per scattering state of the media
gives every ``mua_k`` of one medium (the *estimated* one) with the others' ``mua`` fixed.
The weight after partial path lengths ``L_m`` in medium ``m`` is

.. math:: W_k = w_k \\, \\exp\\Big(-\\sum_m \\mu_{a,m,k} L_m\\Big),

with ``mua_tab[m, k]`` the ``mua_k`` of the estimated medium and the fixed value of every
other medium. The deposits stay per voxel crossing (one medium per voxel). The roulette
test uses the slowest decay rate of ``k`` over the media, ``rate[k]``: it is exact for one
medium and, for several, only a conservative first check (the weight itself is then
compared with the threshold). Refraction between media is not built (the Python layer
requires one refractive index for all media, or matched interfaces).
"""

import math

import numba
import numpy as np

from .._rng import counter_double, next_double, photon_stream
from ..light._sources import SI_SURFACE, launch_from
from ..monte_carlo._atomic import fetch_add
from ..monte_carlo._steps import _clamp, _enter_top, _fresnel, _hg_cos, _mirror, _plane_distance, _spin
from ..monte_carlo._tally import (
    KILLRANGE,
    N_TALLY,
    T_BOTTOM,
    T_KILLED,
    T_LAUNCHED,
    T_MISSED,
    T_OUTSIDE_ABSORBED,
    T_ROULETTE,
    T_SIDES,
    T_SPECULAR,
    T_TOP,
    W_ONE,
)
from ._white_steps import flush as _flush
from ._white_steps import settle
from ._white_uniform import white_uniform_batch

__all__ = ["N_TALLY", "W_ONE", "run_white_batches", "white_batch"]

_INF = np.inf
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _next_check(q, lr):
    """The path length at which the next live weight falls below the threshold."""
    m = _INF
    for k in range(q.size):
        if q[k] > 0 and lr[k] < m:
            m = lr[k]
    return m


# Near-copy of monte_carlo._kernel.transport_batch, kept apart on purpose: the white run
# tallies another quantity (one weight per tabulated mua, decayed along the path, with its
# own roulette), and folding it into the direct kernel would put that per-mua work in the
# inner loop of every direct run. The shared steps (_steps, _tally, launch) are imported.
@numba.njit(cache=True, fastmath=_FASTMATH)
def white_batch(
    b, mua_tab, rate, kid, Mf, mus, g, nref, nx, ny, nz, dx, dy, dz,
    boundary_type, n_out, matched, roulette, weight_threshold, chance,
    si, sf, stab, svox, fold, seed, batch_size, n_total, acc, tally,
):  # fmt: skip
    """Run the photons of batch ``b`` for all absorptions ``mua_tab[:, k]`` at once.

    Parameters
    ----------
    mua_tab : (n_media, K) float64 absorption coefficient (cm^-1) of each medium for each
        ``k``, all > 0: the estimated medium's row holds the ``mua_k``, the others' rows
        their fixed value.
    rate : (K,) the smallest ``mua_tab[m, k]`` over the media in the grid (cm^-1).
    kid : (K,) uint64 what keys the roulette numbers of ``k`` (the bits of its ``mua``), so
        that a weight's numbers do not depend on the other weights of the run.
    Mf : (nx*ny*nz,) uint8 or int32 medium index of each voxel (C order; kernel_args).
    mus, g : (n_media,) scattering coefficient (cm^-1) and anisotropy of each medium.
    nref : the refractive index of every medium (one value).
    boundary_type, n_out, matched, roulette, weight_threshold, chance : as
        :func:`mcmatlab_py.monte_carlo._kernel.transport_batch`.
    si, sf, stab, svox : the source (:mod:`mcmatlab_py.light._sources`).
    fold : (nx*ny*nz,) int64, the row of ``acc`` of each voxel (C order): the identity,
        or the voxel's orbit under the symmetries of block and beam, which sums the
        mirror images as it runs and keeps ``acc`` small enough for the caches.
    acc : (n_rows, K) int64 absorbed fixed-point weight per row and ``mua_k``.
    tally : (N_TALLY, K) int64, the ``T_*`` totals of :mod:`mcmatlab_py.monte_carlo._kernel` per ``k``.
    """
    K = rate.size
    multi = mus.size > 1
    Lx = nx * dx
    Ly = ny * dy
    Lz = nz * dz
    st = np.empty(4, dtype=np.uint64)
    surface = si[SI_SURFACE] == 1
    q = np.zeros(K, dtype=np.int64)  # fixed-point weight of each k
    w = np.zeros(K)  # weight_k = w[k] exp(-mua[k] L)
    lr = np.zeros(K)  # path length at which weight_k falls below the threshold
    e = np.zeros(K)  # exp(-mua_k (L - pend)) of each k
    nr = np.zeros(K, dtype=np.int64)  # roulettes of each k so far in this photon
    done = np.zeros(K)  # the part of ``pend`` each k has had (settled for its roulette)
    first = b * batch_size
    last = min(first + batch_size, n_total)
    for _ip in range(first, last):
        s0, s1, s2, s3 = photon_stream(seed, _ip)  # each photon its own path stream
        s0, s1, s2, s3, px, py, pz, ux, uy, uz, ok = launch_from(
            si, sf, stab, svox, nx, ny, nz, dx, dy, dz, st, s0, s1, s2, s3)
        for k in range(K):
            tally[T_LAUNCHED, k] += W_ONE
        if boundary_type == 3:
            px = px - Lx * math.floor(px / Lx)
            py = py - Ly * math.floor(py / Ly)
        if not (ok and 0.0 <= px <= Lx and 0.0 <= py <= Ly and 0.0 <= pz <= Lz):
            for k in range(K):
                tally[T_MISSED, k] += W_ONE
            continue
        ix = _clamp(int(math.floor(px / dx)), nx)
        iy = _clamp(int(math.floor(py / dy)), ny)
        iz = _clamp(int(math.floor(pz / dz)), nz)
        m = Mf[(ix * ny + iy) * nz + iz]
        w_start = np.int64(W_ONE)
        if not matched:
            if surface:
                spec, ux, uy, uz = _enter_top(n_out, nref, ux, uy, uz, w_start)
                for k in range(K):
                    tally[T_SPECULAR, k] += spec
                w_start -= spec
                if w_start == 0:
                    continue
            elif nref == _INF:
                for k in range(K):
                    tally[T_MISSED, k] += W_ONE
                continue
        for k in range(K):
            q[k] = w_start
            nr[k] = 0
            done[k] = 0.0
            e[k] = 1.0
            w[k] = w_start / W_ONE
            lr[k] = math.log(w[k] / weight_threshold) / rate[k]
        check = _next_check(q, lr)
        L = 0.0  # path length travelled
        pend = 0.0  # path length since the last deposit
        inside = True
        alive = True
        while alive:
            s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
            tau = -math.log(1.0 - r1)  # scattering optical depth to the next event
            while True:
                m = Mf[(_clamp(ix, nx) * ny + _clamp(iy, ny)) * nz + _clamp(iz, nz)]
                mus_m = mus[m]
                d0 = _plane_distance(px, ux, ix, nx, dx)
                d1 = _plane_distance(py, uy, iy, ny, dy)
                d2 = _plane_distance(pz, uz, iz, nz, dz)
                if d0 <= d1 and d0 <= d2:
                    axis = 0
                    dmin = d0
                elif d1 <= d2:
                    axis = 1
                    dmin = d1
                else:
                    axis = 2
                    dmin = d2
                if tau < mus_m * dmin:  # scattering before the plane
                    s = tau / mus_m
                    px += s * ux
                    py += s * uy
                    pz += s * uz
                    L += s
                    pend += s
                    break
                if dmin == _INF:  # outside, moving away: lost
                    _flush(q, w, e, mua_tab[m], pend, tally[T_OUTSIDE_ABSORBED], done)
                    pend = 0.0
                    for k in range(K):
                        tally[T_KILLED, k] += q[k]
                    alive = False
                    break
                tau -= mus_m * dmin
                px += dmin * ux
                py += dmin * uy
                pz += dmin * uz
                L += dmin
                pend += dmin
                # leaving this voxel (or this stretch outside): deposit what was lost in it
                if inside:
                    n_alive = _flush(q, w, e, mua_tab[m], pend,
                                     acc[fold[(ix * ny + iy) * nz + iz]], done)
                    pend = 0.0
                else:
                    n_alive = _flush(q, w, e, mua_tab[m], pend, tally[T_OUTSIDE_ABSORBED], done)
                    pend = 0.0
                if n_alive == 0:  # every weight below the fixed-point resolution
                    alive = False
                    break
                if axis == 0:
                    sgn = 1 if ux > 0.0 else -1
                    px = (ix + 1) * dx if sgn > 0 else ix * dx
                    inew = ix + sgn
                    nax = nx
                elif axis == 1:
                    sgn = 1 if uy > 0.0 else -1
                    py = (iy + 1) * dy if sgn > 0 else iy * dy
                    inew = iy + sgn
                    nax = ny
                else:
                    sgn = 1 if uz > 0.0 else -1
                    pz = (iz + 1) * dz if sgn > 0 else iz * dz
                    inew = iz + sgn
                    nax = nz
                if (not inside) or 0 <= inew < nax:  # one refractive index: no refraction
                    if axis == 0:
                        ix = inew
                    elif axis == 1:
                        iy = inew
                    else:
                        iz = inew
                    if not inside:
                        inside = 0 <= ix < nx and 0 <= iy < ny and 0 <= iz < nz
                    continue
                top = axis == 2 and sgn < 0
                bottom = axis == 2 and sgn > 0
                if boundary_type == 1:
                    escaping = True
                elif boundary_type == 2:
                    escaping = top
                elif boundary_type == 3:
                    escaping = top or bottom
                else:
                    escaping = False
                if boundary_type == 3 and axis != 2:
                    if axis == 0:
                        ix = 0 if sgn > 0 else nx - 1
                        px = 0.0 if sgn > 0 else Lx
                    else:
                        iy = 0 if sgn > 0 else ny - 1
                        py = 0.0 if sgn > 0 else Ly
                    continue
                if escaping:
                    if not matched:
                        ua = ux if axis == 0 else (uy if axis == 1 else uz)
                        rf, cat = _fresnel(nref, n_out, abs(ua))
                        s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                        if r1 < rf:
                            ux, uy, uz = _mirror(ux, uy, uz, axis)
                            continue
                    slot = T_TOP if top else (T_BOTTOM if bottom else T_SIDES)
                    for k in range(K):
                        tally[slot, k] += q[k]
                    alive = False
                    break
                if axis == 0:
                    ix = inew
                elif axis == 1:
                    iy = inew
                else:
                    iz = inew
                inside = False
            if not alive:
                break
            # ------------------------------------------------------ scattering event
            if not inside and (
                abs(px / Lx - 0.5) > 0.5 * KILLRANGE
                or abs(py / Ly - 0.5) > 0.5 * KILLRANGE
                or abs(pz / Lz - 0.5) > 0.5 * KILLRANGE
            ):
                _flush(q, w, e, mua_tab[m], pend, tally[T_OUTSIDE_ABSORBED], done)
                pend = 0.0
                for k in range(K):
                    tally[T_KILLED, k] += q[k]
                break
            s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
            s0, s1, s2, s3, r2 = next_double(s0, s1, s2, s3)
            ux, uy, uz = _spin(ux, uy, uz, _hg_cos(g[m], r1), 2.0 * math.pi * r2)
            if L > check:
                # some weights fell below the threshold: settle each of them up to here,
                # then roulette each of those weights on its own
                if inside:
                    dst = acc[fold[(ix * ny + iy) * nz + iz]]
                else:
                    dst = tally[T_OUTSIDE_ABSORBED]
                for k in range(K):
                    if q[k] == 0 or L <= lr[k]:
                        continue
                    settle(q, w, e, mua_tab[m], k, pend, dst, done)
                    if q[k] == 0:  # below the fixed-point resolution already
                        continue
                    if multi and w[k] * e[k] >= weight_threshold:
                        # decayed slower than the bound: check again where it can be below
                        lr[k] = L + math.log(w[k] * e[k] / weight_threshold) / rate[k]
                        continue
                    if roulette:
                        r1 = counter_double(seed, _ip, kid[k], nr[k])
                        nr[k] += 1
                        if r1 < chance:
                            w[k] /= chance
                            if multi:
                                lr[k] = L + math.log(w[k] * e[k] / weight_threshold) / rate[k]
                            else:  # as before several media (the same numbers)
                                lr[k] = math.log(w[k] / weight_threshold) / rate[k]
                            qn = np.int64(W_ONE * w[k] * e[k])
                            tally[T_ROULETTE, k] += qn - q[k]
                            q[k] = qn
                        else:
                            tally[T_ROULETTE, k] -= q[k]
                            q[k] = 0
                    else:  # no roulette: the last bit of weight is absorbed where it is
                        dst[k] += q[k]
                        q[k] = 0
                check = _next_check(q, lr)
                if check == _INF:
                    break


@numba.njit(cache=True, parallel=True)
def run_white_batches(
    mua_tab, rate, kid, Mf, mus, g, nref, nx, ny, nz, dx, dy, dz,
    boundary_type, n_out, matched, roulette, weight_threshold, chance,
    si, sf, stab, svox, fold, seed, batch_size, n_total, batch_start, batch_stop, acc, tally,
    uniform=-1,
):  # fmt: skip
    """Run batches ``[batch_start, batch_stop)`` on ``acc.shape[0]`` workers.

    ``uniform``: the medium that fills the grid when every face is escaping (then
    :func:`mcmatlab_py.emulator._white_uniform.white_uniform_batch` runs), else -1.

    ``acc`` is (n_workers, n_rows, K) and ``tally`` (n_workers, N_TALLY, K), one slice per
    worker; batches are claimed from an atomic counter as in
    :func:`mcmatlab_py.monte_carlo._kernel.run_batches`, so the integer totals depend only on the
    seed, never on the number of threads.
    """
    n_workers = acc.shape[0]
    counter = np.zeros(1, dtype=np.int64)
    for kw in numba.prange(n_workers):
        while True:
            b = batch_start + fetch_add(counter, 0, 1)
            if b >= batch_stop:
                break
            if uniform >= 0:
                white_uniform_batch(
                    b, mua_tab[uniform], kid, mus[uniform], g[uniform], nref, nx, ny, nz,
                    dx, dy, dz, n_out, matched, roulette, weight_threshold, chance,
                    si, sf, stab, svox, fold, seed, batch_size, n_total, acc[kw], tally[kw],
                )  # fmt: skip
            else:
                white_batch(
                    b, mua_tab, rate, kid, Mf, mus, g, nref, nx, ny, nz, dx, dy, dz,
                    boundary_type, n_out, matched, roulette, weight_threshold, chance,
                    si, sf, stab, svox, fold, seed, batch_size, n_total, acc[kw], tally[kw],
                )  # fmt: skip
