"""Threads for ensembles: OpenBLAS thread limits and member blocks run side by side.

:func:`run_blocks` splits the members of an ensemble into contiguous blocks and runs
a function on each in its own thread (numpy's products and the ``nogil`` numba kernels
release the GIL); each member is computed by the same code whatever the split, so the
numbers do not depend on the number of threads.

The rest limits OpenBLAS threads around small dense products (a threadpoolctl in
miniature).

The fast-diagonalization products are small (1-D bases of at most ~100 x 100
applied to a few MB of data): threading them gains nothing and, when another
process keeps a core busy, OpenBLAS's spinning threads make them up to 100
times slower (measured: a 196 x 196 solve 1.4 ms single-threaded, 160 ms with
two threads on a loaded 2-core machine).  :func:`blas_threads` sets the thread
count of every loaded OpenBLAS (numpy's and scipy's) and restores it on exit.
If no OpenBLAS is found it does nothing.
"""

from __future__ import annotations

import ctypes
import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np

__all__ = ["DEFAULT_THREADS", "blas_threads", "keep_freed_memory", "release_free_memory",
           "run_blocks"]

#: member blocks run concurrently by default (the reference machine has 2 cores)
DEFAULT_THREADS = min(2, os.cpu_count() or 1)
_POOL: ThreadPoolExecutor | None = None


def _pool() -> ThreadPoolExecutor:
    global _POOL
    if _POOL is None:  # blocks beyond the threads queue up: the numbers stay the same
        _POOL = ThreadPoolExecutor(max_workers=max(1, DEFAULT_THREADS - 1),
                                   thread_name_prefix="fem-fd")
    return _POOL


_MALLOC_TUNED = False


def keep_freed_memory(mmap_threshold: int = 16 << 20, trim_threshold: int = 64 << 20) -> bool:
    """Let glibc keep freed blocks of up to ``mmap_threshold`` bytes for reuse.

    An ensemble step allocates a few arrays of ``N x n_state`` floats (2 MB at N = 50
    on the filter's mesh) and frees them again. By default glibc hands blocks of that
    size straight back to the kernel, so every step pays fresh page faults for them; on
    the 2-core reference VM that was a third of the filter's time (150 steps: median
    1.77 s, with this 1.09 s, six runs each, ``benchmarks/bench_filter.py``). Sets
    ``M_MMAP_THRESHOLD`` and ``M_TRIM_THRESHOLD`` with ``mallopt`` once per process; the
    heap then holds up to ``trim_threshold`` bytes of free memory. Returns whether it
    applied (glibc only; elsewhere it does nothing).
    """
    global _MALLOC_TUNED
    if _MALLOC_TUNED:
        return True
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
    _MALLOC_TUNED = bool(mallopt(M_MMAP_THRESHOLD, int(mmap_threshold))) and bool(
        mallopt(M_TRIM_THRESHOLD, int(trim_threshold)))
    return _MALLOC_TUNED


def release_free_memory() -> bool:
    """Give the heap's free memory back to the system (glibc ``malloc_trim(0)``).

    After a build that made and freed large temporaries (an emulator's load operator:
    ~270 MB), the freed blocks stay in the process's resident set; later phases then
    start from that level (a cold ``identify`` peaked at 640 MB in its plots). Returns
    whether anything was released (glibc only; elsewhere it does nothing)."""
    try:
        trim = ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return False
    trim.argtypes = [ctypes.c_size_t]
    return bool(trim(0))


def run_blocks(n: int, fn: Callable[[int, int], None], blocks: int = 2) -> None:
    """Call ``fn(i0, i1)`` on ``min(blocks, n)`` contiguous blocks of ``range(n)``, side by
    side on up to :data:`DEFAULT_THREADS` threads (the calling thread takes the last).

    The blocks depend on ``n`` and ``blocks`` only, never on the number of threads: a
    product over a block may round differently from one over another block size (BLAS
    kernels split their work by shape), so a split that followed the cores would change
    the last bits with the machine."""
    nb = max(1, min(int(blocks), n))
    bounds = np.linspace(0, n, nb + 1).astype(int)
    pairs = [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    if nb == 1 or DEFAULT_THREADS <= 1:
        for a, b in pairs:
            fn(a, b)
        return
    futures = [_pool().submit(fn, a, b) for a, b in pairs[:-1]]
    fn(*pairs[-1])
    for f in futures:
        f.result()


_LOCK = threading.Lock()
_LIBS: list | None = None


def _openblas_libs() -> list:
    global _LIBS
    if _LIBS is not None:
        return _LIBS
    libs = []
    try:
        with open("/proc/self/maps") as fh:
            paths = sorted({ln.split()[-1] for ln in fh if "openblas" in ln.lower()
                            and ln.split()[-1].startswith("/")})
    except OSError:  # not Linux
        paths = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for prefix in ("scipy_openblas", "openblas"):
            for suffix in ("64_", ""):
                get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                put = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                if get is not None and put is not None:
                    get.restype = ctypes.c_int
                    put.argtypes = [ctypes.c_int]
                    libs.append((get, put))
                    break
            else:
                continue
            break
    _LIBS = libs
    return libs


@contextmanager
def blas_threads(n: int = 1):
    """Run the block with at most ``n`` OpenBLAS threads."""
    with _LOCK:
        libs = _openblas_libs()
        old = [get() for get, _ in libs]
        for _, put in libs:
            put(n)
    try:
        yield
    finally:
        with _LOCK:
            for (_, put), k in zip(libs, old, strict=True):
                put(k)
