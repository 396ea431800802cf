"""Numba kernel of the voxel Monte Carlo for a cuboid of one medium (the common case).

When one medium fills the grid, every boundary is an escaping face (``boundary_type
1``) and only the plain outputs are asked for, the walk needs no voxel faces: the packet
moves a whole free path at once and only a path that ends outside the cuboid is cut at
the face it crosses. :func:`mcmatlab_py.monte_carlo._kernel.run_batches` then runs
:func:`transport_uniform_batch` instead of the general kernel. It computes the same
physics as :func:`mcmatlab_py.monte_carlo._kernel.transport_batch` (same launch, fixed-point
weights, deposits, Fresnel at the faces, roulette and escape tallies), faster:

* the optics are scalars, and the voxel of an interaction is found from its position
  (no face distances, no divisions per step);
* the free path's optical depth comes from an exponential ziggurat
  (:func:`mcmatlab_py._rng.next_exponential`, no logarithm) and the azimuth from a point
  in the unit disc (:func:`mcmatlab_py._rng.next_azimuth`, no sine or cosine).

It draws its random numbers in another order than the general kernel, so a seed gives
other (statistically equal) numbers; the result still depends only on ``(seed, batch)``,
so it is the same for any number of threads.
"""

import numba
import numpy as np

from .._rng import next_azimuth, next_double, next_exponential, seed_stream
from ..light._sources import SI_SURFACE, launch_from
from . import _tally
from ._steps import _cut_at_face, _enter_top, _fresnel, _hg_cos, _mirror, _spin_cs
from ._tally import T_BOTTOM, T_LAUNCHED, T_MISSED, T_ROULETTE, T_SIDES, T_SPECULAR, T_TOP, W_ONE

_INF = np.inf
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@numba.njit(cache=True, inline="always")
def uniform_path_applies(uniform_medium, boundary_type, nref, mua, mus, phase_idx):
    """Whether :func:`transport_uniform_batch` can run a plain run: one medium, every face
    escaping, a finite refractive index, a positive attenuation, Henyey-Greenstein."""
    if uniform_medium < 0 or boundary_type != 1:
        return False
    m = uniform_medium
    if not (nref[m] < _INF and mua[m] + mus[m] > 0.0):
        return False
    if phase_idx is None:
        return True
    return phase_idx[m] < 0


@numba.njit(cache=True, fastmath=_FASTMATH)
def transport_uniform_batch(
    b, m, mua, mus, g, nref, nx, ny, nz, dx, dy, dz, n_out, matched,
    roulette, weight_threshold, chance, si, sf, stab, svox, seed, batch_size, n_total,
    acc, tally,
):  # fmt: skip
    """Run the photons of batch ``b`` in the medium ``m`` that fills the grid.

    The arguments are those of :func:`mcmatlab_py.monte_carlo._kernel.transport_batch`; ``acc``
    (nx*ny*nz,) and ``tally`` are int64 fixed-point weights, updated in place.
    """
    Lx = nx * dx
    Ly = ny * dy
    Lz = nz * dz
    inv_dx = 1.0 / dx
    inv_dy = 1.0 / dy
    inv_dz = 1.0 / dz
    mut = mua[m] + mus[m]
    inv_mut = 1.0 / mut
    frac = mua[m] / mut  # fraction of the weight absorbed at an interaction
    gm = g[m]
    nm = nref[m]
    w_thr = np.int64(weight_threshold * W_ONE)
    s0, s1, s2, s3 = seed_stream(seed, b)
    st = np.empty(4, dtype=np.uint64)  # the random state, for the launch kernel
    surface = si[SI_SURFACE] == 1
    first = b * batch_size
    last = min(first + batch_size, n_total)
    for _ in range(first, last):
        # ---------------------------------------------------------------- launch
        s0, s1, s2, s3, px, py, pz, ux, uy, uz, ok = launch_from(
            si, sf, stab, svox, nx, ny, nz, dx, dy, dz, st, s0, s1, s2, s3)
        w = np.int64(W_ONE)
        tally[T_LAUNCHED] += w
        # the part of a fixed-point unit not yet deposited: carried on, so that rounding
        # down at each interaction does not bias NA where mua / (mua + mus) is tiny
        due = 0.0
        if not (ok and 0.0 <= px <= Lx and 0.0 <= py <= Ly and 0.0 <= pz <= Lz):
            tally[T_MISSED] += w
            continue
        if not matched and surface and n_out > 0.0:  # n_out = 0: MCmatlab's faces
            # specular reflection at the top face, Fresnel at the ray's angle; refraction
            spec, ux, uy, uz = _enter_top(n_out, nm, ux, uy, uz, w)
            tally[T_SPECULAR] += spec
            w -= spec
            if w == 0:
                continue
        # ------------------------------------------------------------- hop loop
        while True:
            s0, s1, s2, s3, tau = next_exponential(s0, s1, s2, s3)
            escaped = False
            while True:  # move; only a path that leaves the cuboid is cut at its face
                s = tau * inv_mut
                qx = px + s * ux
                qy = py + s * uy
                qz = pz + s * uz
                if 0.0 <= qx <= Lx and 0.0 <= qy <= Ly and 0.0 <= qz <= Lz:
                    px = qx
                    py = qy
                    pz = qz
                    break
                axis, dmin, ua, px, py, pz = _cut_at_face(px, py, pz, ux, uy, uz, Lx, Ly, Lz)
                if not matched and n_out > 0.0:
                    rf, cat = _fresnel(nm, n_out, abs(ua))
                    s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                    if r1 < rf:  # reflected back in: go on with the optical depth left
                        ux, uy, uz = _mirror(ux, uy, uz, axis)
                        tau = max(tau - mut * dmin, 0.0)
                        continue
                if axis == 2:
                    tally[T_TOP if uz < 0.0 else T_BOTTOM] += w
                else:
                    tally[T_SIDES] += w
                escaped = True
                break
            if escaped:
                break
            # ------------------------------------------------ interaction
            ix = min(int(px * inv_dx), nx - 1)
            iy = min(int(py * inv_dy), ny - 1)
            iz = min(int(pz * inv_dz), nz - 1)
            j = (ix * ny + iy) * nz + iz
            wd = w * frac + due
            rr = 0.0  # small deposits are rounded at random: unbiased in this voxel
            if wd < _tally.RANDOM_ROUNDING_BELOW:
                s0, s1, s2, s3, rr = next_double(s0, s1, s2, s3)
            dep, due = _tally.split_deposit(wd, w, rr)
            w -= dep
            acc[j] += dep
            s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
            cost = _hg_cos(gm, r1)
            s0, s1, s2, s3, cosp, sinp = next_azimuth(s0, s1, s2, s3)
            ux, uy, uz = _spin_cs(ux, uy, uz, cost, cosp, sinp)
            if w < w_thr:
                if roulette:
                    s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                    if r1 < chance:
                        gain = np.int64(w / chance) - w
                        tally[T_ROULETTE] += gain
                        w += gain
                    else:
                        tally[T_ROULETTE] -= w
                        break
                else:  # no roulette: the last bit of weight is absorbed where it is
                    acc[j] += w
                    break

