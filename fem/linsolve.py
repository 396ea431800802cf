r"""Sparse solvers for the implicit step matrices of an ensemble.

Member ``n`` solves :math:`(a_n M + b_n K + \theta R)\,x_n = r_n` on the free
nodes, with per-member scalars ``a_n`` (VHC scale / dt) and ``b_n`` (theta x
TC scale).  Both solvers take the matrices once and never refactorize per step:

- :class:`DirectSolver` keeps one sparse LU (SuperLU) per distinct ``(a, b)``
  pair, built the first time the pair is seen;
- :class:`BatchedPCG` runs preconditioned conjugate gradients for all members
  at once (one sparse matrix times an (nfree, N) block per iteration),
  warm-started from the previous temperatures, with a Jacobi preconditioner or
  a given one (the stepper passes fast diagonalization of the homogenized
  operator on structured meshes).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["BatchedPCG", "DirectSolver"]


class DirectSolver:
    """Cached sparse LU factorizations, one per distinct pair of scalars.

    Parameters
    ----------
    M, K, R : sparse (nfree, nfree)
        Mass, stiffness and theta-weighted convective matrices on free nodes.
    max_cached : int
        Factorizations kept (least recently used dropped beyond).
    """

    def __init__(self, M, K, R, max_cached: int = 64):
        self.M, self.K, self.R = sp.csc_matrix(M), sp.csc_matrix(K), sp.csc_matrix(R)
        self.max_cached = max_cached
        self._lu: dict = {}

    def _factor(self, a: float, b: float):
        key = (a, b)
        lu = self._lu.pop(key, None)
        if lu is None:
            A = (a * self.M + b * self.K + self.R).tocsc()
            lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A")
        self._lu[key] = lu  # most recent last
        while len(self._lu) > self.max_cached:
            self._lu.pop(next(iter(self._lu)))
        return lu

    def solve(self, r: np.ndarray, a: np.ndarray, b: np.ndarray, x0=None) -> np.ndarray:
        """Solve for all members; r (N, nfree) -> (N, nfree)."""
        out = np.empty_like(r)
        pairs = np.stack([a, b], axis=1)
        uniq, inv = np.unique(pairs, axis=0, return_inverse=True)
        inv = inv.ravel()
        for u, (ua, ub) in enumerate(uniq):
            members = np.flatnonzero(inv == u)
            lu = self._factor(float(ua), float(ub))
            out[members] = lu.solve(np.ascontiguousarray(r[members].T)).T
        return out


class BatchedPCG:
    r"""Jacobi-preconditioned CG for all members at once.

    Parameters
    ----------
    M, K, R : sparse (nfree, nfree)
    rtol : float
        Stop when each member's residual 2-norm is below ``rtol`` times its
        right-hand side's.
    maxiter : int
    precond : callable, optional
        ``precond(R, a, b) -> Z`` approximately solving ``A_n z_n = r_n`` for
        residual columns R (nfree, N); default Jacobi.
    jacobi_below : float
        With ``precond``: solves whose step matrix is this close to its diagonal, i.e.
        :math:`\max_{i,n} (b_n K_{ii} + R_{ii}) / (a_n M_{ii})` below it (short steps: the
        mass dominates), use Jacobi instead, whose iterations then cost a fraction of the
        preconditioner's for as few or fewer of them. 0 (default): never.
    """

    def __init__(self, M, K, R, rtol: float = 1e-10, maxiter: int = 2000, precond=None,
                 jacobi_below: float = 0.0):
        self.M, self.K, self.R = sp.csr_matrix(M), sp.csr_matrix(K), sp.csr_matrix(R)
        self.m_diag = self.M.diagonal()
        self.k_diag = self.K.diagonal()
        self.r_diag = self.R.diagonal()
        self.M_is_diag = self.M.nnz == np.count_nonzero(self.m_diag)
        self.R_is_diag = self.R.nnz == np.count_nonzero(self.r_diag)
        self.rtol, self.maxiter = rtol, maxiter
        self.precond = precond
        self.jacobi_below = float(jacobi_below)
        if self.jacobi_below > 0:  # the diagonal's stiffness over mass, per unit scale
            m = np.where(self.m_diag > 0, self.m_diag, np.inf)
            self._k_over_m = float(np.max(self.k_diag / m))
            self._r_over_m = float(np.max(self.r_diag / m))
        self.last_iterations = 0
        self.last_jacobi = False

    def _operator(self, a, b):
        """X -> A X for columns X (nfree, N), A_n = a_n M + b_n K + R."""
        if self.M_is_diag and self.R_is_diag:
            D = self.m_diag[:, None] * a + self.r_diag[:, None]

            def matvec(X):
                Y = self.K @ X
                Y *= b
                Y += D * X
                return Y
        else:
            def matvec(X):
                return (self.M @ X) * a + (self.K @ X) * b + self.R @ X
        return matvec

    def solve(self, r: np.ndarray, a: np.ndarray, b: np.ndarray, x0=None) -> np.ndarray:
        """Solve for all members; r (N, nfree) -> (N, nfree); x0 the initial guess."""
        B = np.ascontiguousarray(r.T)
        # a copy: for one member x0.T is contiguous already, and X is updated in place
        X = np.zeros_like(B) if x0 is None else np.array(x0.T, dtype=float, order="C")
        jacobi = self.precond is None
        if not jacobi and self.jacobi_below > 0:
            a_min = float(np.min(a))
            stiff = (float(np.max(b / a)) * self._k_over_m + self._r_over_m / a_min
                     if a_min > 0 else np.inf)
            jacobi = stiff < self.jacobi_below
        self.last_jacobi = jacobi
        if jacobi:
            dinv = 1.0 / (self.m_diag[:, None] * a + self.k_diag[:, None] * b
                          + self.r_diag[:, None])

            def prec(Rr):
                return dinv * Rr
        else:
            def prec(Rr):
                return self.precond(Rr, a, b)
        matvec = self._operator(a, b)
        Rr = B - matvec(X)
        bnorm = np.linalg.norm(B, axis=0)
        bnorm[bnorm == 0] = 1.0
        Z = prec(Rr)
        P = Z.copy()
        rz = np.einsum("ij,ij->j", Rr, Z)
        it = 0
        for it in range(1, self.maxiter + 1):  # noqa: B007 - count kept for diagnostics
            if np.all(np.linalg.norm(Rr, axis=0) <= self.rtol * bnorm):
                it -= 1
                break
            AP = matvec(P)
            pap = np.einsum("ij,ij->j", P, AP)
            alpha = np.where(pap > 0, rz / np.where(pap > 0, pap, 1.0), 0.0)
            X += alpha * P
            Rr -= alpha * AP
            Z = prec(Rr)
            rz_new = np.einsum("ij,ij->j", Rr, Z)
            beta = np.where(rz > 0, rz_new / np.where(rz > 0, rz, 1.0), 0.0)
            P = Z + beta * P
            rz = rz_new
        else:
            raise RuntimeError(f"PCG did not converge in maxiter={self.maxiter} iterations")
        self.last_iterations = it
        return X.T
