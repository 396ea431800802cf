"""Numba kernel of the voxel Monte Carlo (arrays and scalars only).

Photon packets as in MCML (Wang, Jacques & Zheng 1995) and MCmatlab (Marti et al. 2018):
exponential free paths in optical depth, Henyey-Greenstein scattering, implicit capture
(the packet loses ``w * mua / mut`` at each interaction), Russian roulette below a weight
threshold. Weights are fixed-point integers (:mod:`mcmatlab_py.monte_carlo._tally`), so
the same seed gives bit-identical ``NA`` for any number of threads. The photon's voxel
is tracked as integer indices that change by +-1 when it crosses a voxel face (a 3-D
DDA), never recomputed by truncating a possibly negative coordinate: the bug of the
public mcxyz code that piles energy into the first voxel layer of the -x and -y faces.
(A free move ends inside the cuboid, where truncation is the floor.) Coordinates are
local: ``0 <= px <= Lx`` etc. (the Python layer shifts x and y by ``L/2``).

Within the safety distance ``safe`` of its voxel (:mod:`mcmatlab_py.monte_carlo.safety`)
a packet moves a whole free path at once; within one voxel of a change of medium it
walks face by face. Sources are launched by :mod:`mcmatlab_py.light._sources`; refraction
and reflection are described in :mod:`mcmatlab_py.monte_carlo._steps`, the optional
outputs (compiled in only when ``oi`` is an array) in :mod:`mcmatlab_py.monte_carlo._outputs`.
"""

import math

import numba
import numpy as np

from .._rng import next_azimuth, next_double, next_exponential, seed_stream
from ..light._sources import SI_SURFACE, launch_from, sample_pwl
from . import _outputs as O
from ._prefetch import deposit_late
from ._steps import (
    _FASTMATH,
    _INF,
    _clamp,
    _cross_interface,
    _cut_at_face_r,
    _enter_top,
    _fresnel,
    _hg_cos,
    _interface_normal,
    _mirror,
    _nearest_plane,
    _reciprocals,
    _refract_face,
    _spin_cs,
)
from ._tally import (
    KILLRANGE,
    RANDOM_ROUNDING_BELOW,
    T_ABSORBED_EXCLUDED,
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
    fluence_scale,
    split_deposit,
)
from ._track import track_walk


@numba.njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def transport_batch(
    b, M, safe, majorant, mua, mus, g, nref, nx, ny, nz, dx, dy, dz,
    boundary_type, n_out, matched, roulette, weight_threshold, chance,
    si, sf, stab, svox, phase_idx, phase_tab, normals, use_normals,
    seed, batch_size, n_total, acc, tally, oi, of, consider, ext, paths, path_n,
    track=None, flu=None,
):  # fmt: skip
    """Run the photons of batch ``b`` and add their weights into ``acc`` and ``tally``.

    Parameters
    ----------
    M : (nx*ny*nz,) uint8 (int32 beyond 256 media), medium index per voxel, C order of
        (nx, ny, nz).
    safe : (nx*ny*nz,) float32 cm, how far a packet in each voxel may move without meeting
        a voxel of another kind of medium (:func:`mcmatlab_py.monte_carlo.safety.safety_distances`).
        Negative: the packet crosses that ball by delta tracking
        (:func:`mcmatlab_py.monte_carlo.safety.navigation_safety`).
    majorant : (n_media,) float64 cm^-1, the largest ``mua + mus`` of each medium's group of
        delta tracking (:func:`mcmatlab_py.monte_carlo.safety.delta_groups`).
    mua, mus, g, nref : (n_media,) float64 optical properties (cm^-1, -, -).
    boundary_type : 0 none escape, 1 all escape, 2 top escapes, 3 top and bottom
        escape with cyclic sides (MCmatlab).
    si, sf, stab, svox : the source (:mod:`mcmatlab_py.light._sources`).
    phase_idx : (n_media,) int32, row of ``phase_tab`` of a tabulated phase function, or -1.
    phase_tab : (n_tables, 2 L) float64 density and cumulative of the scattering angle.
    normals : (nx*ny*nz*3,) float32 smoothed interface normals, used if ``use_normals``.
    acc : (nx*ny*nz,) int64 absorbed fixed-point weight, updated in place.
    tally : (N_TALLY,) int64, updated in place.
    oi, of, consider, ext, paths, path_n : the optional outputs (:mod:`mcmatlab_py.monte_carlo._outputs`);
        ``oi = None`` compiles them out.
    track : (n_media,) bool, media whose fluence is tallied along the path (track length),
        or None (compiled out); a move through several voxels is split among them
        (:func:`mcmatlab_py.monte_carlo._track.track_walk`).
    flu : (nx*ny*nz,) int64, the track-length tally: weight times length, ``FLU_ONE`` per
        launched packet crossing a voxel's diagonal (:func:`fluence_scale`).
    """
    Lx = nx * dx
    Ly = ny * dy
    Lz = nz * dz
    w_thr = np.int64(weight_threshold * W_ONE)
    s0, s1, s2, s3 = seed_stream(seed, b)
    st = np.empty(4, dtype=np.uint64)  # the random state, for the launch kernel
    surface = si[SI_SURFACE] == 1
    n_table = phase_tab.shape[1] // 2
    first = b * batch_size
    last = min(first + batch_size, n_total)
    fscale = fluence_scale(dx, dy, dz)
    inv_dx = 1.0 / dx
    inv_dy = 1.0 / dy
    inv_dz = 1.0 / dz
    absorb = np.zeros(mua.size)  # the fraction of the weight absorbed at an interaction
    for k in range(mua.size):
        if mua[k] + mus[k] > 0.0:
            absorb[k] = mua[k] / (mua[k] + mus[k])
    # per-packet state of the optional outputs (unused, and optimised away, when oi is None)
    cnt = np.zeros(4, dtype=np.int64)  # scatterings, reflections, refractions, transitions
    rec = np.empty((1, 2), dtype=np.int64)  # deposits awaiting the end-of-life criteria
    if oi is not None:
        rec = np.empty((256, 2), dtype=np.int64)
    n_paths = 0
    dc_end = False
    if oi is not None:
        n_paths = oi[O.OI_N_PATHS]
        dc_end = oi[O.OI_DC] == 1 and oi[O.OI_DC_END] == 1
    for ip in range(first, last):
        # ---------------------------------------------------------------- launch
        s0, s1, s2, s3, px, py, pz, ux, uy, uz, ok = launch_from(
            si, sf, stab, svox, nx, ny, nz, dx, dy, dz, st, s0, s1, s2, s3)
        w = np.int64(W_ONE)
        tally[T_LAUNCHED] += w
        if boundary_type == 3:  # cyclic sides: fold the entry point into the face
            px = px - Lx * math.floor(px / Lx)
            py = py - Ly * math.floor(py / Ly)
        if not (ok and 0.0 <= px <= Lx and 0.0 <= py <= Ly and 0.0 <= pz <= Lz):
            tally[T_MISSED] += w
            continue
        t_opl = 0.0  # optical path (cm): time of flight times c
        # the part of a fixed-point unit not yet deposited: carried on, so that rounding
        # down at each interaction does not bias NA where mua / (mua + mus) is tiny
        due = 0.0
        wrap_x = 0  # cyclic wraps, to unfold the exit point for the radial tallies
        wrap_y = 0
        n_rec = 0
        fate = O.FATE_KILLED
        record_path = False
        if oi is not None:
            cnt[:] = 0
            record_path = ip < n_paths
        ix = _clamp(int(math.floor(px / dx)), nx)
        iy = _clamp(int(math.floor(py / dy)), ny)
        iz = _clamp(int(math.floor(pz / dz)), nz)
        m = M[(ix * ny + iy) * nz + iz]
        if not matched:
            if surface and n_out > 0.0:
                # specular reflection at the top face, Fresnel at the ray's angle; refraction
                # (n_out = 0: MCmatlab's faces, which neither reflect nor refract)
                spec, ux, uy, uz = _enter_top(n_out, nref[m], ux, uy, uz, w)
                tally[T_SPECULAR] += spec
                w -= spec
                if w == 0:
                    continue
            elif nref[m] == _INF:  # emitted inside a perfect reflector: no light leaves it
                tally[T_MISSED] += w
                continue
        # the packet's own refractive index: its voxel's, except after a reflection off a
        # smoothed interface that sends it on through the other medium's voxels (MCmatlab)
        npk = nref[m]
        inside = True
        alive = True
        rs = 0.0  # the packet's safety: how far it may move freely, 0 if unknown
        delta = False  # whether that ball is crossed by delta tracking
        rux = ruy = ruz = 0.0  # 1 / (ux, uy, uz), computed where needed once u changes
        pj = 0  # the deposit not yet added, and its voxel
        pdep = np.int64(0)
        mut = 0.0
        j = 0
        if oi is not None:
            if record_path:
                O.path_point(paths, path_n, ip, px, py, pz, w / W_ONE)
        # ------------------------------------------------------------- hop loop
        while alive:
            stale = True  # (rux, ruy, ruz) are not those of the new direction
            # the optical depth to the next interaction, by the ziggurat (no logarithm)
            s0, s1, s2, s3, tau = next_exponential(s0, s1, s2, s3)
            while True:  # move until tau is used up or the photon dies
                if not (rs > 0.0 and tau < mut * rs):
                    # the voxel's medium, and how far the packet may move in it freely
                    ixc = _clamp(ix, nx)
                    iyc = _clamp(iy, ny)
                    izc = _clamp(iz, nz)
                    j = (ixc * ny + iyc) * nz + izc
                    m = M[j]
                    if inside and (matched or npk == nref[m]):
                        sv = np.float64(safe[j])
                        # a larger ball of the same rate at once; one of another rate
                        # (delta tracking or not) only once this one is used up: the look-up
                        # came because tau exceeds mut * rs, and the rest of tau would be
                        # biased at another rate (a dermis layer would absorb 0.9% too little)
                        if abs(sv) > rs and (rs == 0.0 or (sv < 0.0) == delta):
                            rs = abs(sv)
                            delta = sv < 0.0
                    else:
                        rs = 0.0
                    # a ball of delta tracking draws its paths at the group's majorant
                    mut = majorant[m] if rs > 0.0 and delta else mua[m] + mus[m]
                if rs > 0.0:
                    # a free move: no voxel of another kind of medium lies within rs of the
                    # packet (mcmatlab_py.monte_carlo.safety); only the cuboid's faces can stop it. An
                    # interaction within rs leaves the rest of that ball to the next move, and
                    # the medium of a kind as the packet's: no look-up
                    hit = tau < mut * rs
                    s = tau / mut if hit else rs
                    qx = px + s * ux
                    qy = py + s * uy
                    qz = pz + s * uz
                    cut = not (0.0 <= qx <= Lx and 0.0 <= qy <= Ly and 0.0 <= qz <= Lz)
                    if cut:  # it leaves the cuboid: cut at the face, which is met below
                        stale, rux, ruy, ruz = _reciprocals(stale, ux, uy, uz, rux, ruy, ruz)
                        axis, s, ua, qx, qy, qz = _cut_at_face_r(px, py, pz, ux, uy, uz, rux,
                                                                 ruy, ruz, Lx, Ly, Lz)
                        hit = False
                    if track is not None:
                        if track[m]:
                            stale, rux, ruy, ruz = _reciprocals(stale, ux, uy, uz, rux, ruy,
                                                                ruz)
                            track_walk(flu, w, fscale, px, py, pz, ux, uy, uz, rux, ruy, ruz,
                                       s, ix, iy, iz, nx, ny, nz, dx, dy, dz)
                    if oi is not None:
                        t_opl += s * (1.0 if matched else npk)
                    px = qx
                    py = qy
                    pz = qz
                    ix = min(int(px * inv_dx), nx - 1)
                    iy = min(int(py * inv_dy), ny - 1)
                    iz = min(int(pz * inv_dz), nz - 1)
                    if hit:
                        rs -= s
                        j = (ix * ny + iy) * nz + iz
                        if delta:
                            # a tentative interaction: real with probability (mua + mus) /
                            # majorant of the medium here, else null (the packet goes on)
                            mh = M[j]
                            s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                            if r1 * mut >= mua[mh] + mus[mh]:
                                s0, s1, s2, s3, tau = next_exponential(s0, s1, s2, s3)
                                continue
                            m = mh
                        break
                    rs = 0.0
                    tau = max(tau - mut * s, 0.0)
                    if not cut:
                        continue
                    sgn = 1 if ua > 0.0 else -1
                    if axis == 0:
                        inew = ix + sgn
                    elif axis == 1:
                        inew = iy + sgn
                    else:
                        inew = iz + sgn
                else:
                    # ------------------------------------ one voxel face at a time
                    stale, rux, ruy, ruz = _reciprocals(stale, ux, uy, uz, rux, ruy, ruz)
                    axis, dmin = _nearest_plane(px, py, pz, ux, uy, uz, rux, ruy, ruz, ix, iy,
                                                iz, nx, ny, nz, dx, dy, dz)
                    if tau < mut * dmin:  # interaction before the plane
                        s = tau / mut
                        if track is not None:
                            if inside and track[m]:
                                flu[j] += np.int64(w * (s * fscale) + 0.5)
                        if oi is not None:
                            t_opl += s * (1.0 if matched else npk)
                        px += s * ux
                        py += s * uy
                        pz += s * uz
                        break
                    if dmin == _INF:  # outside, moving away in vacuum: lost
                        tally[T_KILLED] += w
                        alive = False
                        break
                    tau -= mut * dmin
                    if track is not None:
                        if inside and track[m]:
                            flu[j] += np.int64(w * (dmin * fscale) + 0.5)
                    if oi is not None:
                        t_opl += dmin * (1.0 if matched else npk)
                    px += dmin * ux
                    py += dmin * uy
                    pz += dmin * uz
                    # land exactly on the plane crossed and find the neighbour voxel (the side
                    # from the reciprocal's sign: LLVM hoists that of u to every new direction)
                    if axis == 0:
                        sgn = 1 if rux > 0.0 else -1
                        px = (ix + 1) * dx if sgn > 0 else ix * dx
                        inew = ix + sgn
                    elif axis == 1:
                        sgn = 1 if ruy > 0.0 else -1
                        py = (iy + 1) * dy if sgn > 0 else iy * dy
                        inew = iy + sgn
                    else:
                        sgn = 1 if ruz > 0.0 else -1
                        pz = (iz + 1) * dz if sgn > 0 else iz * dz
                        inew = iz + sgn
                    if not inside:
                        # outside the cuboid on this axis: re-entry or move along outside
                        if axis == 0:
                            ix = inew
                        elif axis == 1:
                            iy = inew
                        else:
                            iz = inew
                        inside = 0 <= ix < nx and 0 <= iy < ny and 0 <= iz < nz
                        continue
                    nax = nx if axis == 0 else (ny if axis == 1 else nz)
                    if 0 <= inew < nax:
                        # internal voxel face
                        if axis == 0:
                            mnew = M[(inew * ny + iy) * nz + iz]
                        elif axis == 1:
                            mnew = M[(ix * ny + inew) * nz + iz]
                        else:
                            mnew = M[(ix * ny + iy) * nz + inew]
                        refracting = not matched and nref[mnew] != npk
                        if oi is not None:
                            if mnew != m and not refracting and consider[mnew]:
                                cnt[3] += 1
                        if refracting:
                            ua = ux if axis == 0 else (uy if axis == 1 else uz)
                            cin = abs(ua)
                            smooth = False
                            gx = 0.0
                            gy = 0.0
                            gz = 0.0
                            if use_normals:
                                gx, gy, gz = _interface_normal(normals, M, nref, nref[mnew], px,
                                                               py, pz, nx, ny, nz, dx, dy, dz)
                                gn = math.sqrt(gx * gx + gy * gy + gz * gz)
                                ga = gx if axis == 0 else (gy if axis == 1 else gz)
                                if gn > 0.0 and ga * sgn > 0.0:
                                    gx /= gn
                                    gy /= gn
                                    gz /= gn
                                    c = gx * ux + gy * uy + gz * uz
                                    if c > 0.0:  # else the smoothed surface faces away: the face
                                        smooth = True
                                        cin = min(1.0, c)
                            if smooth or npk == nref[m]:
                                # (a packet passing through the other medium's voxels meets no
                                # face of its own where no smoothed interface is: MCmatlab)
                                rf, cat = _fresnel(npk, nref[mnew], cin)
                                s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                                if oi is not None:
                                    if consider[mnew]:
                                        if r1 < rf:
                                            cnt[1] += 1
                                        else:
                                            cnt[2] += 1
                                            cnt[3] += 1
                                    if record_path:
                                        O.path_point(paths, path_n, ip, px, py, pz, w / W_ONE)
                                ux, uy, uz, npk, stays = _cross_interface(
                                    ux, uy, uz, smooth, gx, gy, gz, cin, cat, npk, nref[mnew],
                                    r1 < rf, axis, sgn)
                                stale = True
                                if stays:  # reflected back into its voxel
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
                if boundary_type == 3 and axis != 2:
                    # cyclic side: re-enter through the opposite face
                    if axis == 0:
                        ix = 0 if sgn > 0 else nx - 1
                        px = 0.0 if sgn > 0 else Lx
                    else:
                        iy = 0 if sgn > 0 else ny - 1
                        py = 0.0 if sgn > 0 else Ly
                    if oi is not None:
                        if axis == 0:
                            wrap_x += sgn
                        else:
                            wrap_y += sgn
                        if record_path:  # a NaN vertex breaks the polyline at the jump
                            O.path_point(paths, path_n, ip, np.nan, np.nan, np.nan, np.nan)
                            O.path_point(paths, path_n, ip, px, py, pz, w / W_ONE)
                    continue
                if escaping:
                    faces = n_out > 0.0  # 0: MCmatlab's faces, no Fresnel at the cuboid
                    if not matched and faces:
                        ua = ux if axis == 0 else (uy if axis == 1 else uz)
                        rf, cat = _fresnel(npk, n_out, abs(ua))
                        s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
                        if r1 < rf:
                            ux, uy, uz = _mirror(ux, uy, uz, axis)
                            stale = True
                            if oi is not None:
                                if record_path:
                                    O.path_point(paths, path_n, ip, px, py, pz, w / W_ONE)
                            continue
                        if oi is not None:  # the direction outside, refracted into n_out
                            ux, uy, uz = _refract_face(ux, uy, uz, npk / n_out, cat, axis, sgn)
                    if oi is not None:
                        if record_path:
                            O.path_point(paths, path_n, ip, px, py, pz, w / W_ONE)
                        # without face Fresnel the packet goes on in its own medium, and, as
                        # MCmatlab's, reaches far field and collector only from n = 1
                        fate = O.record_escape(
                            oi, of, ext, cnt, px, py, pz, ux, uy, uz, w, t_opl,
                            1.0 if matched else (n_out if faces else npk), axis, sgn,
                            ix, iy, iz, nx, ny, nz,
                            px + wrap_x * Lx - of[O.OF_X0], py + wrap_y * Ly - of[O.OF_Y0],
                            matched or faces or npk == 1.0)
                    if top:
                        tally[T_TOP] += w
                    elif bottom:
                        tally[T_BOTTOM] += w
                    else:
                        tally[T_SIDES] += w
                    alive = False
                    break
                # non-escaping face: continue outside in the nearest voxel's medium
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
            # (in voxel j, of medium m or of one of its kind)
            wd = w * absorb[m] + due
            rr = 0.0  # small deposits are rounded at random: unbiased in this voxel
            if wd < RANDOM_ROUNDING_BELOW:
                s0, s1, s2, s3, rr = next_double(s0, s1, s2, s3)
            dep, due = split_deposit(wd, w, rr)
            w -= dep
            if inside:
                if oi is None:
                    pj, pdep = deposit_late(acc, M, safe, pj, pdep, j, dep)
                elif dc_end:
                    rec = O.push_record(rec, n_rec, j, dep)
                    n_rec += 1
                elif O.criteria_met(oi, cnt, fate, False):
                    pj, pdep = deposit_late(acc, M, safe, pj, pdep, j, dep)
                else:
                    tally[T_ABSORBED_EXCLUDED] += dep
            else:
                tally[T_OUTSIDE_ABSORBED] += dep
                if (
                    abs(px / Lx - 0.5) > 0.5 * KILLRANGE
                    or abs(py / Ly - 0.5) > 0.5 * KILLRANGE
                    or abs(pz / Lz - 0.5) > 0.5 * KILLRANGE
                ):
                    tally[T_KILLED] += w
                    break
            if oi is not None:
                if consider[m] and mus[m] > 0.0:  # mus = 0: the packet was absorbed, not scattered
                    cnt[0] += 1
                if record_path:
                    O.path_point(paths, path_n, ip, px, py, pz, w / W_ONE)
            # the azimuth from a point in the unit disc (no sine or cosine), drawn before the
            # deflection: the one-medium kernel draws them the other way round
            s0, s1, s2, s3, cosp, sinp = next_azimuth(s0, s1, s2, s3)
            s0, s1, s2, s3, r1 = next_double(s0, s1, s2, s3)
            if phase_idx is None:  # no tabulated phase function: pruned at compile time
                cost = _hg_cos(g[m], r1)
            else:
                row = phase_idx[m]
                if row < 0:
                    cost = _hg_cos(g[m], r1)
                else:
                    cost = math.cos(math.pi * sample_pwl(phase_tab[row], 0, n_table, r1))
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
                else:
                    # no roulette: the last bit of weight is absorbed where it is
                    if inside:
                        if oi is None:
                            acc[j] += w
                        elif dc_end:
                            rec = O.push_record(rec, n_rec, j, w)
                            n_rec += 1
                        elif O.criteria_met(oi, cnt, fate, False):
                            acc[j] += w
                        else:
                            tally[T_ABSORBED_EXCLUDED] += w
                    else:
                        tally[T_OUTSIDE_ABSORBED] += w
                    break
        acc[pj] += pdep  # the last deposit (0 if none is pending)
        if oi is not None:
            if dc_end:  # MCmatlab's evaluateOnlyAtEndOfLife: the whole path, or nothing
                met = O.criteria_met(oi, cnt, fate, True)
                # as MCmatlab's, the deposits count times the packet's final weight
                tally[T_ABSORBED_EXCLUDED] += O.flush_record(rec, n_rec, acc, met,
                                                             w / W_ONE)
