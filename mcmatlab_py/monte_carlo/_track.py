"""Numba kernel of the track-length tally along a straight move through several voxels.

The general kernel (:mod:`mcmatlab_py.monte_carlo._kernel`) moves a packet through a run of voxels
of one kind of medium in one step (:mod:`mcmatlab_py.monte_carlo.safety`); where that medium's fluence
is tallied along the path, :func:`track_walk` splits the move at the voxel faces it
crosses and adds each voxel's share, as a walk face by face would. The packet's own
position is not touched: the transport does not depend on whether the tally runs.
"""

import numba
import numpy as np

from ._steps import _plane_distance_r

_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@numba.njit(cache=True, inline="always", fastmath=_FASTMATH)
def track_walk(flu, w, fscale, px, py, pz, ux, uy, uz, rx, ry, rz, s, ix, iy, iz, nx, ny, nz,
               dx, dy, dz):
    """Add ``w * length * fscale`` (rounded) to ``flu`` for each voxel along the move of
    length ``s`` (cm) from ``(px, py, pz)`` in voxel ``(ix, iy, iz)`` along ``u``, which stays
    inside the cuboid. ``flu`` (nx*ny*nz,) int64; ``w`` the packet's fixed-point weight;
    ``(rx, ry, rz)`` the reciprocals of ``u`` (:func:`mcmatlab_py.monte_carlo._steps._reciprocals`).

    The voxel traversal of Amanatides & Woo (1987): the distances along the move to the
    next plane of each axis grow by a voxel's side over the direction's component.
    """
    wf = w * fscale
    t0 = _plane_distance_r(px, ux, rx, ix, nx, dx)
    t1 = _plane_distance_r(py, uy, ry, iy, ny, dy)
    t2 = _plane_distance_r(pz, uz, rz, iz, nz, dz)
    # a voxel's side along the move: the side times the reciprocal (inf for a zero
    # component), no division of its own
    d0 = dx * abs(rx)
    d1 = dy * abs(ry)
    d2 = dz * abs(rz)
    # the voxel's index, the steps of the indices along the axes and the index past the
    # cuboid, from the signs of the reciprocals (inf for a zero component, never stepped):
    # computed here, not where the direction changes, as the signs of u would be (LLVM
    # hoists what depends only on u to every change of direction)
    j = (ix * ny + iy) * nz + iz
    ax = 1 if rx > 0.0 else -1
    ay = 1 if ry > 0.0 else -1
    az = 1 if rz > 0.0 else -1
    ex = nx if ax > 0 else -1
    ey = ny if ay > 0 else -1
    ez = nz if az > 0 else -1
    t = 0.0
    while True:
        tn = min(t0, min(t1, t2))
        if tn >= s:
            flu[j] += np.int64(wf * (s - t) + 0.5)
            return
        flu[j] += np.int64(wf * (tn - t) + 0.5)
        t = tn
        if t0 == tn:
            ix += ax
            if ix == ex:
                return
            j += ax * ny * nz
            t0 += d0
        elif t1 == tn:
            iy += ay
            if iy == ey:
                return
            j += ay * nz
            t1 += d1
        else:
            iz += az
            if iz == ez:
                return
            j += az
            t2 += d2
