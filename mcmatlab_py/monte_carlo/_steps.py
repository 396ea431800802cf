"""Numba kernels of one step of photon transport: Fresnel, scattering angle, voxel planes.

Pure functions of scalars and arrays, used by :mod:`mcmatlab_py.monte_carlo._kernel`. They are
inlined into the transport loop (``inline="always"``), so moving them here costs nothing.

With mismatched
interfaces, a packet meeting a change of refractive index inside the grid is
reflected or refracted (Fresnel, Snell) about the smoothed interface normal of
MCmatlab (:func:`mcmatlab_py.monte_carlo.optics.interface_normals`) when ``use_normals`` is set,
else about the voxel face. A smoothed normal can disagree with the voxel face the
packet crosses. A packet reflected about it keeps its true direction: where that still
points into the new voxel, the packet travels on through the other medium's voxels
(with their absorption and scattering, but its own refractive index ``npk``, as
MCmatlab's ``P->RI``): a voxel of its own index is no interface to it, and another is
one only where a smoothed normal says so. (Mirroring the component normal to the face
instead sends the light reflected off the rim of Example 17's droplet up instead of out and
down: 0.00007 of the power through the sides below z = 0.0217 cm instead of the ray
trace's 0.0072, ``tests/test_mc_curved.py``.) A refracted direction that points back out of the new
voxel has that component mirrored, so that it enters the medium it refracted into.
``n = inf`` is a perfect reflector; ``g = 1`` (and -1) scatters without
(with full) deflection; a medium with a tabulated phase function (``phase_idx >= 0``)
draws the scattering angle from its table.
"""

import math

import numba
import numpy as np

from ._prefetch import opaque

_INF = np.inf
# fast-math without 'nnan'/'ninf': the kernel relies on inf distances
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _fresnel(n1, n2, ca1):
    """Fresnel reflectance for unpolarised light; returns (R, cos of transmitted angle).

    ``ca1`` is the cosine of the angle of incidence (>= 0). ``n = inf`` on either side
    is a perfect reflector.
    """
    if n1 == n2:
        return 0.0, ca1
    if n2 == _INF or n1 == _INF:
        return 1.0, 0.0
    if ca1 > 1.0 - 1e-12:
        r = (n2 - n1) / (n2 + n1)
        return r * r, ca1
    sa1 = math.sqrt(max(0.0, 1.0 - ca1 * ca1))
    sa2 = n1 * sa1 / n2
    if sa2 >= 1.0:
        return 1.0, 0.0  # total internal reflection
    ca2 = math.sqrt(1.0 - sa2 * sa2)
    cap = ca1 * ca2 - sa1 * sa2  # cos(a1 + a2)
    cam = ca1 * ca2 + sa1 * sa2  # cos(a1 - a2)
    sap = sa1 * ca2 + ca1 * sa2
    sam = sa1 * ca2 - ca1 * sa2
    r = 0.5 * sam * sam * (cam * cam + cap * cap) / (sap * sap * cam * cam)
    return r, ca2


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _enter_top(n_out, n_in, ux, uy, uz, w):
    """A packet of weight ``w`` (integer units) entering through the top face from a
    medium of index ``n_out`` into one of ``n_in``: ``(spec, ux, uy, uz)``, the weight
    reflected specularly (Fresnel at the ray's angle) and the refracted direction."""
    rf, cat = _fresnel(n_out, n_in, uz)
    spec = np.int64(rf * w)
    if uz < 1.0:
        ratio = n_out / n_in
        ux *= ratio
        uy *= ratio
        uz = cat
    return spec, ux, uy, uz


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _hg_cos(g, xi):
    """Henyey-Greenstein deflection cosine from a uniform ``xi``."""
    if g == 0.0:
        return 2.0 * xi - 1.0
    if abs(g) >= 1.0:  # the limits: no deflection, or straight back
        return g
    tmp = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi)
    c = (1.0 + g * g - tmp * tmp) / (2.0 * g)
    return min(1.0, max(-1.0, c))


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _spin(ux, uy, uz, cost, psi):
    """Rotate direction (ux, uy, uz) by polar cos ``cost`` and azimuth ``psi`` (MCML)."""
    cosp = math.cos(psi)
    # sin from cos (one transcendental fewer): psi in [0, 2 pi)
    sinp = math.sqrt(max(0.0, 1.0 - cosp * cosp))
    if psi > math.pi:
        sinp = -sinp
    return _spin_cs(ux, uy, uz, cost, cosp, sinp)


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _spin_cs(ux, uy, uz, cost, cosp, sinp):
    """Rotate direction (ux, uy, uz) by polar cos ``cost`` and the azimuth of cos ``cosp``
    and sin ``sinp`` (MCML's spin)."""
    sint = math.sqrt(max(0.0, 1.0 - cost * cost))
    if abs(uz) > 0.99999:
        return sint * cosp, sint * sinp, cost * (1.0 if uz > 0.0 else -1.0)
    temp = math.sqrt(1.0 - uz * uz)
    nux = sint * (ux * uz * cosp - uy * sinp) / temp + ux * cost
    nuy = sint * (uy * uz * cosp + ux * sinp) / temp + uy * cost
    nuz = -sint * cosp * temp + uz * cost
    return nux, nuy, nuz


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _plane_distance(p, u, i, n, d):
    """Distance along direction component ``u`` to the next voxel plane of one axis.

    ``i`` may be -1 or ``n`` for a photon outside the cuboid on that axis, where
    the only plane ahead is the cuboid face it moves towards.
    """
    if u > 0.0:
        if i >= n:
            return _INF
        return max(0.0, ((i + 1) * d - p) / u)
    if u < 0.0:
        if i < 0:
            return _INF
        return max(0.0, (i * d - p) / u)
    return _INF


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _reciprocals(stale, ux, uy, uz, rx, ry, rz):
    """``(False, 1/ux, 1/uy, 1/uz)``, ``inf`` for a zero component, computed here and now
    if ``stale`` (the direction changed), else ``(False, rx, ry, rz)``. The general kernel
    needs them only where a packet walks face by face or leaves the cuboid, not after most
    interactions; :func:`mcmatlab_py.monte_carlo._prefetch.opaque` keeps the divisions
    from being hoisted to every change of direction."""
    if stale:
        ux = opaque(ux)
        uy = opaque(uy)
        uz = opaque(uz)
        rx = 1.0 / ux if ux != 0.0 else _INF
        ry = 1.0 / uy if uy != 0.0 else _INF
        rz = 1.0 / uz if uz != 0.0 else _INF
    return False, rx, ry, rz


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _plane_distance_r(p, u, r, i, n, d):
    """:func:`_plane_distance` with the reciprocal ``r = 1 / u`` given
    (:func:`_reciprocals`): the same numbers, as fast-math's division is the product by
    the reciprocal."""
    if u > 0.0:
        if i >= n:
            return _INF
        return max(0.0, ((i + 1) * d - p) * r)
    if u < 0.0:
        if i < 0:
            return _INF
        return max(0.0, (i * d - p) * r)
    return _INF


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _nearest_plane(px, py, pz, ux, uy, uz, rx, ry, rz, ix, iy, iz, nx, ny, nz, dx, dy, dz):
    """``(axis, d)``: the axis of the first voxel plane met from ``(px, py, pz)`` in voxel
    ``(ix, iy, iz)`` along ``u`` (reciprocals ``r``, :func:`_reciprocals`) and its distance
    (cm); x before y before z on a tie."""
    d0 = _plane_distance_r(px, ux, rx, ix, nx, dx)
    d1 = _plane_distance_r(py, uy, ry, iy, ny, dy)
    d2 = _plane_distance_r(pz, uz, rz, iz, nz, dz)
    if d0 <= d1 and d0 <= d2:
        return 0, d0
    if d1 <= d2:
        return 1, d1
    return 2, d2


@numba.njit(cache=True, inline="always")
def _clamp(i, n):
    if i < 0:
        return 0
    if i >= n:
        return n - 1
    return i


@numba.njit(cache=True, fastmath=_FASTMATH)
def _interface_normal(normals, M, nref, n_new, px, py, pz, nx, ny, nz, dx, dy, dz):
    """Smoothed interface normal at a point, pointing into the medium of index ``n_new``.

    Trilinear interpolation between the 8 voxel centres around the point, over those
    whose refractive index is ``n_new`` (as MCmatlab); not normalised. ``normals`` is
    (nx*ny*nz*3,) float32.
    """
    fx = px / dx - 0.5
    fy = py / dy - 0.5
    fz = pz / dz - 0.5
    i0 = int(math.floor(fx))
    j0 = int(math.floor(fy))
    k0 = int(math.floor(fz))
    tx = fx - i0
    ty = fy - j0
    tz = fz - k0
    gx = 0.0
    gy = 0.0
    gz = 0.0
    for ci in range(2):
        i = i0 + ci
        if i < 0 or i >= nx:
            continue
        wi = tx if ci == 1 else 1.0 - tx
        for cj in range(2):
            j = j0 + cj
            if j < 0 or j >= ny:
                continue
            wj = wi * (ty if cj == 1 else 1.0 - ty)
            for ck in range(2):
                k = k0 + ck
                if k < 0 or k >= nz:
                    continue
                v = (i * ny + j) * nz + k
                if nref[M[v]] != n_new:
                    continue
                wk = wj * (tz if ck == 1 else 1.0 - tz)
                gx += wk * normals[3 * v]
                gy += wk * normals[3 * v + 1]
                gz += wk * normals[3 * v + 2]
    return gx, gy, gz


@numba.njit(cache=True, inline="always")
def _mirror(ux, uy, uz, axis):
    """Reverse the direction component along ``axis`` (a reflection off a voxel face)."""
    if axis == 0:
        return -ux, uy, uz
    if axis == 1:
        return ux, -uy, uz
    return ux, uy, -uz


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _refract_face(ux, uy, uz, ratio, cat, axis, sgn):
    """Snell's law through a voxel face: tangential components times ``n1 / n2`` (``ratio``),
    the normal one ``cat`` (cosine of the transmitted angle) along the crossing sign."""
    ux *= ratio
    uy *= ratio
    uz *= ratio
    if axis == 0:
        ux = sgn * cat
    elif axis == 1:
        uy = sgn * cat
    else:
        uz = sgn * cat
    return ux, uy, uz


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _refract_smooth(ux, uy, uz, gx, gy, gz, cin, cat, mu, axis, sgn):
    """Snell's law in vector form through the smoothed normal g (unit, into the new
    medium): ``cin`` the cosine of incidence on g, ``cat`` of transmission, ``mu = n1 /
    n2``. A refracted direction that points back out of the new voxel has the component
    normal to the voxel face crossed mirrored, so that the packet enters the medium it
    refracted into (see :mod:`mcmatlab_py.monte_carlo._kernel`)."""
    k_ = cat - mu * cin
    ux = mu * ux + k_ * gx
    uy = mu * uy + k_ * gy
    uz = mu * uz + k_ * gz
    un = math.sqrt(ux * ux + uy * uy + uz * uz)
    ux /= un
    uy /= un
    uz /= un
    ua = ux if axis == 0 else (uy if axis == 1 else uz)
    if ua * sgn <= 0.0:
        return _mirror(ux, uy, uz, axis)
    return ux, uy, uz


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _cross_interface(ux, uy, uz, smooth, gx, gy, gz, cin, cat, npk, n_new, reflected, axis,
                     sgn):
    """The packet at a change of refractive index, Fresnel's draw made (``reflected``):
    ``(ux, uy, uz, npk, stays)``, its new direction, its own refractive index, and whether
    it stays in its voxel.

    About the smoothed normal g (``smooth``, ``cin`` the cosine of incidence on it): a
    refracted packet takes ``n_new`` and enters (:func:`_refract_smooth`); a reflected one
    takes its true direction and keeps its index, and stays where that points back, else
    travels on into the new voxel in its own medium (as MCmatlab). About the voxel face:
    mirrored and stays, or refracted and enters.
    """
    if smooth:
        if not reflected:
            ux, uy, uz = _refract_smooth(ux, uy, uz, gx, gy, gz, cin, cat, npk / n_new,
                                         axis, sgn)
            return ux, uy, uz, n_new, False
        ux, uy, uz = ux - 2.0 * cin * gx, uy - 2.0 * cin * gy, uz - 2.0 * cin * gz
        ua = ux if axis == 0 else (uy if axis == 1 else uz)
        return ux, uy, uz, npk, ua * sgn <= 0.0
    if reflected:
        ux, uy, uz = _mirror(ux, uy, uz, axis)
        return ux, uy, uz, npk, True
    ux, uy, uz = _refract_face(ux, uy, uz, npk / n_new, cat, axis, sgn)
    return ux, uy, uz, n_new, False


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _cut_at_face(px, py, pz, ux, uy, uz, Lx, Ly, Lz):
    """Where a move from ``(px, py, pz)`` (inside the cuboid ``[0, L]^3``) along ``u``
    leaves it: ``(axis, d, ua, qx, qy, qz)``, the axis of the face crossed, the distance
    to it (>= 0), the direction's component along that axis and the exit point, landed
    exactly on the face (the one-medium kernels cut only such moves)."""
    rx = 1.0 / ux if ux != 0.0 else _INF
    ry = 1.0 / uy if uy != 0.0 else _INF
    rz = 1.0 / uz if uz != 0.0 else _INF
    return _cut_at_face_r(px, py, pz, ux, uy, uz, rx, ry, rz, Lx, Ly, Lz)


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def _cut_at_face_r(px, py, pz, ux, uy, uz, rx, ry, rz, Lx, Ly, Lz):
    """:func:`_cut_at_face` with the reciprocals of the direction given (:func:`_reciprocals`)."""
    d0 = (Lx - px) * rx if ux > 0.0 else (-px * rx if ux < 0.0 else _INF)
    d1 = (Ly - py) * ry if uy > 0.0 else (-py * ry if uy < 0.0 else _INF)
    d2 = (Lz - pz) * rz if uz > 0.0 else (-pz * rz if uz < 0.0 else _INF)
    if d0 <= d1 and d0 <= d2:
        axis = 0
        d = d0
        ua = ux
    elif d1 <= d2:
        axis = 1
        d = d1
        ua = uy
    else:
        axis = 2
        d = d2
        ua = uz
    d = max(d, 0.0)
    qx = px + d * ux
    qy = py + d * uy
    qz = pz + d * uz
    if axis == 0:
        qx = Lx if ux > 0.0 else 0.0
    elif axis == 1:
        qy = Ly if uy > 0.0 else 0.0
    else:
        qz = Lz if uz > 0.0 else 0.0
    return axis, d, ua, qx, qy, qz
