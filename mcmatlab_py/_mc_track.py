"""Numba kernel of the track-length tally along a straight move through several voxels.

The general kernel (:mod:`mcmatlab_py._mc_kernel`) moves a packet through a run of voxels
of one kind of medium in one step (:mod:`mcmatlab_py.safety`); where that medium's fluence
is tallied along the path, :func:`track_walk` splits the move at the voxel faces it
crosses and adds each voxel's share, as a walk face by face would. The packet's own
position is not touched: the transport does not depend on whether the tally runs.
"""

import numba
import numpy as np

from ._mc_steps import _clamp, _plane_distance

_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@numba.njit(cache=True, fastmath=_FASTMATH)
def track_walk(flu, w, fscale, px, py, pz, ux, uy, uz, s, ix, iy, iz, nx, ny, nz, dx, dy, dz):
    """Add ``w * length * fscale`` (rounded) to ``flu`` for each voxel along the move of
    length ``s`` (cm) from ``(px, py, pz)`` in voxel ``(ix, iy, iz)`` along ``u``, which stays
    inside the cuboid. ``flu`` (nx*ny*nz,) int64; ``w`` the packet's fixed-point weight."""
    left = s
    while True:
        ixc = _clamp(ix, nx)
        iyc = _clamp(iy, ny)
        izc = _clamp(iz, nz)
        j = (ixc * ny + iyc) * nz + izc
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
        if left <= dmin:
            flu[j] += np.int64(w * (left * fscale) + 0.5)
            return
        flu[j] += np.int64(w * (dmin * fscale) + 0.5)
        left -= dmin
        px += dmin * ux
        py += dmin * uy
        pz += dmin * uz
        if axis == 0:
            px = (ix + 1) * dx if ux > 0.0 else ix * dx
            ix += 1 if ux > 0.0 else -1
            if ix < 0 or ix >= nx:
                return
        elif axis == 1:
            py = (iy + 1) * dy if uy > 0.0 else iy * dy
            iy += 1 if uy > 0.0 else -1
            if iy < 0 or iy >= ny:
                return
        else:
            pz = (iz + 1) * dz if uz > 0.0 else iz * dz
            iz += 1 if uz > 0.0 else -1
            if iz < 0 or iz >= nz:
                return
