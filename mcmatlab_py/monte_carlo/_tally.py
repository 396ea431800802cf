"""Fixed-point weights and the tally slots shared by the Monte Carlo kernels.

Weights are fixed-point integers (``W_ONE`` is weight 1). A packet's deposits plus its
final escape add up to its launch weight *exactly*, and integer sums do not depend on
the order in which threads add them, so the same seed gives bit-identical ``NA`` for any
number of threads. The Python layer reads the slots here.
"""

import math

import numba
import numpy as np

KILLRANGE = 5.0  # as MCmatlab: photons farther than 2.5 cuboid sizes from the centre die
W_ONE = 2**36  # fixed-point weight of a launched packet (about 1.5e-11 resolution)
#: a deposit of fewer units than this is rounded up or down at random (up with probability
#: its fraction) instead of carrying the fraction to the next interaction: a carried fraction
#: lands in the next interaction's voxel, so the first voxel of every path, which receives
#: none, read up to 0.7% low where a medium absorbs 1e-10 of the weight per interaction
#: (air that scatters: about 7 units an interaction). Above it the carry's bias is below
#: 5e-7 of a voxel's deposit.
RANDOM_ROUNDING_BELOW = 2**20


@numba.njit(cache=True, inline="always")
def split_deposit(wd: float, w, r: float):
    """``(deposit, carried)``: a deposit of ``wd`` fixed-point units as whole units now and
    the fraction carried to the next interaction. Below :data:`RANDOM_ROUNDING_BELOW` units
    it is rounded up with probability its fraction (``r`` uniform in [0, 1), drawn by the
    caller only there) and nothing is carried: its expectation is ``wd`` in this voxel.
    Never more than the packet's weight ``w``."""
    dep = np.int64(wd)
    if wd >= RANDOM_ROUNDING_BELOW:
        return dep, wd - dep
    if r < wd - dep:
        dep = min(dep + 1, w)
    return dep, 0.0


#: the track-length tally: a launched packet crossing a voxel's diagonal adds FLU_ONE
FLU_ONE = 2**24


@numba.njit(cache=True)
def fluence_scale(dx: float, dy: float, dz: float) -> float:
    """The track-length tally's units per (fixed-point weight x cm): ``FLU_ONE`` per
    ``W_ONE`` weight over a voxel's diagonal (the longest path one voxel holds)."""
    return FLU_ONE / (W_ONE * math.sqrt(dx * dx + dy * dy + dz * dz))

# tally slots (per thread slot, int64 fixed-point weights)
T_LAUNCHED = 0
T_SPECULAR = 1
T_TOP = 2
T_BOTTOM = 3
T_SIDES = 4
T_OUTSIDE_ABSORBED = 5
T_KILLED = 6
T_MISSED = 7
T_ROULETTE = 8  # weight created by roulette survivors minus weight of packets killed
T_ABSORBED_EXCLUDED = 9  # absorbed inside by packets that failed the deposition criteria
N_TALLY = 10
