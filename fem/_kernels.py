"""numba kernels of the fem package: arrays and scalars in, no validation.

The Python layer (:mod:`fem.assembly`, :mod:`fem.locate`) checks shapes and
dtypes once and calls these.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _tet_inverse(p, t, e, G):
    """Fill G (3, 3) with rows = gradients of barycentrics 1..3; return signed 6V."""
    i0 = t[0, e]
    a00 = p[0, t[1, e]] - p[0, i0]
    a10 = p[1, t[1, e]] - p[1, i0]
    a20 = p[2, t[1, e]] - p[2, i0]
    a01 = p[0, t[2, e]] - p[0, i0]
    a11 = p[1, t[2, e]] - p[1, i0]
    a21 = p[2, t[2, e]] - p[2, i0]
    a02 = p[0, t[3, e]] - p[0, i0]
    a12 = p[1, t[3, e]] - p[1, i0]
    a22 = p[2, t[3, e]] - p[2, i0]
    c00 = a11 * a22 - a12 * a21
    c01 = a12 * a20 - a10 * a22
    c02 = a10 * a21 - a11 * a20
    det = a00 * c00 + a01 * c01 + a02 * c02
    inv = 1.0 / det
    # rows of the inverse of the edge matrix A = [v1-v0, v2-v0, v3-v0]
    # (columns): inverse = adjugate / det, adjugate[i, j] = cofactor[j, i]
    G[0, 0] = c00 * inv
    G[1, 0] = c01 * inv
    G[2, 0] = c02 * inv
    G[0, 1] = (a02 * a21 - a01 * a22) * inv
    G[1, 1] = (a00 * a22 - a02 * a20) * inv
    G[2, 1] = (a01 * a20 - a00 * a21) * inv
    G[0, 2] = (a01 * a12 - a02 * a11) * inv
    G[1, 2] = (a02 * a10 - a00 * a12) * inv
    G[2, 2] = (a00 * a11 - a01 * a10) * inv
    return det


@numba.njit(cache=True)
def tet_volumes(p, t, out):
    """Signed volumes of all elements."""
    for e in range(t.shape[1]):
        i0 = t[0, e]
        a0 = p[0, t[1, e]] - p[0, i0]
        a1 = p[1, t[1, e]] - p[1, i0]
        a2 = p[2, t[1, e]] - p[2, i0]
        b0 = p[0, t[2, e]] - p[0, i0]
        b1 = p[1, t[2, e]] - p[1, i0]
        b2 = p[2, t[2, e]] - p[2, i0]
        c0 = p[0, t[3, e]] - p[0, i0]
        c1 = p[1, t[3, e]] - p[1, i0]
        c2 = p[2, t[3, e]] - p[2, i0]
        out[e] = (a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0)
                  + a2 * (b0 * c1 - b1 * c0)) / 6.0


@numba.njit(cache=True)
def _element_matrix(p, t, e, kind, G, g, out):
    """Local 4x4 matrix of element e: kind 0 stiffness, 1 consistent mass (no coefficient)."""
    det = _tet_inverse(p, t, e, G)
    vol = abs(det) / 6.0
    if kind == 0:
        for d in range(3):
            g[1, d] = G[0, d]
            g[2, d] = G[1, d]
            g[3, d] = G[2, d]
            g[0, d] = -(G[0, d] + G[1, d] + G[2, d])
        for a in range(4):
            for b in range(4):
                out[a, b] = vol * (g[a, 0] * g[b, 0] + g[a, 1] * g[b, 1] + g[a, 2] * g[b, 2])
    else:
        for a in range(4):
            for b in range(4):
                out[a, b] = vol / 20.0 * (2.0 if a == b else 1.0)


@numba.njit(cache=True)
def scatter_rows(p, t, coef, kind, indptr, cols, vals):
    """Write the 16 entries of every element into per-row buckets (with duplicates).

    ``indptr`` holds the bucket starts (4 entries per element per row).
    """
    G = np.empty((3, 3))
    g = np.empty((4, 3))
    loc = np.empty((4, 4))
    fill = indptr[:-1].copy()
    for e in range(t.shape[1]):
        _element_matrix(p, t, e, kind, G, g, loc)
        for a in range(4):
            r = t[a, e]
            k = fill[r]
            fill[r] = k + 4
            for b in range(4):
                cols[k + b] = t[b, e]
                vals[k + b] = coef[e] * loc[a, b]


@numba.njit(cache=True)
def merge_rows(indptr, cols, vals, prune_rtol, counts):
    """Sort each row bucket by column, sum duplicates, drop |v| <= rtol |diag|."""
    n = indptr.shape[0] - 1
    for r in range(n):
        s, e = indptr[r], indptr[r + 1]
        order = np.argsort(cols[s:e], kind="mergesort")
        c = cols[s:e][order]
        v = vals[s:e][order]
        m = 0
        diag = 0.0
        for q in range(e - s):
            if m > 0 and c[q] == cols[s + m - 1]:
                vals[s + m - 1] += v[q]
            else:
                cols[s + m] = c[q]
                vals[s + m] = v[q]
                m += 1
        for q in range(m):
            if cols[s + q] == r:
                diag = abs(vals[s + q])
        w = 0
        for q in range(m):
            if cols[s + q] == r or abs(vals[s + q]) > prune_rtol * diag:
                cols[s + w] = cols[s + q]
                vals[s + w] = vals[s + q]
                w += 1
        counts[r] = w


@numba.njit(cache=True)
def compact_rows(indptr, cols, vals, counts):
    """Move the merged rows together; return the final indptr."""
    n = indptr.shape[0] - 1
    out = np.empty(n + 1, dtype=indptr.dtype)
    out[0] = 0
    w = 0
    for r in range(n):
        s = indptr[r]
        for q in range(counts[r]):
            cols[w] = cols[s + q]
            vals[w] = vals[s + q]
            w += 1
        out[r + 1] = w
    return out


@numba.njit(cache=True)
def build_buckets(p, t, lo, inv_h, nb):
    """Bucket grid of element bounding boxes: CSR (start, items)."""
    ne = t.shape[1]
    counts = np.zeros(nb[0] * nb[1] * nb[2] + 1, dtype=np.int64)
    rng = np.empty((ne, 6), dtype=np.int64)
    for e in range(ne):
        for d in range(3):
            mn = np.inf
            mx = -np.inf
            for a in range(4):
                v = p[d, t[a, e]]
                mn = min(mn, v)
                mx = max(mx, v)
            i0 = int(np.floor((mn - lo[d]) * inv_h[d] - 1e-9))
            i1 = int(np.floor((mx - lo[d]) * inv_h[d] + 1e-9))
            rng[e, 2 * d] = min(max(i0, 0), nb[d] - 1)
            rng[e, 2 * d + 1] = min(max(i1, 0), nb[d] - 1)
        for i in range(rng[e, 0], rng[e, 1] + 1):
            for j in range(rng[e, 2], rng[e, 3] + 1):
                for k in range(rng[e, 4], rng[e, 5] + 1):
                    counts[(i * nb[1] + j) * nb[2] + k + 1] += 1
    start = np.cumsum(counts)
    fill = start[:-1].copy()
    items = np.empty(start[-1], dtype=np.int64)
    for e in range(ne):
        for i in range(rng[e, 0], rng[e, 1] + 1):
            for j in range(rng[e, 2], rng[e, 3] + 1):
                for k in range(rng[e, 4], rng[e, 5] + 1):
                    b = (i * nb[1] + j) * nb[2] + k
                    items[fill[b]] = e
                    fill[b] += 1
    return start, items


@numba.njit(cache=True)
def locate_points(x, p, t, lo, inv_h, nb, start, items, tol, elem, bary):
    """Containing element and barycentrics of each point; elem = -1 if none.

    Among the candidate elements the one with the largest smallest barycentric
    wins, so points on shared faces get a valid element.  Barycentrics within
    ``tol`` of the element are clipped to [0, 1] and renormalised to sum 1.
    """
    G = np.empty((3, 3))
    lam = np.empty(4)
    npt = x.shape[1]
    for q in range(npt):
        elem[q] = -1
        ib = np.empty(3, dtype=np.int64)
        outside = False
        for d in range(3):
            s = (x[d, q] - lo[d]) * inv_h[d]
            i = int(np.floor(s))
            if i < 0:
                if s < -1e-6:
                    outside = True
                i = 0
            if i >= nb[d]:
                if s > nb[d] + 1e-6:
                    outside = True
                i = nb[d] - 1
            ib[d] = i
        if outside:
            continue
        b = (ib[0] * nb[1] + ib[1]) * nb[2] + ib[2]
        best = -np.inf
        for r in range(start[b], start[b + 1]):
            e = items[r]
            _tet_inverse(p, t, e, G)
            i0 = t[0, e]
            dx = x[0, q] - p[0, i0]
            dy = x[1, q] - p[1, i0]
            dz = x[2, q] - p[2, i0]
            l1 = G[0, 0] * dx + G[0, 1] * dy + G[0, 2] * dz
            l2 = G[1, 0] * dx + G[1, 1] * dy + G[1, 2] * dz
            l3 = G[2, 0] * dx + G[2, 1] * dy + G[2, 2] * dz
            l0 = 1.0 - l1 - l2 - l3
            m = min(min(l0, l1), min(l2, l3))
            if m > best:
                best = m
                elem[q] = e
                lam[0] = l0
                lam[1] = l1
                lam[2] = l2
                lam[3] = l3
                if m >= 0.0:
                    break
        if best < -tol:
            elem[q] = -1
            continue
        s = 0.0
        for a in range(4):
            lam[a] = min(max(lam[a], 0.0), 1.0)
            s += lam[a]
        for a in range(4):
            bary[a, q] = lam[a] / s


@numba.njit(cache=True, nogil=True, fastmath=True)
def edge_partials(X, dinv, Fz, Fx, Z1, X1):
    """Thin contractions of Y = X * dinv (B, Px, Py, Pz) onto boundary rows.

    Z1[b, p, q, k] = sum_r Y[b, p, q, r] Fz[b', k, r] and
    X1[b, i, q, r] = sum_p Fx[b'', i, p] Y[b, p, q, r], where b' = b if the
    basis is per member (leading size B) else 0; one pass over Y.  Fz and Fx
    have exactly 2 rows (zero-padded by the caller) so the loops vectorize.
    """
    B, Px, Py, Pz = X.shape
    for b in range(B):
        bz = b if Fz.shape[0] > 1 else 0
        bx = b if Fx.shape[0] > 1 else 0
        fz0 = Fz[bz, 0]
        fz1 = Fz[bz, 1]
        X1[b] = 0.0
        for p in range(Px):
            fx0 = Fx[bx, 0, p]
            fx1 = Fx[bx, 1, p]
            for q in range(Py):
                x = X[b, p, q]
                d = dinv[b, p, q]
                o0 = X1[b, 0, q]
                o1 = X1[b, 1, q]
                a0 = 0.0
                a1 = 0.0
                for r in range(Pz):
                    y = x[r] * d[r]
                    a0 += y * fz0[r]
                    a1 += y * fz1[r]
                    o0[r] += fx0 * y
                    o1[r] += fx1 * y
                Z1[b, p, q, 0] = a0
                Z1[b, p, q, 1] = a1


@numba.njit(cache=True, nogil=True, fastmath=True)
def correct_modes(X, dinv, Axy, Fz, Bz, Fx, out):
    """out = (X - Axy . Fz - Fx^T . Bz) * dinv: the corrected mode coefficients.

    Axy (B, Px, Py, 2) expands along z with Fz (., 2, Pz); Bz (B, 2, Py, Pz)
    expands along x with Fx (., 2, Px); one pass over the full arrays.
    """
    B, Px, Py, Pz = X.shape
    for b in range(B):
        bz = b if Fz.shape[0] > 1 else 0
        bx = b if Fx.shape[0] > 1 else 0
        fz0 = Fz[bz, 0]
        fz1 = Fz[bz, 1]
        for p in range(Px):
            fx0 = Fx[bx, 0, p]
            fx1 = Fx[bx, 1, p]
            for q in range(Py):
                x = X[b, p, q]
                d = dinv[b, p, q]
                g0 = Bz[b, 0, q]
                g1 = Bz[b, 1, q]
                a0 = Axy[b, p, q, 0]
                a1 = Axy[b, p, q, 1]
                o = out[b, p, q]
                for r in range(Pz):
                    o[r] = (x[r] - a0 * fz0[r] - a1 * fz1[r] - fx0 * g0[r] - fx1 * g1[r]) * d[r]


@numba.njit(cache=True, nogil=True)
def lumped_rhs(T, a, m, g, f, out):
    """out[n, i] = a[n] m[i] T[n, i] + g[i] + f[n or 0, i]: one pass over the ensemble."""
    N, n = T.shape
    one = f.shape[0] == 1
    for k in range(N):
        fk = f[0] if one else f[k]
        ak = a[k]
        for i in range(n):
            out[k, i] = ak * m[i] * T[k, i] + g[i] + fk[i]


@numba.njit(cache=True, nogil=True, inline="always")
def _tri_z(X, d, o, out):
    """out = (I ⊗ I ⊗ T) X for the tridiagonal T (diagonal ``d``, off-diagonal ``o``)."""
    nx, ny, nz = X.shape
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                v = d[k] * X[i, j, k]
                if k > 0:
                    v += o[k - 1] * X[i, j, k - 1]
                if k < nz - 1:
                    v += o[k] * X[i, j, k + 1]
                out[i, j, k] = v


@numba.njit(cache=True, nogil=True, inline="always")
def _tri_y(X, d, o, out, add):
    """out (+)= (I ⊗ T ⊗ I) X (added to ``out`` where ``add``)."""
    nx, ny, nz = X.shape
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                v = d[j] * X[i, j, k]
                if j > 0:
                    v += o[j - 1] * X[i, j - 1, k]
                if j < ny - 1:
                    v += o[j] * X[i, j + 1, k]
                if add:
                    out[i, j, k] += v
                else:
                    out[i, j, k] = v


@numba.njit(cache=True, nogil=True)
def tridiag3_rhs(T, a, dx, ox, dy, oy, dz, oz, scale, g, f, out):
    """out[n] = a[n] scale (Mx ⊗ My ⊗ Mz) T[n] + g + f[n or 0] for tridiagonal 1-D masses.

    T (N, nx, ny, nz) C order; ``d*`` the 1-D diagonals, ``o*`` the off-diagonals
    (``o*[i]`` couples nodes i and i + 1: constant on a homogeneous box, weighted by the
    layers' VHC along z); ``g`` (nx*ny*nz,), ``f`` (1 or N, nx*ny*nz); out (N, nx*ny*nz).
    The three 1-D products are applied one axis at a time (9 instead of 27 flops
    per node).
    """
    N, nx, ny, nz = T.shape
    one = f.shape[0] == 1
    A = np.empty((nx, ny, nz))
    B = np.empty((nx, ny, nz))
    for n in range(N):
        _tri_z(T[n], dz, oz, A)
        _tri_y(A, dy, oy, B, False)
        fn = f[0] if one else f[n]
        c = a[n] * scale
        for i in range(nx):  # x, then scale and add the loads
            for j in range(ny):
                for k in range(nz):
                    v = dx[i] * B[i, j, k]
                    if i > 0:
                        v += ox[i - 1] * B[i - 1, j, k]
                    if i < nx - 1:
                        v += ox[i] * B[i + 1, j, k]
                    q = (i * ny + j) * nz + k
                    out[n, q] = c * v + g[q] + fn[q]


@numba.njit(cache=True, nogil=True)
def tridiag3_theta_rhs(T, a, beta, mass, stiff, mzk, g, f, out):
    """out[n] = a[n] (Mx ⊗ My ⊗ Mz) T[n] - beta[n] K T[n] + g + f[n or 0], with
    ``K = Kx ⊗ My ⊗ Mz' + Mx ⊗ Ky ⊗ Mz' + Mx ⊗ My ⊗ Kz``: the right-hand side of a theta
    step on the tensor-product operator in one pass (beta = (1 - theta) x the member's TC
    factor), without the 27-point stiffness product and its temporaries.

    T (N, nx, ny, nz), any strides; ``mass`` = (dx, ox, dy, oy, dz, oz) the 1-D masses
    (diagonals, off-diagonals; the VHC folded into the z factor), ``stiff`` = (kdx, kox, kdy, koy, kdz,
    koz) the 1-D stiffnesses and ``mzk`` = (dz', oz') the z mass of K's cross terms (the TC
    folded into the z factors; equal to the mass's z factor on one medium); ``g``
    (nx*ny*nz,), ``f`` (1 or N, nx*ny*nz); out (N, nx*ny*nz).
    """
    N, nx, ny, nz = T.shape
    dx, ox, dy, oy, dz, oz = mass
    kdx, kox, kdy, koy, kdz, koz = stiff
    md, mo = mzk
    one = f.shape[0] == 1
    Zc = np.empty((nx, ny, nz))
    Zm = np.empty((nx, ny, nz))
    Zk = np.empty((nx, ny, nz))
    Y1 = np.empty((nx, ny, nz))
    Y2 = np.empty((nx, ny, nz))
    Y3 = np.empty((nx, ny, nz))
    for n in range(N):
        X = T[n]
        _tri_z(X, dz, oz, Zc)
        _tri_z(X, md, mo, Zm)
        _tri_z(X, kdz, koz, Zk)
        _tri_y(Zc, dy, oy, Y1, False)     # My Mz X (the mass)
        _tri_y(Zm, dy, oy, Y2, False)     # My Mz' X (under Kx)
        _tri_y(Zm, kdy, koy, Y3, False)   # Ky Mz' X + My Kz X (under Mx)
        _tri_y(Zk, dy, oy, Y3, True)
        fn = f[0] if one else f[n]
        an = a[n]
        bn = beta[n]
        for i in range(nx):  # x: Mx (a Y1 - beta Y3) - beta Kx Y2, and the loads
            for j in range(ny):
                for k in range(nz):
                    v = dx[i] * (an * Y1[i, j, k] - bn * Y3[i, j, k]) \
                        - bn * kdx[i] * Y2[i, j, k]
                    if i > 0:
                        v += ox[i - 1] * (an * Y1[i - 1, j, k] - bn * Y3[i - 1, j, k]) \
                            - bn * kox[i - 1] * Y2[i - 1, j, k]
                    if i < nx - 1:
                        v += ox[i] * (an * Y1[i + 1, j, k] - bn * Y3[i + 1, j, k]) \
                            - bn * kox[i] * Y2[i + 1, j, k]
                    q = (i * ny + j) * nz + k
                    out[n, q] = v + g[q] + fn[q]


@numba.njit(cache=True, nogil=True)
def layered_modes_solve(Y, mux, muy, alpha, beta, cd, co, kd, ko, md, mo, hd):
    """Solve, in place, the z-tridiagonal system of every member and (x, y) mode.

    Y (B, Px, Pz, Py): right-hand sides in x-y modal coordinates, z nodal; mode (p, q)
    of member b solves ``(alpha[b] Mc + beta[b] (Kk + (mux[p] + muy[q]) Mk) + Hd) y = Y``
    with ``Mc`` (``cd`` diagonal, ``co`` off-diagonal), ``Kk`` (``kd``, ``ko``) and
    ``Mk`` (``md``, ``mo``) symmetric tridiagonal and ``Hd`` diagonal. The matrices
    are symmetric positive definite and diagonally dominant: Thomas's algorithm,
    without pivoting, factorizing on the fly (per-member coefficients cost nothing).
    The y modes are the innermost, contiguous axis: the recurrences in z of the Py
    systems run side by side (SIMD lanes, overlapping divisions) instead of one
    latency-bound chain per system.
    """
    B, Px, Pz, Py = Y.shape
    cp = np.empty((Pz, Py))
    bl = np.empty(Py)
    ad = np.empty(Pz)
    ao = np.empty(Pz)
    for b in range(B):
        a = alpha[b]
        bb = beta[b]
        for r in range(Pz):
            ad[r] = a * cd[r] + bb * kd[r] + hd[r]
        for r in range(Pz - 1):
            ao[r] = a * co[r] + bb * ko[r]
        for p in range(Px):
            for q in range(Py):
                bl[q] = bb * (mux[p] + muy[q])
            X = Y[b, p]
            for q in range(Py):
                inv = 1.0 / (ad[0] + bl[q] * md[0])
                X[0, q] *= inv
                if Pz > 1:
                    cp[0, q] = (ao[0] + bl[q] * mo[0]) * inv
            for r in range(1, Pz):
                for q in range(Py):
                    lo = ao[r - 1] + bl[q] * mo[r - 1]
                    inv = 1.0 / (ad[r] + bl[q] * md[r] - lo * cp[r - 1, q])
                    X[r, q] = (X[r, q] - lo * X[r - 1, q]) * inv
                    if r < Pz - 1:
                        cp[r, q] = (ao[r] + bl[q] * mo[r]) * inv
            for r in range(Pz - 2, -1, -1):
                for q in range(Py):
                    X[r, q] -= cp[r, q] * X[r + 1, q]


@numba.njit(cache=True, nogil=True)
def group_maxima(T, nodes, starts, out):
    """out[g] = max(out[g], max T[nodes[starts[g]:starts[g + 1]]]): the groups' running
    maxima in one pass, no gathered copy."""
    for g in range(starts.size - 1):
        m = out[g]
        for k in range(starts[g], starts[g + 1]):
            v = T[nodes[k]]
            if v > m:
                m = v
        out[g] = m


@numba.njit(cache=True)
def kuhn_elements(nx, ny, nz, local, out):
    """out (4, 6 nx ny nz): the six Kuhn elements of each voxel, voxel v's as 6 v .. 6 v + 5;
    ``local`` (6, 4) their node-number offsets from the voxel's low corner."""
    sy = nz + 1
    sx = (ny + 1) * sy
    e = 0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                base = i * sx + j * sy + k
                for s in range(6):
                    for a in range(4):
                        out[a, e] = base + local[s, a]
                    e += 1


@numba.njit(cache=True, inline="always")
def banded_row(i, n, diag, off, strides, Y):
    """(A Y)_i for a symmetric A with ``diag`` and, per stride ``o``, the couplings
    ``off[k, i] = A[i, i + o]`` (0 where none), near the ends of the vector. Summed in the
    order of the columns, as a CSR row is: the same number to the last bit."""
    acc = 0.0
    for k in range(2, -1, -1):
        o = strides[k]
        if i >= o:
            acc += off[k, i - o] * Y[i - o]
    acc += diag[i] * Y[i]
    for k in range(3):
        o = strides[k]
        if i + o < n:
            acc += off[k, i] * Y[i + o]
    return acc


@numba.njit(cache=True, inline="always")
def banded_at(i, n, diag, off, strides, Y):
    """(A Y)_i for A banded (:func:`fem.banded.banded_operator`: three strides, sorted),
    summed in the order of the columns (:func:`banded_row`)."""
    o1, o2, o3 = strides[0], strides[1], strides[2]
    if o3 <= i < n - o3:  # every neighbour exists: no branches
        acc = off[2, i - o3] * Y[i - o3]
        acc += off[1, i - o2] * Y[i - o2]
        acc += off[0, i - o1] * Y[i - o1]
        acc += diag[i] * Y[i]
        acc += off[0, i] * Y[i + o1]
        acc += off[1, i] * Y[i + o2]
        acc += off[2, i] * Y[i + o3]
        return acc
    return banded_row(i, n, diag, off, strides, Y)


@numba.njit(cache=True)
def banded_from_csr(indptr, indices, data, diag, off, strides):
    """Fill ``diag`` and ``off`` (3, n) from a CSR matrix; ``strides`` (3,) gets the
    distances above the diagonal. False if the pattern has more than three distances or
    an entry without its mirror image of equal value."""
    n = indptr.size - 1
    m = 0  # distances found
    upper = np.zeros(3, np.int64)
    lower = np.zeros(3, np.int64)
    for i in range(n):
        for q in range(indptr[i], indptr[i + 1]):
            o = indices[q] - i
            v = data[q]
            if o == 0:
                diag[i] += v
                continue
            d = o if o > 0 else -o
            k = -1
            for r in range(m):
                if strides[r] == d:
                    k = r
            if k < 0:
                if m == 3:
                    return False
                strides[m] = d
                k = m
                m += 1
            if o > 0:
                off[k, i] += v
                upper[k] += 1
            else:  # row i + o's entry at distance d, read before this row
                if off[k, i + o] != v:
                    return False
                lower[k] += 1
    for k in range(3):
        if upper[k] != lower[k]:
            return False
    # unused distances: beyond the last row, so that they couple nothing
    big = 1
    for k in range(m):
        big = max(big, strides[k] + 1)
    for k in range(m, 3):
        strides[k] = big
    return True


@numba.njit(cache=True)
def locate_structured(x, lower, spacing, shape, path_of_order, swapped, tol, elem, bary):
    """:func:`fem.locate.locate` on ``box_mesh``: for each point (column of ``x``) its voxel
    and Kuhn simplex from the coordinates, and the barycentrics in closed form (the
    arithmetic of the vectorised version, so the same numbers to the last bit)."""
    f = np.empty(3)
    ijk = np.empty(3, np.int64)
    for p in range(x.shape[1]):
        inside = True
        for a in range(3):
            u = (x[a, p] - lower[a]) / spacing[a]
            if not (u >= -tol and u <= shape[a] + tol):
                inside = False
            c = np.int64(np.floor(u)) if np.isfinite(u) else 0
            c = min(max(c, 0), shape[a] - 1)
            ijk[a] = c
            f[a] = min(max(u - c, 0.0), 1.0)
        if not inside:
            elem[p] = -1
            for r in range(4):
                bary[r, p] = 0.0
            continue
        # the axes by decreasing f, ties in axis order (a stable sort of -f)
        o0, o1, o2 = 0, 1, 2
        if f[o1] > f[o0]:
            o0, o1 = o1, o0
        if f[o2] > f[o1]:
            o1, o2 = o2, o1
            if f[o1] > f[o0]:
                o0, o1 = o1, o0
        s = path_of_order[3 * o0 + o1]
        v = (ijk[0] * shape[1] + ijk[1]) * shape[2] + ijk[2]
        elem[p] = 6 * v + s
        bary[0, p] = 1.0 - f[o0]
        bary[1, p] = f[o0] - f[o1]
        if swapped[s]:
            bary[2, p] = f[o2]
            bary[3, p] = f[o1] - f[o2]
        else:
            bary[2, p] = f[o1] - f[o2]
            bary[3, p] = f[o2]


@numba.njit(cache=True)
def seven_point_csr(diag, w, strides, indptr, indices, data):
    """The CSR arrays of the symmetric 7-point matrix with ``diag`` (n,) on the diagonal and
    ``-w[a, i]`` at (i, i + strides[a]) and (i + strides[a], i); strides sorted ascending.
    Columns in order, exact zeros left out (as DIA to CSR and ``eliminate_zeros``); returns
    the number of entries."""
    n = diag.size
    q = 0
    indptr[0] = 0
    for i in range(n):
        for a in range(2, -1, -1):
            s = strides[a]
            if i >= s and w[a, i - s] != 0.0:
                indices[q] = i - s
                data[q] = -w[a, i - s]
                q += 1
        if diag[i] != 0.0:
            indices[q] = i
            data[q] = diag[i]
            q += 1
        for a in range(3):
            s = strides[a]
            if i + s < n and w[a, i] != 0.0:
                indices[q] = i + s
                data[q] = -w[a, i]
                q += 1
        indptr[i + 1] = q
    return q
