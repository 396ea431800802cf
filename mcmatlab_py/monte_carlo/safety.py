"""Safety distances of a voxel grid: how far a packet may move without meeting another medium.

The general Monte Carlo kernel (:mod:`mcmatlab_py.monte_carlo._kernel`) moves a packet through a
run of voxels of one medium in a single step where nothing can change along the way:
from any point of voxel ``v`` it may go up to ``safe[v]`` cm in any direction and stay
among voxels whose optics equal those of ``v``. Only within one voxel of a change of
optics does it walk face by face. This is the "safety" of Geant4's navigation (the
distance to the nearest boundary, isotropic), here from a Euclidean distance transform.

Two media are the same kind of medium when mua, mus, g, n and the phase function are the
same: a packet cannot tell them apart, so a voxel of a second, identical medium costs
nothing. Where deposition criteria count the transitions between media (MCmatlab's
``interfaceTransitions``), every medium is its own kind.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = ["safety_distances", "medium_kinds"]

#: the distances are shortened by this fraction, so that a move of the full safety, rounded,
#: cannot end inside a voxel of another kind
SHRINK = 1e-6


def medium_kinds(mua, mus, g, nref, phase_idx=None, by_medium: bool = False) -> np.ndarray:
    """(n_media,) int: the kind of each medium, equal for media with the same mua, mus, g,
    n and phase-function row (``phase_idx``, -1 or None for Henyey-Greenstein); each medium
    its own kind if ``by_medium``."""
    n = len(mua)
    if by_medium:
        return np.arange(n)
    rows = np.full(n, -1) if phase_idx is None else np.asarray(phase_idx)
    keys = np.stack([np.asarray(mua, float), np.asarray(mus, float), np.asarray(g, float),
                     np.asarray(nref, float), rows.astype(float)], axis=1)
    return np.unique(keys, axis=0, return_inverse=True)[1].ravel()


def safety_distances(M: np.ndarray, kinds: np.ndarray, d: tuple[float, float, float]
                     ) -> np.ndarray:
    """(nx*ny*nz,) float32 cm, C order: for each voxel of the grid ``M`` (nx, ny, nz) of
    medium indices, the distance from any point of it to the nearest voxel of another kind
    (``kinds``, :func:`medium_kinds`); ``inf`` where none exists. Outside the grid counts as
    the same kind (the kernel cuts a move at the cuboid's faces itself). ``d``: the voxel
    sides (dx, dy, dz) in cm.

    The distance between the boxes of voxels ``v`` and ``w`` is
    :math:`\\sqrt{\\sum_a ((|v_a - w_a| - 1)^+ d_a)^2}`, the distance between the centres of
    ``v`` and of the voxel next to ``w`` on ``v``'s side: the Euclidean distance transform
    of the other kinds' voxels dilated by one voxel (3 x 3 x 3) gives it exactly.
    """
    K = np.asarray(kinds)[np.asarray(M)]
    safe = np.full(K.shape, np.inf, dtype=np.float32)
    for k in np.unique(K):
        mine = K == k
        if mine.all():
            break
        # the kind's bounding box, one voxel wider: beyond it lie only voxels of other kinds
        # (or the outside of the grid), farther than those of the box's outer layer
        box = tuple(slice(max(int(ix.min()) - 1, 0), int(ix.max()) + 2)
                    for ix in np.nonzero(mine))
        sub = mine[box]
        near = ndimage.binary_dilation(~sub, structure=np.ones((3, 3, 3), bool))
        if near.all():
            dist = np.zeros(sub.shape)
        else:
            dist = ndimage.distance_transform_edt(~near, sampling=d)
        part = safe[box]
        part[sub] = (dist[sub] * (1.0 - SHRINK)).astype(np.float32)
    return safe.ravel()
