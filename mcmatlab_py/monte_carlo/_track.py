"""Numba kernel of the track-length tally along a straight move through several voxels.

The general kernel (:mod:`mcmatlab_py.monte_carlo._kernel`) moves a packet through a run of voxels
of one kind of medium in one step (:mod:`mcmatlab_py.monte_carlo.safety`); where that medium's fluence
is tallied along the path, :func:`track_walk` splits the move at the voxel faces it
crosses and adds each voxel's share, as a walk face by face would. The packet's own
position is not touched: the transport does not depend on whether the tally runs.
"""

import numba
import numpy as np

from ._steps import _clamp, _plane_distance

_INF = np.inf

_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def track_walk(flu, w, fscale, px, py, pz, ux, uy, uz, s, ix, iy, iz, nx, ny, nz, dx, dy, dz):
    """Add ``w * length * fscale`` (rounded) to ``flu`` for each voxel along the move of
    length ``s`` (cm) from ``(px, py, pz)`` in voxel ``(ix, iy, iz)`` along ``u``, which stays
    inside the cuboid. ``flu`` (nx*ny*nz,) int64; ``w`` the packet's fixed-point weight.

    The voxel traversal of Amanatides & Woo (1987): the distances along the move to the
    next plane of each axis grow by a voxel's side over the direction's component.
    """
    wf = w * fscale
    t0 = _plane_distance(px, ux, ix, nx, dx)
    t1 = _plane_distance(py, uy, iy, ny, dy)
    t2 = _plane_distance(pz, uz, iz, nz, dz)
    d0 = dx / abs(ux) if ux != 0.0 else _INF
    d1 = dy / abs(uy) if uy != 0.0 else _INF
    d2 = dz / abs(uz) if uz != 0.0 else _INF
    t = 0.0
    while True:
        j = (_clamp(ix, nx) * ny + _clamp(iy, ny)) * nz + _clamp(iz, nz)
        tn = min(t0, min(t1, t2))
        if tn >= s:
            flu[j] += np.int64(wf * (s - t) + 0.5)
            return
        flu[j] += np.int64(wf * (tn - t) + 0.5)
        t = tn
        if t0 == tn:
            ix += 1 if ux > 0.0 else -1
            t0 += d0
        elif t1 == tn:
            iy += 1 if uy > 0.0 else -1
            t1 += d1
        else:
            iz += 1 if uz > 0.0 else -1
            t2 += d2
        if ix < 0 or ix >= nx or iy < 0 or iy >= ny or iz < 0 or iz >= nz:
            return
