r"""Implicit heat steps' linear solves on an NVIDIA GPU (numba-cuda): MCmatlab's ``HS.useGPU``.

:class:`CudaPCG` is a drop-in for the CPU solvers of :mod:`fem.linsolve`: built from the
free-node mass, stiffness and theta-weighted convective matrices ``M, K, R``, it solves
:math:`(a_n M + b_n K + R)\,x_n = r_n` for every member ``n`` of an ensemble with
``solve(r, a, b, x0=None)``, ``r`` (N, nfree). It is :class:`fem.linsolve.BatchedPCG`'s
method on the device: Jacobi-preconditioned conjugate gradients, all members at once, each
stopped when its residual's 2-norm is below ``rtol`` times its right-hand side's
(``rtol = 1e-9`` by default, :class:`fem.HeatStepper`'s).

What stays on the device: the matrices (uploaded once, as one CSR pattern with a value
array per matrix, so that per-member scales cost nothing), the work vectors, and the last
solution, which is the next solve's first guess when no ``x0`` is given (the previous
step's temperatures, for a stepper). What moves per solve: the right-hand side up and the
solution down (the interface's, and :class:`fem.HeatStepper` needs the temperatures on the
host for damage, maxima and probes), ``2 N`` scalars up, and ``N`` residual norms down per
iteration for the stopping test. The dot products are reduced in a fixed order (no
atomics): a solve repeats to the bit on the same device.

:func:`make_solver` checks for a GPU and makes the solver; :class:`fem.HeatStepper` calls it
for ``method="gpu"`` (the heat front end's ``HS.use_gpu``) on its free-node matrices.
``numba.cuda`` is imported only by these, so ``import fem`` never needs numba-cuda (the
``gpu`` extra).

Tested on numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, ``tests/test_fem_gpu.py``)
against :class:`fem.linsolve.DirectSolver` and the CPU stepper. Not yet run or timed on a
real GPU: no GPU was available when it was written; ``benchmarks/bench_heat_gpu.py`` times
it against the CPU where there is one.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

__all__ = ["DEFAULT_RTOL", "CudaPCG", "device_name", "gpu_available", "make_solver"]

#: the relative residual tolerance of :class:`fem.HeatStepper`'s PCG path
DEFAULT_RTOL = 1e-9
#: most thread blocks per member on a GPU (the threads stride over the rows beyond)
MAX_BLOCKS = 1024


def gpu_available() -> bool:
    """Whether a GPU solver can run here: the ``numba-cuda`` package (the ``gpu`` extra) and
    a CUDA GPU, or numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1`` set before
    ``numba.cuda`` is first imported). The same test as ``MC.use_gpu``'s."""
    try:
        from numba import cuda
    except ImportError:
        return False
    return bool(cuda.is_available())


def device_name() -> str:
    """The current CUDA device in words (for reports), or the simulator's name."""
    from numba import cuda

    if _simulated():
        return "numba's CUDA simulator"
    d = cuda.get_current_device()
    name = d.name.decode() if isinstance(d.name, bytes) else str(d.name)
    return f"{name} (compute capability {d.compute_capability[0]}.{d.compute_capability[1]})"


def _simulated() -> bool:
    import numba

    return bool(numba.config.ENABLE_CUDASIM)


def make_solver(M, K, R, *, rtol: float = DEFAULT_RTOL, maxiter: int = 2000,
                device: int = 0, setting: str = "HS.use_gpu") -> CudaPCG:
    """A :class:`CudaPCG` on GPU ``device``, or a RuntimeError saying how to get one.

    Parameters
    ----------
    M, K, R : sparse (nfree, nfree)
        J/K, W/K, W/K: mass, stiffness and theta-weighted convective matrices on the free
        nodes (symmetric; every ``a M + b K + R`` with ``a, b > 0`` positive definite).
    rtol, maxiter
        As :class:`CudaPCG`.
    device : int
        The CUDA device (``numba.cuda.select_device``; ignored by the simulator).
    setting : str
        The user's switch, named in the error message with its alternative
        (``"HS.use_gpu"``: "... Set HS.use_gpu = False to run on the CPU").

    Raises
    ------
    RuntimeError
        When numba-cuda is missing or ``numba.cuda.is_available()`` is False.
    """
    if not gpu_available():
        raise RuntimeError(
            f"{setting} = True needs numba-cuda (pip install 'tissue-enkf[gpu]') and an "
            "NVIDIA GPU with its driver; none was found (numba.cuda.is_available() is False). "
            f"Set {setting} = False to run on the CPU")
    if not _simulated():
        from numba import cuda

        cuda.select_device(int(device))
    return CudaPCG(M, K, R, rtol=rtol, maxiter=maxiter)


class CudaPCG:
    """Jacobi-preconditioned CG for all members at once, on a CUDA GPU.

    Parameters
    ----------
    M, K, R : sparse (nfree, nfree)
        As :class:`fem.linsolve.BatchedPCG`; member ``n``'s matrix is
        ``a_n M + b_n K + R``.
    rtol : float
        Stop when each member's residual 2-norm is below ``rtol`` times its
        right-hand side's.
    maxiter : int
    blocks : int, optional
        Thread blocks per member (default: enough for one row per thread, at most
        :data:`MAX_BLOCKS`; one under the simulator, whose threads are Python threads).

    Attributes
    ----------
    last_iterations : int
        CG iterations of the last solve (matrix products after the first residual).
    """

    def __init__(self, M, K, R, rtol: float = DEFAULT_RTOL, maxiter: int = 2000,
                 blocks: int | None = None):
        from numba import cuda

        from . import _cuda_kernels as KC

        mats = [sp.csr_matrix(A, dtype=float) for A in (M, K, R)]
        n = mats[0].shape[0]
        for name, A in zip("MKR", mats, strict=True):
            if A.shape != (n, n):
                raise ValueError(f"{name} must have shape ({n}, {n}), got {A.shape}")
        if not (math.isfinite(rtol) and rtol > 0):
            raise ValueError(f"rtol must be > 0, got {rtol!r}")
        if int(maxiter) < 1:
            raise ValueError(f"maxiter must be >= 1, got {maxiter!r}")
        self.n, self.rtol, self.maxiter = n, float(rtol), int(maxiter)
        self._cuda, self._K = cuda, KC
        # one CSR pattern (that of |M| + |K| + |R|), one value array per matrix
        S = sp.csr_matrix(abs(mats[0]) + abs(mats[1]) + abs(mats[2]))
        S.sum_duplicates()
        S.sort_indices()
        rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(S.indptr))
        keys = rows * n + S.indices
        values = []
        for A in mats:
            C = A.tocoo()
            C.sum_duplicates()
            v = np.zeros(S.nnz)
            v[np.searchsorted(keys, C.row.astype(np.int64) * n + C.col)] = C.data
            values.append(v)
        index = np.int32 if S.nnz < 2**31 else np.int64
        self.nnz = S.nnz
        host = dict(indptr=S.indptr.astype(index), indices=S.indices.astype(np.int32),
                    vm=values[0], vk=values[1], vr=values[2],
                    dm=mats[0].diagonal(), dk=mats[1].diagonal(), dr=mats[2].diagonal())
        self._A = {k: cuda.to_device(np.ascontiguousarray(v)) for k, v in host.items()}
        if blocks is None:
            blocks = 1 if _simulated() else min(MAX_BLOCKS, -(-n // KC.TPB))
        self.blocks = max(1, int(blocks))
        self._N = 0  # members of the work arrays on the device
        self._has_x = False  # whether _x holds the last solution
        self.last_iterations = 0

    def _allocate(self, N: int) -> None:
        cuda, size = self._cuda, N * self.n
        self._x, self._rhs, self._r, self._z, self._p, self._ap, self._dinv = (
            cuda.device_array(size) for _ in range(7))
        self._part = cuda.device_array(3 * N * self.blocks)
        self._sums = [cuda.device_array(3 * N), cuda.device_array(2 * N)]
        self._pap = cuda.device_array(N)
        self._N, self._has_x = N, False

    def solve(self, r: np.ndarray, a: np.ndarray, b: np.ndarray, x0=None) -> np.ndarray:
        """Solve for all members; r (N, nfree) -> (N, nfree).

        ``x0`` (N, nfree), the first guess; without it, the last solve's solution (kept on
        the device) when it had the same N, else zeros.
        """
        rhs = np.ascontiguousarray(r, dtype=float)
        if rhs.ndim != 2 or rhs.shape[1] != self.n:
            raise ValueError(f"r must have shape (N, {self.n}), got {rhs.shape}")
        N = rhs.shape[0]
        a = np.ascontiguousarray(a, dtype=float)
        b = np.ascontiguousarray(b, dtype=float)
        if a.shape != (N,) or b.shape != (N,):
            raise ValueError(f"a and b must have shape ({N},), got {a.shape} and {b.shape}")
        if N != self._N:
            self._allocate(N)
        cuda, KC, A = self._cuda, self._K, self._A
        self._rhs.copy_to_device(rhs.ravel())
        if x0 is not None:
            x0 = np.ascontiguousarray(x0, dtype=float)
            if x0.shape != rhs.shape:
                raise ValueError(f"x0 must have shape {rhs.shape}, got {x0.shape}")
            self._x.copy_to_device(x0.ravel())
        elif not self._has_x:
            self._x.copy_to_device(np.zeros(N * self.n))
        self._has_x = False  # until this solve converges
        d_a, d_b = cuda.to_device(a), cuda.to_device(b)
        grid, tpb, gx, n = (self.blocks, N), KC.TPB, self.blocks, self.n
        mat = (A["indptr"], A["indices"], A["vm"], A["vk"], A["vr"])
        x, r_, z, p, ap, part = self._x, self._r, self._z, self._p, self._ap, self._part
        cur, nxt = self._sums
        pap = self._pap

        KC.start[grid, tpb](*mat, A["dm"], A["dk"], A["dr"], d_a, d_b, n, x, self._rhs, r_, z,
                            p, self._dinv, part)
        KC.reduce_partials[(1, 3 * N), tpb](part, gx, cur)  # [r.z | r.r | rhs.rhs]
        sums = cur.copy_to_host()
        bnorm = np.sqrt(sums[2 * N:])
        bnorm[bnorm == 0] = 1.0
        rr = sums[N:2 * N]
        it = 0
        for it in range(1, self.maxiter + 1):  # noqa: B007 - count kept for diagnostics
            if np.all(np.sqrt(rr) <= self.rtol * bnorm):
                it -= 1
                break
            KC.spmv_dot[grid, tpb](*mat, d_a, d_b, n, p, ap, part)
            KC.reduce_partials[(1, N), tpb](part, gx, pap)
            KC.update[grid, tpb](n, x, r_, z, p, ap, self._dinv, cur[:N], pap, part)
            KC.reduce_partials[(1, 2 * N), tpb](part, gx, nxt)  # [new r.z | r.r]
            KC.direction[grid, tpb](n, p, z, nxt[:N], cur[:N])
            cur, nxt = nxt, cur
            rr = cur[N:2 * N].copy_to_host()
        else:
            raise RuntimeError(f"PCG did not converge in maxiter={self.maxiter} iterations "
                               "on the GPU")
        self._has_x = True
        self.last_iterations = it
        return x.copy_to_host().reshape(N, n)
