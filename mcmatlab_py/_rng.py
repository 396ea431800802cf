"""Counter-based seeding and the xoshiro256** generator, for numba kernels.

Each Monte Carlo batch owns an independent stream seeded from ``(seed, batch)``
through splitmix64, so the photons of a batch are the same whatever thread
runs it (Blackman & Vigna 2021, "Scrambled linear pseudorandom number
generators", ACM TOMS 47:36). The state is four ``uint64`` held in local
variables: nothing is allocated per photon.
"""

import numba
import numpy as np

_U64 = np.uint64
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_TWO_M53 = 1.0 / 9007199254740992.0  # 2**-53


@numba.njit(cache=True, inline="always")
def splitmix64(x):
    """One splitmix64 step: returns ``(new_x, output)``."""
    x = x + _GOLDEN
    z = x
    z = (z ^ (z >> _U64(30))) * _MIX1
    z = (z ^ (z >> _U64(27))) * _MIX2
    z = z ^ (z >> _U64(31))
    return x, z


@numba.njit(cache=True, inline="always")
def _rotl(x, k):
    return (x << _U64(k)) | (x >> _U64(64 - k))


@numba.njit(cache=True)
def seed_stream(seed, stream):
    """State of stream ``stream`` of generator ``seed``: four uint64."""
    x = _U64(seed) * _MIX1 + _U64(stream) * _GOLDEN + _U64(0x2545F4914F6CDD1D)
    x, s0 = splitmix64(x)
    x, s1 = splitmix64(x)
    x, s2 = splitmix64(x)
    x, s3 = splitmix64(x)
    return s0, s1, s2, s3


@numba.njit(cache=True, inline="always")
def next_double(s0, s1, s2, s3):
    """xoshiro256**: returns the new state and a double uniform in [0, 1)."""
    result = _rotl(s1 * _U64(5), 7) * _U64(9)
    t = s1 << _U64(17)
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotl(s3, 45)
    return s0, s1, s2, s3, (result >> _U64(11)) * _TWO_M53
