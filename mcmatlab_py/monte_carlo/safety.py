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

Kinds of one refractive index whose attenuations ``mua + mus`` lie within
:data:`DELTA_RATIO` of each other form one group (:func:`delta_groups`). Where a voxel
touches a voxel of another kind of its group (:func:`navigation_safety`), its safety is
the distance to another group, and within it the kernel moves a packet by
delta (Woodcock) tracking: free paths drawn at the group's largest attenuation (the
majorant), a tentative interaction real with probability ``(mua + mus) / majorant`` of
the voxel it falls in, else a null one that leaves the packet as it was. The packets then
cross a thin layer of a similar tissue (an epidermis over a dermis, the wall of a vessel)
without walking it face by face; in the bulk of a medium they move as before, with no
look-up. Light refracts only between groups, and media tallied along the path (thin
media, :func:`mcmatlab_py.monte_carlo.host.track_media`) stay out of every group.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = ["DELTA_RATIO", "delta_groups", "medium_kinds", "navigation_safety", "safety_distances"]

#: kinds of one refractive index join a group of delta tracking when their attenuation is
#: at least this share of the group's largest: at most 1 - DELTA_RATIO of the tentative
#: interactions are null
DELTA_RATIO = 0.7

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


def delta_groups(kinds, mua, mus, nref, present=None, track=None, ratio: float | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The groups of kinds crossed by delta tracking (module doc).

    ``kinds`` (n_media,) from :func:`medium_kinds`; ``mua``, ``mus``, ``nref`` (n_media,);
    ``present`` (n_media,) bool, the media in the grid (default all); ``track`` (n_media,)
    bool or None, the media tallied along the path, each left in a group of its kind alone.
    Kinds join, largest attenuation first, the group of the largest not yet grouped, of the
    same refractive index, while their attenuation is at least ``ratio`` (default
    :data:`DELTA_RATIO`; above 1: no groups) times its.

    Returns ``(group, majorant, merged)``, each (n_media,): each medium's group (a label,
    equal for the media of one kind), the group's largest ``mua + mus`` (cm^-1; the
    medium's own where its group holds one kind) and whether its group holds several
    kinds (then a packet's medium is looked up at each tentative interaction)."""
    ratio = DELTA_RATIO if ratio is None else float(ratio)
    kinds = np.asarray(kinds)
    mut = np.asarray(mua, float) + np.asarray(mus, float)
    nref = np.asarray(nref, float)
    n = kinds.size
    present = np.ones(n, bool) if present is None else np.asarray(present, bool)
    alone = np.zeros(n, bool) if track is None else np.asarray(track, bool)
    alone = alone | ~np.isfinite(nref) | ~(mut > 0.0)
    group = kinds.copy()
    # one medium for each kind that may join a group, largest attenuation first
    first = {}
    for i in np.argsort(-mut, kind="stable"):
        k = int(kinds[i])
        if present[i] and not alone[kinds == k].any():
            first.setdefault(k, i)
    open_ = list(first.values())
    while open_:
        head = open_.pop(0)
        join = [i for i in open_ if nref[i] == nref[head] and mut[i] >= ratio * mut[head]]
        for i in join:
            group[kinds == kinds[i]] = kinds[head]
            open_.remove(i)
    majorant = mut.copy()
    merged = np.zeros(n, bool)
    for k in np.unique(group):
        mine = group == k
        if np.unique(kinds[mine]).size > 1:
            merged[mine] = True
            majorant[mine] = mut[mine & present].max()
    return group, majorant, merged


def safety_distances(M: np.ndarray, kinds: np.ndarray, d: tuple[float, float, float],
                     only=None) -> np.ndarray:
    """(nx*ny*nz,) float32 cm, C order: for each voxel of the grid ``M`` (nx, ny, nz) of
    medium indices, the distance from any point of it to the nearest voxel of another kind
    (``kinds``, :func:`medium_kinds`, or another group of :func:`delta_groups`); ``inf``
    where none exists. Outside the grid counts as the same kind (the kernel cuts a move at
    the cuboid's faces itself). ``d``: the voxel sides (dx, dy, dz) in cm. ``only``: the
    kinds whose voxels need their distance (default all; the others' stay ``inf``).

    The distance between the boxes of voxels ``v`` and ``w`` is
    :math:`\\sqrt{\\sum_a ((|v_a - w_a| - 1)^+ d_a)^2}`, the distance between the centres of
    ``v`` and of the voxel next to ``w`` on ``v``'s side: the Euclidean distance transform
    of the other kinds' voxels dilated by one voxel (3 x 3 x 3) gives it exactly.
    """
    K = np.asarray(kinds)[np.asarray(M)]
    safe = np.full(K.shape, np.inf, dtype=np.float32)
    for k in np.unique(K) if only is None else np.intersect1d(np.unique(K), only):
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


def navigation_safety(M: np.ndarray, kinds: np.ndarray, group: np.ndarray, merged: np.ndarray,
                      d: tuple[float, float, float]) -> np.ndarray:
    """(nx*ny*nz,) float32 cm, C order: the general kernel's safety of each voxel of ``M``
    (nx, ny, nz): the distance to another kind (``kinds``, :func:`medium_kinds`), >= 0;
    or, where that is 0 (a voxel next to another kind, where the packets would walk face
    by face), the voxel's medium is ``merged`` in a group of delta tracking (``group``,
    :func:`delta_groups`) and another group lies farther, minus the distance to it: a
    ball crossed by delta tracking. (Delta tracking also where the other kind lies a
    voxel or more away was slower on MCmatlab's Example 4: a look-up at every tentative
    interaction costs more than the free moves' look-ups where balls are that large.)"""
    exact = safety_distances(M, kinds, d)
    if not np.any(np.asarray(merged)):
        return exact
    # the other groups' distances only for the merged media's voxels, where they are used
    far = safety_distances(M, group, d, only=np.unique(np.asarray(group)[np.asarray(merged)]))
    delta = np.asarray(merged)[np.asarray(M).ravel()] & (exact == 0.0) & (far > 0.0)
    return np.where(delta, -far, exact).astype(np.float32)
