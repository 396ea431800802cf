"""Large standard-normal draws, fast and reproducible for any number of threads.

The filter draws its model noise, ``(N, n_state)`` normals, every step: with N = 50 on
the paper's 4851-node mesh that is 2.4e5 numbers, 2.6 ms of numpy's generator on one
core of the 2-core reference machine, a quarter of a step. :func:`standard_normal`
takes a seed for each of at most two fixed blocks of rows from the caller's generator
and fills the blocks concurrently with a numba ziggurat (:mod:`enkf._kernels`, 1.0 ms
for the whole draw on one core). The split depends on the size of the draw only, not
on the machine: the same generator state gives the same numbers on one core or many.

:func:`standard_normal_later` draws the same numbers on the worker thread while the
caller goes on (the filter draws the next step's model noise during this step's
analysis); its seeds are taken from the generator at the call, so the stream is the
same as with :func:`standard_normal` at that point.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import _kernels

__all__ = ["PendingNormals", "standard_normal", "standard_normal_later"]

#: draws smaller than this are one block (a thread hand-off costs ~50 us)
SPLIT_MIN = 20_000
_BLOCKS = 2  # fixed: the numbers must not depend on the number of cores
_TABLES = _kernels.ziggurat_tables()
_POOL: ThreadPoolExecutor | None = None


_CORES = os.cpu_count() or 1


def _pool() -> ThreadPoolExecutor | None:
    global _POOL
    if _CORES < 2:
        return None
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=1, thread_name_prefix="enkf-normal")
    return _POOL


def _seeds(rng: np.random.Generator, shape: tuple[int, ...]):
    """(empty output, its blocks, one seed per block): the split depends on the size only."""
    out = np.empty(shape)
    if out.size == 0:
        return out, [], np.zeros(0, np.uint64)
    blocks = _BLOCKS if out.size >= SPLIT_MIN and shape[0] >= _BLOCKS else 1
    seeds = rng.integers(0, 2**63, size=blocks, dtype=np.uint64)
    if blocks == 1:
        return out, [out], seeds
    cut = np.linspace(0, shape[0], blocks + 1).astype(int)
    return out, [out[a:b] for a, b in zip(cut[:-1], cut[1:], strict=True)], seeds


class PendingNormals:
    """Normals being drawn on the worker thread; :meth:`result` waits and returns them."""

    def __init__(self, future=None, value: np.ndarray | None = None):
        self._future, self._value = future, value

    def result(self) -> np.ndarray:
        if self._future is not None:
            self._value = self._future.result()
            self._future = None
        return self._value


def standard_normal_later(rng: np.random.Generator, shape: tuple[int, ...],
                          scale: float | np.ndarray = 1.0) -> PendingNormals:
    """``scale * standard_normal(rng, shape)``, drawn on the worker thread.

    The seeds are drawn from ``rng`` now (so the generator moves exactly as with
    :func:`standard_normal`) and the numbers are the same; on one core the draw is done
    before returning.
    """
    out, parts, seeds = _seeds(rng, tuple(int(s) for s in shape))
    scale = np.asarray(scale, float)

    def fill():
        for seed, part in zip(seeds, parts, strict=True):
            _kernels.fill_normal(seed, part, *_TABLES)
        np.multiply(out, scale, out=out)
        return out

    pool = _pool()
    if pool is None or out.size == 0:
        return PendingNormals(value=fill())
    return PendingNormals(pool.submit(fill))


def standard_normal(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """A new float64 array of ``shape`` with independent N(0, 1) entries.

    Parameters
    ----------
    rng : numpy.random.Generator
        The source of the seeds: one or two 64-bit integers are drawn from it.
    shape : tuple of int
        Output shape; a large draw is split into two blocks along the first axis.
    """
    out, parts, seeds = _seeds(rng, tuple(int(s) for s in shape))
    pool = _pool() if len(parts) == 2 else None
    if pool is None:  # one block, or one core: the blocks in turn
        for seed, part in zip(seeds, parts, strict=True):
            _kernels.fill_normal(seed, part, *_TABLES)
        return out
    future = pool.submit(_kernels.fill_normal, seeds[0], parts[0], *_TABLES)
    _kernels.fill_normal(seeds[1], parts[1], *_TABLES)
    future.result()
    return out
