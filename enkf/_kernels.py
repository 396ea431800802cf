"""Numba kernels of the generic filter: standard normals by the ziggurat method.

A row-block of normals comes from its own xoshiro256** stream (Blackman & Vigna 2021),
seeded through splitmix64, and the ziggurat of Marsaglia & Tsang (2000, J. Stat.
Softw. 5(8)) with 128 layers turns it into N(0, 1) numbers. The layer index takes
the low 7 bits of each 64-bit output and the signed abscissa the high 32, so the two
are independent (the correlation Leong et al. 2005 found in the original, which took
both from one 32-bit word, does not arise). The generator is written here, not taken
from ``mcmatlab_py._rng``: the generic filter imports nothing of the project.
"""

from __future__ import annotations

import numba
import numpy as np

_U64 = np.uint64
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_TWO_M53 = 1.0 / 9007199254740992.0  # 2**-53
_R = 3.442619855899  # start of the ziggurat's tail


def ziggurat_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``kn`` (128,) int64 acceptance bounds, ``wn`` and ``fn`` (128,) float64 widths and
    densities of Marsaglia & Tsang's 128-layer normal ziggurat (their ``zigset``)."""
    m1 = 2147483648.0
    dn = tn = _R
    vn = 9.91256303526217e-3
    kn = np.zeros(128, dtype=np.int64)
    wn = np.zeros(128)
    fn = np.zeros(128)
    q = vn / np.exp(-0.5 * dn * dn)
    kn[0] = int(dn / q * m1)
    kn[1] = 0
    wn[0] = q / m1
    wn[127] = dn / m1
    fn[0] = 1.0
    fn[127] = np.exp(-0.5 * dn * dn)
    for i in range(126, 0, -1):
        dn = np.sqrt(-2.0 * np.log(vn / dn + np.exp(-0.5 * dn * dn)))
        kn[i + 1] = int(dn / tn * m1)
        tn = dn
        fn[i] = np.exp(-0.5 * dn * dn)
        wn[i] = dn / m1
    return kn, wn, fn


@numba.njit(cache=True, inline="always")
def _splitmix64(x):
    x = x + _GOLDEN
    z = x
    z = (z ^ (z >> _U64(30))) * _MIX1
    z = (z ^ (z >> _U64(27))) * _MIX2
    return x, z ^ (z >> _U64(31))


@numba.njit(cache=True, inline="always")
def _rotl(x, k):
    return (x << _U64(k)) | (x >> _U64(64 - k))


@numba.njit(cache=True, inline="always")
def _next(s):
    """xoshiro256** on the state array ``s`` (4,) uint64: the next 64-bit output."""
    result = _rotl(s[1] * _U64(5), 7) * _U64(9)
    t = s[1] << _U64(17)
    s[2] ^= s[0]
    s[3] ^= s[1]
    s[1] ^= s[2]
    s[0] ^= s[3]
    s[2] ^= t
    s[3] = _rotl(s[3], 45)
    return result


@numba.njit(cache=True, inline="always")
def _uniform(s):
    """A double in (0, 1]."""
    return ((_next(s) >> _U64(11)) + _U64(1)) * _TWO_M53


@numba.njit(cache=True, inline="always")
def _split(u):
    """(signed 32-bit abscissa from the high bits, layer from the low 7 bits)."""
    hz = np.int64(np.int32(np.uint32(u >> _U64(32))))
    return hz, np.int64(u & _U64(127))


@numba.njit(cache=True)
def _normal_slow(s, hz, iz, kn, wn, fn):
    """The ziggurat's rare branch: the tail (layer 0) or a wedge test, retried."""
    while True:
        x = hz * wn[iz]
        if iz == 0:
            while True:
                x = -np.log(_uniform(s)) / _R
                y = -np.log(_uniform(s))
                if y + y >= x * x:
                    break
            return _R + x if hz > 0 else -_R - x
        if fn[iz] + _uniform(s) * (fn[iz - 1] - fn[iz]) < np.exp(-0.5 * x * x):
            return x
        hz, iz = _split(_next(s))
        if abs(hz) < kn[iz]:
            return hz * wn[iz]


@numba.njit(cache=True, nogil=True)
def fill_normal(seed, out, kn, wn, fn):
    """Fill the C-contiguous ``out`` with N(0, 1) numbers of the stream ``seed`` (uint64)."""
    s = np.empty(4, dtype=np.uint64)
    x = _U64(seed)
    for k in range(4):
        x, s[k] = _splitmix64(x)
    flat = out.reshape(-1)
    for j in range(flat.size):
        hz, iz = _split(_next(s))
        if abs(hz) < kn[iz]:
            flat[j] = hz * wn[iz]
        else:
            flat[j] = _normal_slow(s, hz, iz, kn, wn, fn)
