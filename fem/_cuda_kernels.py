r"""CUDA kernels of :mod:`fem.gpu` (numba-cuda): arrays and scalars in, no validation.

Imported only by :mod:`fem.gpu` when a GPU solver is made, so that ``import fem`` never
needs numba-cuda; under ``NUMBA_ENABLE_CUDASIM=1`` (set before ``numba.cuda`` is first
imported) they run on numba's CUDA simulator.

Layout: an ensemble block of ``N`` vectors of length ``n`` is one flat float64 array,
member-major (member ``m``'s entry ``i`` at ``m * n + i``), as the solvers' ``(N, nfree)``
right-hand sides. Every kernel runs on a 2-D grid, ``(blocks, N)``: ``blockIdx.y`` is the
member, and the threads of the ``x`` blocks stride over the ``n`` rows. Per-member dot
products take two passes, each block's partial sum (a tree in shared memory) then
:func:`reduce_partials`, in a fixed order: no atomics, so that a solve gives the same
numbers at every run on the same device and launch size.

The matrix of member ``m`` is :math:`A_m = a_m M + b_m K + R`, held once as the CSR
pattern of :math:`|M| + |K| + |R|` with one value array per matrix (``vm``, ``vk``,
``vr``); the diagonals ``dm``, ``dk``, ``dr`` give the Jacobi preconditioner.
"""

from __future__ import annotations

from numba import config, cuda, float64

#: threads per block (a power of two: the reductions halve it); the shared arrays of the
#: reductions have this size. The simulator runs each thread as a Python thread and its
#: barriers poll every thread of the block, a cost that grows as TPB^2: there 16 threads
#: run the same code (the tree reduction, the stride over rows) a hundred times faster.
TPB = 16 if config.ENABLE_CUDASIM else 128


@cuda.jit(device=True)
def _row(indptr, indices, vm, vk, vr, am, bm, x, base, i):
    """Row ``i`` of A_m times member m's block of x (offset ``base``)."""
    s = 0.0
    for j in range(indptr[i], indptr[i + 1]):
        s += (am * vm[j] + bm * vk[j] + vr[j]) * x[base + indices[j]]
    return s


@cuda.jit(device=True)
def _block_sum(buf, value, part, idx):
    """Store ``value`` summed over the block's threads in ``part[idx]``."""
    t = cuda.threadIdx.x
    buf[t] = value
    cuda.syncthreads()
    half = TPB // 2
    while half > 0:
        if t < half:
            buf[t] += buf[t + half]
        cuda.syncthreads()
        half //= 2
    if t == 0:
        part[idx] = buf[0]
    cuda.syncthreads()  # buf is used again by the caller's next sum


@cuda.jit
def reduce_partials(part, nblocks, out):
    """``out[q] = sum(part[q * nblocks:(q + 1) * nblocks])``, one block per sum ``q``."""
    buf = cuda.shared.array(TPB, float64)
    q = cuda.blockIdx.y
    s = 0.0
    for i in range(cuda.threadIdx.x, nblocks, TPB):
        s += part[q * nblocks + i]
    _block_sum(buf, s, out, q)


@cuda.jit(device=True)
def _slot(q):
    """Index in the partial sums of sum ``q`` (0, 1, ...) of this block's member."""
    return (q * cuda.gridDim.y + cuda.blockIdx.y) * cuda.gridDim.x + cuda.blockIdx.x


@cuda.jit
def start(indptr, indices, vm, vk, vr, dm, dk, dr, a, b, n, x, rhs, r, z, p, dinv, part):
    """dinv = 1 / diag(A_m); r = rhs - A_m x; z = dinv r; p = z; the partial sums of
    r.z, r.r and rhs.rhs (sums 0, 1, 2)."""
    buf = cuda.shared.array(TPB, float64)
    m = cuda.blockIdx.y
    am, bm = a[m], b[m]
    base = m * n
    s_rz = s_rr = s_bb = 0.0
    for i in range(cuda.blockIdx.x * TPB + cuda.threadIdx.x, n, cuda.gridDim.x * TPB):
        k = base + i
        d = 1.0 / (am * dm[i] + bm * dk[i] + dr[i])
        ri = rhs[k] - _row(indptr, indices, vm, vk, vr, am, bm, x, base, i)
        zi = d * ri
        dinv[k] = d
        r[k] = ri
        z[k] = zi
        p[k] = zi
        s_rz += ri * zi
        s_rr += ri * ri
        s_bb += rhs[k] * rhs[k]
    _block_sum(buf, s_rz, part, _slot(0))
    _block_sum(buf, s_rr, part, _slot(1))
    _block_sum(buf, s_bb, part, _slot(2))


@cuda.jit
def spmv_dot(indptr, indices, vm, vk, vr, a, b, n, p, ap, part):
    """ap = A_m p; the partial sums of p.ap (sum 0)."""
    buf = cuda.shared.array(TPB, float64)
    m = cuda.blockIdx.y
    am, bm = a[m], b[m]
    base = m * n
    s = 0.0
    for i in range(cuda.blockIdx.x * TPB + cuda.threadIdx.x, n, cuda.gridDim.x * TPB):
        v = _row(indptr, indices, vm, vk, vr, am, bm, p, base, i)
        ap[base + i] = v
        s += p[base + i] * v
    _block_sum(buf, s, part, _slot(0))


@cuda.jit
def update(n, x, r, z, p, ap, dinv, rz, pap, part):
    """alpha = rz / pap; x += alpha p; r -= alpha ap; z = dinv r; the partial sums of the
    new r.z and r.r (sums 0, 1). The guards are BatchedPCG's: a member whose p.Ap is not
    positive (its residual already zero) takes no step."""
    buf = cuda.shared.array(TPB, float64)
    m = cuda.blockIdx.y
    alpha = rz[m] / pap[m] if pap[m] > 0.0 else 0.0
    base = m * n
    s_rz = s_rr = 0.0
    for i in range(cuda.blockIdx.x * TPB + cuda.threadIdx.x, n, cuda.gridDim.x * TPB):
        k = base + i
        x[k] += alpha * p[k]
        ri = r[k] - alpha * ap[k]
        zi = dinv[k] * ri
        r[k] = ri
        z[k] = zi
        s_rz += ri * zi
        s_rr += ri * ri
    _block_sum(buf, s_rz, part, _slot(0))
    _block_sum(buf, s_rr, part, _slot(1))


@cuda.jit
def direction(n, p, z, rz_new, rz):
    """p = z + beta p, beta = rz_new / rz per member."""
    m = cuda.blockIdx.y
    beta = rz_new[m] / rz[m] if rz[m] > 0.0 else 0.0
    base = m * n
    for i in range(cuda.blockIdx.x * TPB + cuda.threadIdx.x, n, cuda.gridDim.x * TPB):
        p[base + i] = z[base + i] + beta * p[base + i]
