"""Numba kernels of the optional outputs of the Monte Carlo (arrays and scalars only).

What leaves the tissue, beyond the three escape totals of the plain run (MCmatlab's
outputs, Marti et al. 2018): the boundary irradiance maps ``NI_*``, the far field, the
light collector (objective lens image or fiber power, optionally time-resolved), MCML's
radial and angular reflectance and transmittance (Wang, Jacques & Zheng 1995), the
deposition criteria of MCmatlab's examples 19 and 25, and example photon paths.

The transport kernel calls these only when the Python layer passes an ``oi`` array; with
``oi = None`` numba prunes every call at compile time, so the plain run is unchanged.
The time of flight is the optical path from the launch point (n = 1 everywhere with matched interfaces, as in
MCmatlab) over c; MCmatlab instead starts a focused beam's clock where its wavefront
crosses the focal plane.

* ``oi`` (``OI_SIZE``,) int64: which outputs, their resolutions, the deposition criteria
  and the offsets of each output in ``ext``;
* ``of`` (``OF_SIZE``,) float64: light collector pose and optics, time window, radial bin;
* ``ext`` (n,) int64 per worker: fixed-point weights (``W_ONE`` is one packet) of every
  output, so sums are exact and independent of the thread count, as ``NA``;
* ``cnt`` (4,) int64: the packet's scatterings, reflections, refractions and interface
  transitions, counted in the media flagged by ``consider`` (MCmatlab's
  ``minMediumIdxToConsider..maxMediumIdxToConsider``);
* ``paths`` (n_paths, path_len, 4) float64 and ``path_n`` (n_paths,): example paths, x y z
  (local cm) and weight; photon ``i`` writes row ``i`` only, so no two threads share one.
"""

import math

import numba
import numpy as np

C_LIGHT = 29979245800.0  #: cm/s, speed of light in vacuum (MCmatlab's C)

# layout of oi
OI_NI = 0  #: 1: boundary irradiance maps
OI_FF_RES = 1  #: far-field resolution (0: off)
OI_LC = 2  #: light collector: 0 none, 1 objective lens, 2 fiber
OI_LC_RES = 3  #: image pixels per side (1 for a fiber)
OI_LC_NT = 4  #: time slots: 1, or n_time_bins + 2 (before t_start, bins, after t_end)
OI_NR = 5  #: MCML radial bins (0: off)
OI_NA = 6  #: MCML exit-angle bins
OI_DC = 7  #: 1: deposition criteria apply
OI_DC_END = 8  #: 1: evaluate the criteria at the end of the packet's life
OI_DC_COLLECTED = 9  #: 1: only collected packets deposit
OI_DC_MIN = 10  #: minimum scatterings, reflections, refractions, interface transitions (4)
OI_DC_MAX = 14  #: maxima (4); ``DC_UNLIMITED`` for none
OI_N_PATHS = 18
OI_PATH_LEN = 19
OI_OFF_NI = 20  #: offsets in ext of NI xpos, xneg, ypos, yneg, zpos, zneg (6)
OI_OFF_FF = 26
OI_OFF_IMG = 27
OI_OFF_RD_R = 28
OI_OFF_RD_A = 29
OI_OFF_TT_R = 30
OI_OFF_TT_A = 31
OI_SIZE = 32

# layout of of
OF_LC_R = 0  #: lens centre or fiber tip, local cm (3)
OF_LC_THETA = 3
OF_LC_PHI = 4
OF_LC_F = 5  #: cm, focal length (inf: fiber)
OF_LC_DIAM = 6  #: cm, aperture diameter
OF_LC_FS_OR_NA = 7  #: field size (cm) of a lens, numerical aperture of a fiber
OF_T_START = 8  #: s
OF_T_END = 9  #: s
OF_DR = 10  #: cm, MCML radial bin
OF_X0 = 11  #: local cm, centre of the radial bins (the source's focus)
OF_Y0 = 12
OF_SIZE = 13

EXT_COLLECTED = 0  #: ext[0]: number of collected packets that met the criteria
EXT_HEAD = 1  #: the outputs start after it

DC_UNLIMITED = np.iinfo(np.int64).max

FATE_KILLED = 0
FATE_ESCAPED = 1
FATE_COLLECTED = 2

_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@numba.njit(cache=True)
def criteria_met(oi, cnt, fate, dead):
    """MCmatlab's ``depositionCriteriaMet``: all minima and maxima hold.

    A packet that died without escaping (``dead`` and ``fate == FATE_KILLED``) meets a
    maximum only if that maximum is unlimited, as in MCmatlab.
    """
    if oi[OI_DC] == 0:
        return True
    killed = dead and fate == FATE_KILLED
    for k in range(4):
        if cnt[k] < oi[OI_DC_MIN + k]:
            return False
        hi = oi[OI_DC_MAX + k]
        if (killed and hi != DC_UNLIMITED) or cnt[k] > hi:
            return False
    if oi[OI_DC_COLLECTED] == 1 and fate != FATE_COLLECTED:
        return False
    return True


@numba.njit(cache=True)
def push_record(rec, n, j, dep):
    """Append (voxel, weight) to the packet's deposit record, doubling it when full."""
    if n == rec.shape[0]:
        bigger = np.empty((2 * n, 2), dtype=np.int64)
        bigger[:n] = rec
        rec = bigger
    rec[n, 0] = j
    rec[n, 1] = dep
    return rec


@numba.njit(cache=True)
def flush_record(rec, n, acc, met, scale=1.0):
    """Add the recorded deposits times ``scale`` into ``acc`` if ``met``; return the weight
    left out (all of it if not ``met``, else the rest, ``1 - scale`` of each deposit).

    MCmatlab (MCmatlab.c, ``evaluateCriteriaAtEndOfLife``) adds a packet's recorded
    deposits times its final weight: ``scale`` is that weight, a fraction of the launched
    one. Its "collected fluence rate" (Example 8) thus weights where light was absorbed by
    how much of the packet reached the collector.
    """
    left_out = np.int64(0)
    for i in range(n):
        if met:
            part = np.int64(rec[i, 1] * scale)
            acc[rec[i, 0]] += part
            left_out += rec[i, 1] - part
        else:
            left_out += rec[i, 1]
    return left_out


@numba.njit(cache=True)
def path_point(paths, path_n, ip, x, y, z, w):
    """Add a vertex to example path ``ip`` (NaN x marks a jump: a cyclic wrap)."""
    k = path_n[ip]
    if k < paths.shape[1]:
        paths[ip, k, 0] = x
        paths[ip, k, 1] = y
        paths[ip, k, 2] = z
        paths[ip, k, 3] = w
        path_n[ip] = k + 1


@numba.njit(cache=True, fastmath=_FASTMATH)
def _to_collector_frame(vx, vy, vz, theta, phi):
    """(X, Y, Z) of a vector in the collector frame: Z along (theta, phi), X in the xy plane.

    The frame of MCmatlab's light collector: X = (sin phi, -cos phi, 0),
    Y = (cos theta cos phi, cos theta sin phi, -sin theta), Z = the viewing axis.
    """
    st, ct = math.sin(theta), math.cos(theta)
    sp, cp = math.sin(phi), math.cos(phi)
    X = sp * vx - cp * vy
    Y = ct * cp * vx + ct * sp * vy - st * vz
    Z = st * cp * vx + st * sp * vy + ct * vz
    return X, Y, Z


@numba.njit(cache=True, fastmath=_FASTMATH)
def collect(oi, of, x, y, z, ux, uy, uz, t_opl, n_out):
    """Where an escaping packet lands on the light collector: (flat pixel index, or -1).

    ``(x, y, z)`` local cm on the cuboid face, ``u`` the direction after refraction into
    the surrounding medium of index ``n_out``, ``t_opl`` the optical path so far (cm). The
    packet flies straight to the collector plane; a lens (focal length f) images the
    object plane at f in front of it at 1x onto ``res x res`` pixels over the field size;
    a fiber accepts packets within its core and its acceptance angle asin(NA).
    """
    theta = of[OF_LC_THETA]
    phi = of[OF_LC_PHI]
    UX, UY, UZ = _to_collector_frame(ux, uy, uz, theta, phi)
    if UZ >= 0.0:
        return -1  # moving away from the collector plane
    RX, RY, RZ = _to_collector_frame(x - of[OF_LC_R], y - of[OF_LC_R + 1], z - of[OF_LC_R + 2],
                                     theta, phi)
    if RZ <= 0.0:
        return -1  # already behind the collector plane
    PX = RX - RZ * UX / UZ  # where the packet crosses the collector plane
    PY = RY - RZ * UY / UZ
    if PX * PX + PY * PY >= 0.25 * of[OF_LC_DIAM] ** 2:
        return -1
    res = oi[OI_LC_RES]
    if oi[OI_LC] == 1:  # lens: back to the object plane at Z = f
        f = of[OF_LC_F]
        fs = of[OF_LC_FS_OR_NA]
        IX = PX + f * UX / UZ
        IY = PY + f * UY / UZ
        if IX * IX + IY * IY >= 0.25 * fs * fs:
            return -1
        ix = min(res - 1, max(0, int(res * (IX / fs + 0.5))))
        iy = min(res - 1, max(0, int(res * (IY / fs + 0.5))))
        dist = (RZ - f) / -UZ  # from the face to the object plane (negative: back)
        pix = ix * res + iy
    else:  # fiber
        if math.atan2(math.sqrt(UX * UX + UY * UY), -UZ) >= math.asin(min(1.0, of[OF_LC_FS_OR_NA])):
            return -1
        dist = RZ / -UZ
        pix = 0
    nt = oi[OI_LC_NT]
    it = 0
    if nt > 1:
        t = (t_opl + dist * n_out) / C_LIGHT
        u = (t - of[OF_T_START]) / (of[OF_T_END] - of[OF_T_START])
        it = min(nt - 1, max(0, int(math.floor(1.0 + (nt - 2) * u))))
    return pix * nt + it


@numba.njit(cache=True, fastmath=_FASTMATH)
def record_escape(oi, of, ext, cnt, x, y, z, ux, uy, uz, w, t_opl, n_out, axis, sgn,
                  ix, iy, iz, nx, ny, nz, xr, yr, visible=True):
    """Tally a packet of weight ``w`` (fixed point) leaving through a cuboid face.

    ``axis``, ``sgn``: the face (0, 1, 2 for x, y, z; sign of the direction); ``ix, iy,
    iz`` its voxel; ``xr, yr`` the exit point relative to the source (unfolded across
    cyclic sides), for the radial tallies. ``visible``: False for a packet that leaves
    through a face without Fresnel (``MC.n_outside = None``) from a medium of n != 1: as
    MCmatlab's, it counts in ``NI_*`` only, not in the far field or the collector, and its
    fate is "killed". Returns the packet's fate (escaped or collected), which the
    deposition criteria of its absorbed weight depend on.
    """
    fate = FATE_ESCAPED if visible else FATE_KILLED
    pix = -1
    if visible and oi[OI_LC] != 0:
        pix = collect(oi, of, x, y, z, ux, uy, uz, t_opl, n_out)
        if pix >= 0:
            fate = FATE_COLLECTED
    if not criteria_met(oi, cnt, fate, True):
        return fate
    if pix >= 0:
        ext[oi[OI_OFF_IMG] + pix] += w
        ext[EXT_COLLECTED] += 1
    res = oi[OI_FF_RES]
    if visible and res > 0:
        th = (1.0 - 1e-12) * math.acos(max(-1.0, min(1.0, uz)))
        ph = (1.0 - 1e-12) * (math.pi + math.atan2(uy, ux))
        ith = min(res - 1, int(th / math.pi * res))
        iph = min(res - 1, int(ph / (2.0 * math.pi) * res))
        ext[oi[OI_OFF_FF] + ith * res + iph] += w
    if oi[OI_NI] != 0:
        if axis == 0:
            off = oi[OI_OFF_NI + (0 if sgn > 0 else 1)] + iy * nz + iz
        elif axis == 1:
            off = oi[OI_OFF_NI + (2 if sgn > 0 else 3)] + ix * nz + iz
        else:
            off = oi[OI_OFF_NI + (4 if sgn > 0 else 5)] + ix * ny + iy
        ext[off] += w
    nr = oi[OI_NR]
    if nr > 0 and axis == 2:
        # MCML's bins: the last radial and angular bins also hold what lies beyond them
        ir = min(nr - 1, int(math.sqrt(xr * xr + yr * yr) / of[OF_DR]))
        na = oi[OI_NA]
        ia = min(na - 1, int(math.acos(min(1.0, abs(uz))) / (0.5 * math.pi) * na))
        if sgn < 0:
            ext[oi[OI_OFF_RD_R] + ir] += w
            ext[oi[OI_OFF_RD_A] + ia] += w
        else:
            ext[oi[OI_OFF_TT_R] + ir] += w
            ext[oi[OI_OFF_TT_A] + ia] += w
    return fate
