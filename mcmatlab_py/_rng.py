"""Counter-based seeding and the xoshiro256** generator, for numba kernels.

Each Monte Carlo batch owns an independent stream seeded from ``(seed, batch)``
through splitmix64, so the photons of a batch are the same whatever thread
runs it (Blackman & Vigna 2021, "Scrambled linear pseudorandom number
generators", ACM TOMS 47:36). The state is four ``uint64`` held in local
variables: nothing is allocated per photon.
"""

import math

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


_MIX3 = np.uint64(0xD6E8FEB86659FD93)


@numba.njit(cache=True, inline="always")
def photon_stream(seed, photon):
    """State of photon ``photon``'s own stream of generator ``seed``: four uint64. The
    start of its splitmix64 sequence is itself hashed, so that the states of consecutive
    photons are not shifted copies of one another (as ``seed_stream``'s would be for
    consecutive ``stream``, whose stride is splitmix64's increment)."""
    x, h = splitmix64(_U64(seed) * _MIX1 + _U64(photon) * _MIX3)
    x, s0 = splitmix64(h)
    x, s1 = splitmix64(x)
    x, s2 = splitmix64(x)
    x, s3 = splitmix64(x)
    return s0, s1, s2, s3


@numba.njit(cache=True, inline="always")
def counter_double(seed, a, b, c):
    """A uniform double in [0, 1) that depends only on ``(seed, a, b, c)`` (uint64 each):
    random numbers keyed by what they are for, not by how many were drawn before (the
    white kernels' per-weight roulette, so that a weight's numbers do not depend on the
    other weights of the run)."""
    x = _U64(seed) * _MIX1 + _U64(a) * _GOLDEN + _U64(b) * _MIX2 + _U64(c) * _MIX3
    x, z = splitmix64(x)
    x, z = splitmix64(x ^ z)
    return (z >> _U64(11)) * _TWO_M53


@numba.njit(cache=True, inline="always")
def next_double(s0, s1, s2, s3):
    """xoshiro256**: returns the new state and a double uniform in [0, 1)."""
    s0, s1, s2, s3, u = next_u64(s0, s1, s2, s3)
    return s0, s1, s2, s3, (u >> _U64(11)) * _TWO_M53


@numba.njit(cache=True, inline="always")
def next_u64(s0, s1, s2, s3):
    """xoshiro256**: returns the new state and the raw 64-bit output."""
    result = _rotl(s1 * _U64(5), 7) * _U64(9)
    t = s1 << _U64(17)
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotl(s3, 45)
    return s0, s1, s2, s3, result


# The exponential ziggurat of Marsaglia & Tsang (2000, J. Stat. Softw. 5(8), "The ziggurat
# method for generating random variables"), 256 layers: a draw is one 64-bit output, a
# table look-up, a product and a comparison in 98.9% of the cases (no logarithm). The
# layer takes the low 8 bits and the abscissa the high 32 bits of the output, so the two
# are independent.
_EXP_R = 7.697117470131487  # start of the tail


def _exp_ziggurat_tables():
    """``ke`` (256,) int64 acceptance bounds, ``we`` and ``fe`` (256,) widths and densities
    (Marsaglia & Tsang's ``zigset``)."""
    m2 = 4294967296.0
    de = te = _EXP_R
    ve = 3.949659822581572e-3
    ke = np.zeros(256, dtype=np.int64)
    we = np.zeros(256)
    fe = np.zeros(256)
    q = ve / np.exp(-de)
    ke[0] = int(de / q * m2)
    we[0] = q / m2
    we[255] = de / m2
    fe[0] = 1.0
    fe[255] = np.exp(-de)
    for i in range(254, 0, -1):
        de = -np.log(ve / de + np.exp(-de))
        ke[i + 1] = int(de / te * m2)
        te = de
        fe[i] = np.exp(-de)
        we[i] = de / m2
    return ke, we, fe


_KE, _WE, _FE = _exp_ziggurat_tables()  # frozen into the compiled kernels as constants


@numba.njit(cache=True)
def _exponential_slow(s0, s1, s2, s3, jz, iz):
    """The ziggurat's rare branch: the tail (layer 0) or a wedge test, retried."""
    while True:
        if iz == 0:
            s0, s1, s2, s3, r = next_double(s0, s1, s2, s3)
            return s0, s1, s2, s3, _EXP_R - math.log(1.0 - r)
        x = jz * _WE[iz]
        s0, s1, s2, s3, r = next_double(s0, s1, s2, s3)
        if _FE[iz] + r * (_FE[iz - 1] - _FE[iz]) < math.exp(-x):
            return s0, s1, s2, s3, x
        s0, s1, s2, s3, u = next_u64(s0, s1, s2, s3)
        jz = np.int64(u >> _U64(32))
        iz = np.int64(u & _U64(255))
        if jz < _KE[iz]:
            return s0, s1, s2, s3, jz * _WE[iz]


@numba.njit(cache=True, inline="always")
def next_exponential(s0, s1, s2, s3):
    """A standard exponential number (mean 1) by the ziggurat: the new state and the draw."""
    s0, s1, s2, s3, u = next_u64(s0, s1, s2, s3)
    jz = np.int64(u >> _U64(32))
    iz = np.int64(u & _U64(255))
    if jz < _KE[iz]:
        return s0, s1, s2, s3, jz * _WE[iz]
    return _exponential_slow(s0, s1, s2, s3, jz, iz)


_TWO_M31 = 1.0 / 2147483648.0  # 2**-31


@numba.njit(cache=True, inline="always")
def next_azimuth(s0, s1, s2, s3):
    """cos and sin of a uniform azimuth without a trigonometric call: a point (a, b)
    uniform in the unit disc (rejection, 1.27 outputs on average, each giving a and b
    from its two 32-bit halves) has a uniform angle; cos and sin of twice that angle are
    ``(a^2 - b^2) / q`` and ``2 a b / q`` with ``q = a^2 + b^2``. Returns the new state,
    cos and sin."""
    while True:
        s0, s1, s2, s3, u = next_u64(s0, s1, s2, s3)
        a = (np.int64(u >> _U64(32)) + 0.5) * _TWO_M31 - 1.0
        b = (np.int64(u & _U64(0xFFFFFFFF)) + 0.5) * _TWO_M31 - 1.0
        q = a * a + b * b
        if q <= 1.0:
            break
    iq = 1.0 / q
    return s0, s1, s2, s3, (a * a - b * b) * iq, 2.0 * a * b * iq
