"""Limit OpenBLAS threads around small dense products (a threadpoolctl in miniature).

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
import threading
from contextlib import contextmanager

__all__ = ["blas_threads"]

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
