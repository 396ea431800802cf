"""Numba kernels that launch one photon packet of a light source (arrays and scalars only).

The Python layer (:mod:`mcmatlab_py.light.source`) packs a source into four arrays:

* ``si`` (``SI_SIZE``,) int64: the kind of source and of its distributions, and where
  the tables of custom distributions lie in ``tab``;
* ``sf`` (``SF_SIZE``,) float64: focus (local cm: the cuboid spans ``[0, L]`` on every
  axis), the beam axis ``u`` and the transverse axes ``v``, ``w``, widths;
* ``tab`` (k,) float64: tables of piecewise-linear densities (:func:`sample_pwl`), and
  the cumulative distribution of the emitting voxels of a 3-D source;
* ``vox`` (n,) int64: flat indices (C order of (nx, ny, nz)) of the emitting voxels.

:func:`launch` returns a packet's position and direction. Beams (as MCmatlab's kernel)
draw a point of the focal plane (the plane through the focus normal to ``u``) from the
focal-plane intensity distribution, a direction from the angular one, and start the
packet where the line through that point along that direction crosses the plane
``z = 0``: beams with a focus below the surface converge inside the tissue.

The random state is a (4,) uint64 array (xoshiro256**, :mod:`mcmatlab_py._rng`), updated
in place: the caller copies its local state in and out once per packet.
"""

import math

import numba
import numpy as np

from .._rng import next_double, seed_stream

# source kinds (si[SI_KIND]); 0..4 keep their historical meaning and arithmetic
SRC_PENCIL = 0  #: collimated along +z, at the focus (x, y)
SRC_TOPHAT = 1  #: collimated along +z, uniform disc of radius sf[SF_RADIUS]
SRC_GAUSSIAN = 2  #: collimated along +z, Gaussian of 1/e^2 radius sf[SF_RADIUS]
SRC_PLANE_WAVE = 3  #: uniform over the top face, along u
SRC_ISOTROPIC = 4  #: isotropic point (length 0) or line along u centred on the focus
SRC_BEAM = 5  #: a focused beam: focal-plane and angular distributions (si[SI_NEAR], si[SI_FAR])
SRC_VOLUME = 6  #: isotropic emission from voxels weighted by a 3-D array

# near-field (focal plane) layouts, si[SI_NEAR]
NEAR_POINT = 0  #: every ray through the focus
NEAR_RADIAL = 1  #: radius from distribution si[SI_D1] of width sf[SF_NW1], uniform azimuth
NEAR_XY = 2  #: X along v from si[SI_D1], Y along w from si[SI_D2]
NEAR_LG01 = 3  #: Laguerre-Gaussian LG01 ring, outer 1/e^2 radius sf[SF_NW1]

# far-field (angular) layouts, si[SI_FAR]
FAR_NONE = 0  #: every ray along u
FAR_RADIAL = 1  #: polar angle from si[SI_D3] (width sf[SF_FW1]), uniform azimuth
FAR_XY = 2  #: tan of the angles in the (u, v) and (u, w) planes from si[SI_D3], si[SI_D4]
FAR_LG01 = 3  #: LG01: rays skewed about the azimuthal direction of their focal point

# one-dimensional distributions (MCmatlab's codes 0, 1, 2; then custom arrays)
D_TOPHAT = 0
D_GAUSSIAN = 1
D_LAMBERTIAN = 2
D_CUSTOM = 3

# layout of si
SI_KIND = 0
SI_SURFACE = 1  #: 1: enters through the top face (beams), 0: emitted inside
SI_NEAR = 2
SI_FAR = 3
SI_D1 = 4  #: distribution codes of near 1 (radial or X), near 2 (Y), far 1, far 2
SI_D2 = 5
SI_D3 = 6
SI_D4 = 7
SI_TAB = 8  #: (offset, length) in tab of the custom tables of D1..D4: 8 entries
SI_VOX_OFF = 16  #: offset in tab of the cumulative distribution over vox (length n + 1)
SI_VOX_N = 17  #: number of emitting voxels
SI_SIZE = 18

# layout of sf
SF_F = 0  #: focus, local cm (3)
SF_U = 3  #: beam axis (3)
SF_V = 6  #: transverse axis of X (3)
SF_W = 9  #: transverse axis of Y (3)
SF_LENGTH = 12  #: cm, line emitter length
SF_NW1 = 13  #: cm, near-field width 1 (radial or X)
SF_NW2 = 14  #: cm, near-field width 2 (Y)
SF_FW1 = 15  #: far-field width 1: tan of the half-angle (rad for LG01)
SF_FW2 = 16  #: far-field width 2
SF_LG01 = 17  #: LG01: ratio of the ring's outer 1/e^2 radius to the Gaussian w
SF_RADIUS = 18  #: cm, radius of the SRC_TOPHAT and SRC_GAUSSIAN beams
SF_SIZE = 19


@numba.njit(cache=True, inline="always")
def rand(st):
    """One uniform double in [0, 1) from the state array ``st`` (updated in place)."""
    s0, s1, s2, s3, r = next_double(st[0], st[1], st[2], st[3])
    st[0] = s0
    st[1] = s1
    st[2] = s2
    st[3] = s3
    return r


@numba.njit(cache=True)
def _upper(cdf, off, n, xi):
    """Largest k in [0, n - 2] with ``cdf[off + k] <= xi`` (cdf non-decreasing, n >= 2)."""
    lo = 0
    hi = n - 1  # invariant: cdf[lo] <= xi < cdf[hi] (cdf[n - 1] = 1 > xi)
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if cdf[off + mid] <= xi:
            lo = mid
        else:
            hi = mid
    return lo


@numba.njit(cache=True)
def sample_pwl(tab, off, n, xi):
    """Sample t in [0, 1] from a piecewise-linear density, exactly, with one uniform ``xi``.

    ``tab[off : off + n]`` holds the density at the nodes ``t_i = i / (n - 1)`` and
    ``tab[off + n : off + 2 n]`` its cumulative integral normalised to 1 (see
    :func:`mcmatlab_py.light.source.pwl_table`). The bin is found by bisection; within
    it the density is linear, its integral a quadratic, solved in the cancellation-free
    form ``t = 2 c / (q0 + sqrt(q0^2 + 2 (q1 - q0) c))``. The position of ``xi`` inside
    its bin is again uniform, so one number serves both steps.
    """
    k = _upper(tab, off + n, n, xi)
    c0 = tab[off + n + k]
    c1 = tab[off + n + k + 1]
    frac = (xi - c0) / (c1 - c0) if c1 > c0 else 0.0
    q0 = tab[off + k]
    q1 = tab[off + k + 1]
    c = frac * 0.5 * (q0 + q1)  # area to cover inside the bin (bin width 1)
    den = q0 + math.sqrt(max(0.0, q0 * q0 + 2.0 * (q1 - q0) * c))
    tloc = 2.0 * c / den if den > 0.0 else frac
    return (k + min(1.0, max(0.0, tloc))) / (n - 1)


@numba.njit(cache=True)
def _radial(kind, width, si, tab, slot, st):
    """A radius (or tan of a polar angle) from a radial distribution; uses 1 number.

    Top-hat: uniform over the disc of radius ``width``; Gaussian: intensity
    ``exp(-2 r^2 / width^2)``; custom: the array gives intensity per area at
    ``r_i = width * i / (n - 1)`` (the table holds ``r_i * I_i``).
    """
    xi = rand(st)
    if kind == D_TOPHAT:
        return width * math.sqrt(xi)
    if kind == D_GAUSSIAN:
        return width * math.sqrt(-0.5 * math.log(1.0 - xi))
    return width * sample_pwl(tab, si[SI_TAB + 2 * slot], si[SI_TAB + 2 * slot + 1], xi)


@numba.njit(cache=True)
def _linear(kind, width, si, tab, slot, st):
    """A signed offset in [-width, width] (Gaussian: unbounded) from a 1-D distribution.

    Top-hat: uniform; Gaussian: intensity ``exp(-2 x^2 / width^2)`` (standard deviation
    width / 2, by Box-Muller: 2 numbers); custom: the array over [-width, width].
    """
    xi = rand(st)
    if kind == D_TOPHAT:
        return width * (2.0 * xi - 1.0)
    if kind == D_GAUSSIAN:
        xi2 = rand(st)
        return 0.5 * width * math.sqrt(-2.0 * math.log(1.0 - xi)) * math.cos(2.0 * math.pi * xi2)
    t = sample_pwl(tab, si[SI_TAB + 2 * slot], si[SI_TAB + 2 * slot + 1], xi)
    return width * (2.0 * t - 1.0)


@numba.njit(cache=True)
def _gamma2(st):
    """A Gamma(2, 1) variate (density s e^-s) as a sum of two exponentials: 2 numbers."""
    return -math.log((1.0 - rand(st)) * (1.0 - rand(st)))


@numba.njit(cache=True, fastmath={"nsz", "arcp", "contract", "afn", "reassoc"})
def launch(si, sf, tab, vox, nx, ny, nz, dx, dy, dz, st):
    """Position (local cm) and unit direction of one new packet.

    Returns ``(px, py, pz, ux, uy, uz, ok)``; ``ok`` is False for a ray that cannot
    enter through the top face (it points up or along it), whatever its position.
    Whether the position lies on the cuboid is the caller's test.
    """
    kind = si[SI_KIND]
    Lx = nx * dx
    Ly = ny * dy
    if kind == SRC_ISOTROPIC or kind == SRC_VOLUME:
        if kind == SRC_ISOTROPIC:
            px = sf[SF_F]
            py = sf[SF_F + 1]
            pz = sf[SF_F + 2]
            length = sf[SF_LENGTH]
            if length > 0.0:  # a point source draws no position (its numbers as before)
                s = (rand(st) - 0.5) * length
                px += s * sf[SF_U]
                py += s * sf[SF_U + 1]
                pz += s * sf[SF_U + 2]
        else:
            n = si[SI_VOX_N]
            j = vox[_upper(tab, si[SI_VOX_OFF], n + 1, rand(st))]
            iz = j % nz
            iy = (j // nz) % ny
            ix = j // (ny * nz)
            px = (ix + rand(st)) * dx
            py = (iy + rand(st)) * dy
            pz = (iz + rand(st)) * dz
        r1 = rand(st)
        r2 = rand(st)
        uz = 2.0 * r1 - 1.0
        st_ = math.sqrt(max(0.0, 1.0 - uz * uz))
        ux = st_ * math.cos(2.0 * math.pi * r2)
        uy = st_ * math.sin(2.0 * math.pi * r2)
        return px, py, pz, ux, uy, uz, True
    if kind == SRC_PLANE_WAVE:
        r1 = rand(st)
        r2 = rand(st)
        return r1 * Lx, r2 * Ly, 0.0, sf[SF_U], sf[SF_U + 1], sf[SF_U + 2], sf[SF_U + 2] > 0.0
    if kind != SRC_BEAM:  # the collimated beams along +z: pencil, top-hat, Gaussian
        rad = 0.0
        r1 = rand(st)
        r2 = rand(st)
        if kind == SRC_TOPHAT:
            rad = sf[SF_RADIUS] * math.sqrt(r1)
        elif kind == SRC_GAUSSIAN:
            rad = sf[SF_RADIUS] * math.sqrt(-0.5 * math.log(1.0 - r1))
        phi = 2.0 * math.pi * r2
        return (sf[SF_F] + rad * math.cos(phi), sf[SF_F + 1] + rad * math.sin(phi), 0.0,
                0.0, 0.0, 1.0, True)
    # ----------------------------------------------------------- a focused beam
    ux0, uy0, uz0 = sf[SF_U], sf[SF_U + 1], sf[SF_U + 2]
    vx, vy, vz = sf[SF_V], sf[SF_V + 1], sf[SF_V + 2]
    wx, wy, wz = sf[SF_W], sf[SF_W + 1], sf[SF_W + 2]
    near = si[SI_NEAR]
    far = si[SI_FAR]
    a = 0.0  # focal-plane offset along v, cm
    b = 0.0  # along w
    ca = 1.0  # cos, sin of the azimuth of the focal point (LG01 skews rays with it)
    sa = 0.0
    if near == NEAR_RADIAL:
        alpha = 2.0 * math.pi * rand(st)
        r = _radial(si[SI_D1], sf[SF_NW1], si, tab, 0, st)
        a = r * math.cos(alpha)
        b = r * math.sin(alpha)
    elif near == NEAR_XY:
        a = _linear(si[SI_D1], sf[SF_NW1], si, tab, 0, st)
        b = _linear(si[SI_D2], sf[SF_NW2], si, tab, 1, st)
    elif near == NEAR_LG01:
        alpha = 2.0 * math.pi * rand(st)
        ca = math.cos(alpha)
        sa = math.sin(alpha)
        # I(r) ~ r^2 exp(-2 r^2 / w^2): s = 2 r^2 / w^2 has density s e^-s
        r = sf[SF_NW1] / sf[SF_LG01] * math.sqrt(0.5 * _gamma2(st))
        a = r * ca
        b = r * sa
    # direction: u tilted by a polar angle towards the unit vector cos(beta) v + sin(beta) w
    dx_ = ux0
    dy_ = uy0
    dz_ = uz0
    if far == FAR_RADIAL or (far == FAR_XY and si[SI_D3] == D_LAMBERTIAN) or far == FAR_LG01:
        if far == FAR_LG01:
            theta = sf[SF_FW1] / sf[SF_LG01] * math.sqrt(0.5 * _gamma2(st))
            cb = sa  # tilt along (cos alpha v + sin alpha w) x u = sin alpha v - cos alpha w
            sb = -ca
        else:
            beta = 2.0 * math.pi * rand(st)
            cb = math.cos(beta)
            sb = math.sin(beta)
            kind1 = si[SI_D3]
            if kind1 == D_LAMBERTIAN:
                theta = math.asin(math.sqrt(rand(st)))
            else:
                theta = math.atan(_radial(kind1, sf[SF_FW1], si, tab, 2, st))
        ct = math.cos(theta)
        stt = math.sin(theta)
        dx_ = ct * ux0 + stt * (cb * vx + sb * wx)
        dy_ = ct * uy0 + stt * (cb * vy + sb * wy)
        dz_ = ct * uz0 + stt * (cb * vz + sb * wz)
    elif far == FAR_XY:
        tx = _linear(si[SI_D3], sf[SF_FW1], si, tab, 2, st)
        ty = _linear(si[SI_D4], sf[SF_FW2], si, tab, 3, st)
        dx_ = ux0 + tx * vx + ty * wx
        dy_ = uy0 + tx * vy + ty * wy
        dz_ = uz0 + tx * vz + ty * wz
        norm = math.sqrt(dx_ * dx_ + dy_ * dy_ + dz_ * dz_)
        dx_ /= norm
        dy_ /= norm
        dz_ /= norm
    # the ray through the focal point T along d starts where it crosses z = 0
    tx_ = sf[SF_F] + a * vx + b * wx
    ty_ = sf[SF_F + 1] + a * vy + b * wy
    tz_ = sf[SF_F + 2] + a * vz + b * wz
    if not dz_ > 0.0:
        return tx_, ty_, 0.0, dx_, dy_, dz_, False
    s = tz_ / dz_
    return tx_ - s * dx_, ty_ - s * dy_, 0.0, dx_, dy_, dz_, True


@numba.njit(cache=True, inline="always")
def launch_from(si, sf, tab, vox, nx, ny, nz, dx, dy, dz, st, s0, s1, s2, s3):
    """:func:`launch` for a kernel that keeps its random state in four scalars: the state
    goes through the scratch array ``st`` (4,) uint64. Returns the new state, then
    ``(px, py, pz, ux, uy, uz, ok)``."""
    st[0] = s0
    st[1] = s1
    st[2] = s2
    st[3] = s3
    px, py, pz, ux, uy, uz, ok = launch(si, sf, tab, vox, nx, ny, nz, dx, dy, dz, st)
    return st[0], st[1], st[2], st[3], px, py, pz, ux, uy, uz, ok


@numba.njit(cache=True)
def launch_many(si, sf, tab, vox, nx, ny, nz, dx, dy, dz, seed, n):
    """(n, 7) float64: ``launch`` n times from stream 0 of ``seed`` (x, y, z, ux, uy, uz, ok)."""
    out = np.empty((n, 7))
    st = np.empty(4, dtype=np.uint64)
    st[0], st[1], st[2], st[3] = seed_stream(seed, 0)
    for i in range(n):
        px, py, pz, ux, uy, uz, ok = launch(si, sf, tab, vox, nx, ny, nz, dx, dy, dz, st)
        out[i, 0] = px
        out[i, 1] = py
        out[i, 2] = pz
        out[i, 3] = ux
        out[i, 4] = uy
        out[i, 5] = uz
        out[i, 6] = 1.0 if ok else 0.0
    return out
