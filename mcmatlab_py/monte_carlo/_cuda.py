"""The voxel Monte Carlo on an NVIDIA GPU, through numba's CUDA target (MCmatlab's ``useGPU``).

The same photon physics as the CPU kernel (:mod:`mcmatlab_py.monte_carlo._kernel`): the step
functions of :mod:`mcmatlab_py.monte_carlo._steps`, the launch of :mod:`mcmatlab_py.light._sources` and
the generator of :mod:`mcmatlab_py._rng` are the very same ``@numba.njit`` functions,
which numba's CUDA target compiles again as device functions when a CUDA kernel calls
them. Only the transport loop is written out here, as the CPU kernel's without the hooks
of the optional outputs (those raise :class:`~mcmatlab_py.NotBuiltError` on the GPU).

Each CUDA thread runs one random stream of ``PHOTONS_PER_THREAD`` packets, seeded from
``(seed, stream)`` as a CPU batch. Weights are the same fixed-point integers: the energy
balance is exact, and since integer atomic additions commute, a seed gives the same
totals on any GPU. They are not bit-identical to the CPU kernel's (a CPU batch holds
``MC.batch_size`` packets, and the GPU's ``log``, ``sqrt`` and fused multiply-adds round
differently): the two agree statistically.

This module imports ``numba.cuda`` (the ``numba-cuda`` package, the ``gpu`` extra); set
``NUMBA_ENABLE_CUDASIM=1`` before that import to run the kernel on numba's CUDA simulator
(plain Python threads: slow, for tests on machines without a GPU).
"""

import math

import numba
import numpy as np
from numba import cuda

from .._rng import next_double, seed_stream
from ..light._sources import SI_SURFACE, launch, sample_pwl
from ._steps import (
    _clamp,
    _cross_interface,
    _fresnel,
    _hg_cos,
    _interface_normal,
    _mirror,
    _plane_distance,
    _spin,
)
from ._tally import (
    FLU_ONE,
    KILLRANGE,
    N_TALLY,
    RANDOM_ROUNDING_BELOW,
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
    split_deposit,
)

if numba.config.ENABLE_CUDASIM:
    # The simulator runs the kernel below as Python on wrapped arrays, which the compiled CPU
    # functions cannot take: hand them the wrapped numpy arrays.
    def _unwrapping(f):
        def call(*args):
            return f(*(getattr(a, "_ary", a) for a in args))

        return call

    launch, _interface_normal, sample_pwl = map(_unwrapping, (launch, _interface_normal,
                                                              sample_pwl))
    _next_double_cpu = next_double

    def next_double(s0, s1, s2, s3):  # noqa: F811 (numba returns the state as Python ints)
        return _next_double_cpu(np.uint64(s0), np.uint64(s1), np.uint64(s2), np.uint64(s3))

PHOTONS_PER_THREAD = 32  #: packets per CUDA thread (one random stream each)
THREADS_PER_BLOCK = 128

_INF = np.inf
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


# A copy of the transport loop of _kernel.transport_batch, kept apart on purpose: numba.cuda
# device code cannot call the CPU's @numba.njit functions (nor their fixed-point atomics
# and prefetch), so the loop is written again with cuda.jit device steps. A change to the
# physics there is made here too (tests/test_mc_gpu.py compares the two statistically).
@cuda.jit(fastmath=_FASTMATH)
def transport_streams(
    M, mua, mus, g, nref, uniform_medium, nx, ny, nz, dx, dy, dz,
    boundary_type, n_out, matched, roulette, weight_threshold, chance,
    si, sf, stab, svox, phase_idx, phase_tab, normals, use_normals,
    seed, per_thread, n_total, stream_start, n_streams, acc, tally, track, flu,
):  # fmt: skip
    """Thread ``t`` runs the packets of stream ``stream_start + t``, adding into ``acc`` and
    ``tally`` (int64 fixed point, atomically). Arguments as
    :func:`mcmatlab_py.monte_carlo._kernel.transport_batch`, with ``phase_idx`` an array (-1: HG) and
    ``track`` an array (all False: no track-length tally; ``flu`` then unused)."""
    t = cuda.grid(1)
    if t >= n_streams:
        return
    b = stream_start + t
    Lx = nx * dx
    Ly = ny * dy
    Lz = nz * dz
    w_thr = np.int64(weight_threshold * W_ONE)
    fscale = FLU_ONE / (W_ONE * math.sqrt(dx * dx + dy * dy + dz * dz))
    s0, s1, s2, s3 = seed_stream(seed, b)
    st = cuda.local.array(4, numba.uint64)
    tl = cuda.local.array(N_TALLY, numba.int64)  # this thread's tallies
    for k in range(N_TALLY):
        tl[k] = 0
    surface = si[SI_SURFACE] == 1
    n_table = phase_tab.shape[1] // 2
    first = b * per_thread
    last = min(first + per_thread, n_total)
    for _ in range(first, last):
        # ---------------------------------------------------------------- launch
        st[0] = s0
        st[1] = s1
        st[2] = s2
        st[3] = s3
        px, py, pz, ux, uy, uz, ok = launch(si, sf, stab, svox, nx, ny, nz, dx, dy, dz, st)
        s0 = st[0]
        s1 = st[1]
        s2 = st[2]
        s3 = st[3]
        w = np.int64(W_ONE)
        tl[T_LAUNCHED] += w
        # the part of a fixed-point unit not yet deposited: carried on, so that rounding
        # down at each interaction does not bias NA where mua / (mua + mus) is tiny
        due = 0.0
        if boundary_type == 3:
            px = px - Lx * math.floor(px / Lx)
            py = py - Ly * math.floor(py / Ly)
        if not (ok and 0.0 <= px <= Lx and 0.0 <= py <= Ly and 0.0 <= pz <= Lz):
            tl[T_MISSED] += w
            continue
        ix = _clamp(int(math.floor(px / dx)), nx)
        iy = _clamp(int(math.floor(py / dy)), ny)
        iz = _clamp(int(math.floor(pz / dz)), nz)
        m = M[(ix * ny + iy) * nz + iz]
        if not matched:
            if surface:
                rf, cat = _fresnel(n_out, nref[m], uz)
                spec = np.int64(rf * w)
                tl[T_SPECULAR] += spec
                w -= spec
                if w == 0:
                    continue
                if uz < 1.0:
                    ratio = n_out / nref[m]
                    ux *= ratio
                    uy *= ratio
                    uz = cat
            elif nref[m] == _INF:
                tl[T_MISSED] += w
                continue
        npk = nref[m]  # the packet's own refractive index (see _mc_kernel)
        inside = True
        alive = True
        j = 0
        # ------------------------------------------------------------- hop loop
        while alive:
            s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
            tau = -math.log(1.0 - r1)
            while True:
                m = M[(_clamp(ix, nx) * ny + _clamp(iy, ny)) * nz + _clamp(iz, nz)]
                mut = mua[m] + mus[m]
                fast = inside and uniform_medium >= 0
                if fast:
                    d0 = (Lx - px) / ux if ux > 0.0 else (-px / ux if ux < 0.0 else _INF)
                    d1 = (Ly - py) / uy if uy > 0.0 else (-py / uy if uy < 0.0 else _INF)
                    d2 = (Lz - pz) / uz if uz > 0.0 else (-pz / uz if uz < 0.0 else _INF)
                    d0 = max(d0, 0.0)
                    d1 = max(d1, 0.0)
                    d2 = max(d2, 0.0)
                else:
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
                if tau < mut * dmin:  # interaction before the plane
                    s = tau / mut
                    if inside and track[m]:
                        cuda.atomic.add(flu, (ix * ny + iy) * nz + iz,
                                        np.int64(w * (s * fscale) + 0.5))
                    px += s * ux
                    py += s * uy
                    pz += s * uz
                    if fast:
                        ix = _clamp(int(math.floor(px / dx)), nx)
                        iy = _clamp(int(math.floor(py / dy)), ny)
                        iz = _clamp(int(math.floor(pz / dz)), nz)
                    break
                if dmin == _INF:
                    tl[T_KILLED] += w
                    alive = False
                    break
                tau -= mut * dmin
                if inside and track[m]:
                    cuda.atomic.add(flu, (ix * ny + iy) * nz + iz,
                                    np.int64(w * (dmin * fscale) + 0.5))
                px += dmin * ux
                py += dmin * uy
                pz += dmin * uz
                if axis == 0:
                    sgn = 1 if ux > 0.0 else -1
                    if fast:
                        ix = 0 if sgn < 0 else nx - 1
                    px = (ix + 1) * dx if sgn > 0 else ix * dx
                    inew = ix + sgn
                    nax = nx
                elif axis == 1:
                    sgn = 1 if uy > 0.0 else -1
                    if fast:
                        iy = 0 if sgn < 0 else ny - 1
                    py = (iy + 1) * dy if sgn > 0 else iy * dy
                    inew = iy + sgn
                    nax = ny
                else:
                    sgn = 1 if uz > 0.0 else -1
                    if fast:
                        iz = 0 if sgn < 0 else nz - 1
                    pz = (iz + 1) * dz if sgn > 0 else iz * dz
                    inew = iz + sgn
                    nax = nz
                if fast:
                    if axis != 0:
                        ix = _clamp(int(math.floor(px / dx)), nx)
                    if axis != 1:
                        iy = _clamp(int(math.floor(py / dy)), ny)
                    if axis != 2:
                        iz = _clamp(int(math.floor(pz / dz)), nz)
                if not inside:
                    if axis == 0:
                        ix = inew
                    elif axis == 1:
                        iy = inew
                    else:
                        iz = inew
                    inside = 0 <= ix < nx and 0 <= iy < ny and 0 <= iz < nz
                    continue
                if 0 <= inew < nax:  # an internal voxel face
                    if axis == 0:
                        mnew = M[(inew * ny + iy) * nz + iz]
                    elif axis == 1:
                        mnew = M[(ix * ny + inew) * nz + iz]
                    else:
                        mnew = M[(ix * ny + iy) * nz + inew]
                    if not matched and nref[mnew] != npk:
                        ua = ux if axis == 0 else (uy if axis == 1 else uz)
                        cin = abs(ua)
                        smooth = False
                        gx = 0.0
                        gy = 0.0
                        gz = 0.0
                        if use_normals:
                            gx, gy, gz = _interface_normal(normals, M, nref, nref[mnew], px, py,
                                                           pz, nx, ny, nz, dx, dy, dz)
                            gn = math.sqrt(gx * gx + gy * gy + gz * gz)
                            ga = gx if axis == 0 else (gy if axis == 1 else gz)
                            if gn > 0.0 and ga * sgn > 0.0:
                                gx /= gn
                                gy /= gn
                                gz /= gn
                                c = gx * ux + gy * uy + gz * uz
                                if c > 0.0:
                                    smooth = True
                                    cin = min(1.0, c)
                        if smooth or npk == nref[m]:
                            rf, cat = _fresnel(npk, nref[mnew], cin)
                            s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                            ux, uy, uz, npk, stays = _cross_interface(
                                ux, uy, uz, smooth, gx, gy, gz, cin, cat, npk, nref[mnew],
                                r1 < rf, axis, sgn)
                            if stays:
                                continue
                    if axis == 0:
                        ix = inew
                    elif axis == 1:
                        iy = inew
                    else:
                        iz = inew
                    continue
                # ------------------------------------------- a face of the cuboid
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
                if boundary_type == 3 and axis != 2:  # cyclic side
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
                        rf, cat = _fresnel(npk, n_out, abs(ua))
                        s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                        if r1 < rf:
                            ux, uy, uz = _mirror(ux, uy, uz, axis)
                            continue
                    if top:
                        tl[T_TOP] += w
                    elif bottom:
                        tl[T_BOTTOM] += w
                    else:
                        tl[T_SIDES] += w
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
            # ------------------------------------------------ interaction
            j = (_clamp(ix, nx) * ny + _clamp(iy, ny)) * nz + _clamp(iz, nz)
            m = M[j]
            mut = mua[m] + mus[m]
            wd = w * (mua[m] / mut) + due
            rr = 0.0  # small deposits are rounded at random: unbiased in this voxel
            if wd < RANDOM_ROUNDING_BELOW:
                s0, s1, s2, s3, rr = next_double(s0, s1, s2, s3)
            dep, due = split_deposit(wd, w, rr)
            w -= dep
            if inside:
                cuda.atomic.add(acc, j, dep)
            else:
                tl[T_OUTSIDE_ABSORBED] += dep
                if (
                    abs(px / Lx - 0.5) > 0.5 * KILLRANGE
                    or abs(py / Ly - 0.5) > 0.5 * KILLRANGE
                    or abs(pz / Lz - 0.5) > 0.5 * KILLRANGE
                ):
                    tl[T_KILLED] += w
                    break
            s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
            s0, s1, s2, s3, r2 = next_double(s0, s1, s2, s3)
            row = phase_idx[m]
            if row < 0:
                cost = _hg_cos(g[m], r1)
            else:
                cost = math.cos(math.pi * sample_pwl(phase_tab[row], 0, n_table, r1))
            ux, uy, uz = _spin(ux, uy, uz, cost, 2.0 * math.pi * r2)
            if w < w_thr:
                if roulette:
                    s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                    if r1 < chance:
                        gain = np.int64(w / chance) - w
                        tl[T_ROULETTE] += gain
                        w += gain
                    else:
                        tl[T_ROULETTE] -= w
                        break
                else:
                    if inside:
                        cuda.atomic.add(acc, j, w)
                    else:
                        tl[T_OUTSIDE_ABSORBED] += w
                    break
    for k in range(N_TALLY):
        if tl[k] != 0:
            cuda.atomic.add(tally, k, tl[k])
