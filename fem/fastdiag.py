r"""Fast-diagonalization solver for implicit heat steps on structured box meshes.

On :func:`fem.mesh.box_mesh` with homogeneous VHC ``c`` and TC ``k``, lumped
mass and boundary conditions that hold on whole faces, the implicit matrix of a
theta step for ensemble member ``n`` is

.. math::

    A_n = \alpha_n M + \beta_n K + \theta R, \qquad
    \alpha_n = s^{c}_n c / \Delta t,\quad \beta_n = \theta s^{k}_n k,

(``s`` the per-member scales, ``M``, ``K`` the unit-coefficient P1 matrices,
``R`` the convective boundary matrix).  Away from the twelve edges of the box
these are Kronecker products of 1-D lumped P1 matrices (``Mx``: ``h/2, h, ...,
h/2``; ``Kx``: ``[1, -1; -1, 1]/h`` per interval):

.. math::

    M^\otimes = M_x\otimes M_y\otimes M_z,\qquad
    K^\otimes = K_x\otimes M_y\otimes M_z + M_x\otimes K_y\otimes M_z + M_x\otimes M_y\otimes K_z,

and a convective face adds ``h e e^T`` to the 1-D stiffness of its axis, a
fixed face removes its node from the 1-D problem.  With the 1-D generalized
eigenpairs :math:`(\beta K_a + \theta H_a)\Phi_a = M_a\Phi_a\,\mathrm{diag}(\nu_a)`,
:math:`\Phi_a^T M_a \Phi_a = I`,

.. math::

    (A^\otimes_n)^{-1} = \Phi\,\mathrm{diag}\big(1/(\alpha_n + \nu_x + \nu_y + \nu_z)\big)\,\Phi^T,
    \qquad \Phi = \Phi_x\otimes\Phi_y\otimes\Phi_z,

applied axis by axis (Lynch, Rice & Thomas, Numer. Math. 6, 1964), batched over
members.  Per-member scales change only the diagonal (and, for axes with a
convective face, the tiny 1-D eigenproblem).

The Kuhn split is not symmetric on the box edges: there the P1 lumped mass,
stiffness and convective mass differ from the Kronecker forms (by a factor 4/3
or 2/3, see :func:`fem.mesh.box_mesh`).  The difference
:math:`\Delta_n = A_n - A^\otimes_n` lives on the ``m`` edge nodes ``E`` only
(checked at construction), so the exact P1 system is solved with the
capacitance (Woodbury) formula

.. math::

    x = y - (A^\otimes_n)^{-1} P_E s,\quad y = (A^\otimes_n)^{-1} r,\quad
    s = (I + \Delta_n G_n)^{-1}\Delta_n y_E,\quad G_n = [(A^\otimes_n)^{-1}]_{EE},

where :math:`y_E` and :math:`(A^\otimes)^{-1}P_E s` need only cheap
restricted transforms; :math:`(I + \Delta_n G_n)^{-1}\Delta_n` (m x m) is
computed once per distinct pair of scales and cached.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from . import _kernels
from .bc import HeatBoundary
from .mesh import BoxGrid
from .threads import blas_threads, run_blocks

__all__ = ["KroneckerSolver", "MASS_KINDS", "NotApplicable", "one_d_mass", "one_d_operators"]

#: 1-D mass matrices of the tensor-product operator (see :func:`one_d_mass`)
MASS_KINDS = ("lumped", "averaged", "consistent")


class NotApplicable(Exception):
    """The fast-diagonalization path does not apply to this problem."""


def one_d_operators(n: int, h: float) -> tuple[np.ndarray, np.ndarray]:
    """1-D lumped P1 mass (diagonal, (n+1,)) and stiffness ((n+1, n+1)), unit coefficient."""
    m = np.full(n + 1, h)
    m[[0, -1]] = h / 2
    K = (np.diag(np.full(n + 1, 2.0)) - np.eye(n + 1, k=1) - np.eye(n + 1, k=-1)) / h
    K[0, 0] = K[-1, -1] = 1.0 / h
    return m, K


def one_d_mass(n: int, h: float, kind: str = "lumped") -> np.ndarray:
    """1-D P1 mass matrix ((n+1, n+1), unit coefficient) of the tensor-product operator.

    ``"lumped"``: the row-sum diagonal ``h/2, h, ..., h/2``. ``"averaged"``: the mean of
    the lumped and the consistent (``h/6 [2 1; 1 2]`` per interval) matrices. Lumping
    makes the discrete eigenvalues of the Laplacian too low by ``(kh)^2/12`` relative,
    the consistent mass too high by the same amount; their average cancels that
    leading term, so the modes (and the surface temperature of a heated block) are
    fourth-order accurate in h (Marfurt, Geophysics 49, 1984, for the same cancellation
    in wave propagation). On the filter's 20 x 20 x 10 mesh this takes the surface
    error at the true parameters from -1.1% to +0.1% (validation/coarse_model_error.py).
    """
    if kind not in MASS_KINDS:
        raise ValueError(f"mass must be one of {MASS_KINDS}, got {kind!r}")
    m, _ = one_d_operators(n, h)
    if kind == "lumped":
        return np.diag(m)
    consistent = (np.diag(2.0 * m) + (np.eye(n + 1, k=1) + np.eye(n + 1, k=-1)) * h / 2) / 3
    if kind == "consistent":
        return consistent
    return 0.5 * (np.diag(m) + consistent)


def _contract(X: np.ndarray, Phi: np.ndarray, axis: int) -> np.ndarray:
    """Contract spatial ``axis`` (0..2) of X (B, a0, a1, a2) with Phi's first index.

    ``Phi`` is (L, P) shared by the batch or (B, L, P) per batch entry; the
    result has the contracted axis (now of size P) in the same position.
    Only reshapes of the contiguous X are used (moving the contracted axis to
    the end would need strided copies, ten times slower than the products).
    """
    X = np.ascontiguousarray(X)
    B, a0, a1, a2 = X.shape
    P = Phi.shape[-1]
    if axis == 0:
        Y = np.matmul(_transpose(Phi), X.reshape(B, a0, a1 * a2))
        return Y.reshape(B, P, a1, a2)
    if axis == 1:
        if Phi.ndim == 2:
            Y = np.matmul(Phi.T, X.reshape(B * a0, a1, a2))
        else:
            Y = np.matmul(_transpose(Phi)[:, None], X)
        return Y.reshape(B, a0, P, a2)
    if Phi.ndim == 2:
        return (X.reshape(-1, a2) @ Phi).reshape(B, a0, a1, P)
    return np.matmul(X.reshape(B, a0 * a1, a2), Phi).reshape(B, a0, a1, P)


def _shared_basis_solve(r: np.ndarray, dinv: np.ndarray, Phis, shape) -> np.ndarray:
    """``Phi (dinv * Phi^T r)`` for bases shared by the batch, six large products.

    Each product contracts the last axis and rotates it to the front (the other way on
    the way back), so every contraction is one BLAS call on the whole batch with no
    copies; the batched small products of :func:`_contract` spend their time in
    per-call overhead (measured 3.3-4.1 ms against 4.9 ms for 25 members on the
    filter's 21 x 21 x 11 free grid, one thread).
    """
    B = r.shape[0]
    a0, a1, a2 = shape
    P0, P1, P2 = Phis
    Y = P2.T @ np.ascontiguousarray(r).reshape(-1, a2).T  # (p2, B a0 a1)
    Y = P1.T @ Y.reshape(-1, a1).T  # (p1, p2 B a0)
    Y = P0.T @ Y.reshape(-1, a0).T  # (p0, p1 p2 B)
    Y = Y.reshape(a0, a1, a2, B)
    Y *= np.moveaxis(dinv, 0, -1)
    Z = Y.reshape(a0, -1).T @ P0.T  # (p1 p2 B, a0)
    Z = Z.reshape(a1, -1).T @ P1.T  # (p2 B a0, a1)
    Z = Z.reshape(a2, -1).T @ P2.T  # (B a0 a1, a2)
    return Z.reshape(B, -1)


def _transpose(Phi: np.ndarray) -> np.ndarray:
    return np.swapaxes(Phi, -1, -2)


def _rows(Phi: np.ndarray, idx: np.ndarray) -> np.ndarray:
    return Phi[..., idx, :]


class KroneckerSolver:
    """Exact P1 implicit solves on a structured box mesh by fast diagonalization.

    Parameters
    ----------
    grid : BoxGrid
        The grid whose :func:`fem.mesh.box_mesh` is the mesh.
    boundary : HeatBoundary
    vhc, tc : float
        Homogeneous VHC (J cm^-3 K^-1) and TC (W cm^-1 K^-1).
    dt : float
        s, time step.
    theta : float
        Implicitness (1 backward Euler, 0.5 Crank-Nicolson).
    M_true : array (npoints,)
        The lumped P1 mass with coefficient ``vhc``.
    K_true : csr (npoints, npoints)
        The P1 stiffness with coefficient ``tc``.
    R_true : array (npoints,)
        The lumped convective boundary matrix (diagonal).
    free : bool array (npoints,)
        Nodes not held by a fixed face.
    exact : bool
        Apply the box-edge correction (default).  Without it the solver
        inverts the Kronecker operator only, a preconditioner for the P1 system
        (``M_true``, ``K_true``, ``R_true`` may then be None).
    mass : {"lumped", "averaged"}
        The 1-D mass matrices (:func:`one_d_mass`); ``"averaged"`` needs
        ``exact=False`` (it is its own operator, not a route to the lumped P1 one).

    Raises
    ------
    NotApplicable
        If ``A - A^\\otimes`` is not confined to the box edges (it always is
        for box_mesh; the check guards against misuse).
    """

    def __init__(self, grid: BoxGrid, boundary: HeatBoundary, vhc: float, tc: float,
                 dt: float, theta: float, M_true, K_true, R_true, free, exact: bool = True,
                 mass: str = "lumped"):
        self.grid, self.theta, self.dt, self.vhc, self.tc = grid, theta, dt, vhc, tc
        if exact and mass != "lumped":
            raise NotApplicable(f"the exact P1 correction needs the lumped mass, not {mass!r}")
        sizes = grid.shape
        self.m1, self.K1, self.H1, self.free1 = [], [], [], []
        for a, (n, h) in enumerate(zip(sizes, grid.spacing, strict=True)):
            _, K = one_d_operators(n, h)
            m = one_d_mass(n, h, mass)
            H = np.zeros(n + 1)
            keep = np.ones(n + 1, dtype=bool)
            for side, node in (("-", 0), ("+", n)):
                bc = boundary["xyz"[a] + side]
                if bc.kind == "convective":
                    H[node] += bc.h
                elif bc.kind == "fixed":
                    keep[node] = False
            idx = np.flatnonzero(keep)
            if idx.size == 0:
                raise NotApplicable(f"no free nodes along axis {'xyz'[a]}")
            self.free1.append(idx)
            self.m1.append(m[np.ix_(idx, idx)])  # (n_free, n_free) 1-D mass
            self.K1.append(K[np.ix_(idx, idx)])
            self.H1.append(H[idx])
        self.shape_f = tuple(len(i) for i in self.free1)
        # free nodes of the mesh in the C order of the free grid
        I, J, Kk = np.meshgrid(*self.free1, indexing="ij")
        self.free_nodes = grid.node_index(I.ravel(), J.ravel(), Kk.ravel())
        if not np.array_equal(np.sort(self.free_nodes), np.flatnonzero(free)):
            raise NotApplicable("fixed nodes are not whole faces of the box")
        self._shared = {}
        for a in range(3):
            if not np.any(self.H1[a]):
                mu, Phi = sla.eigh(self.K1[a], self.m1[a])
                self._shared[a] = (mu, Phi)
        self._eig_cache: dict = {}
        self._W_cache: dict = {}
        self._last = None
        if exact:
            self._setup_edges(M_true, K_true, R_true)
        else:
            self.m = 0

    # ------------------------------------------------------------------ 1-D
    def _axis_eig(self, a: int, beta: float):
        """(nu, Phi) of the 1-D pencil (beta K_a + theta H_a, M_a)."""
        if a in self._shared:
            mu, Phi = self._shared[a]
            return beta * mu, Phi
        key = (a, beta)
        if key not in self._eig_cache:
            S = beta * self.K1[a] + self.theta * np.diag(self.H1[a])
            self._eig_cache[key] = sla.eigh(S, self.m1[a])
        return self._eig_cache[key]

    def _member_data(self, alpha: np.ndarray, beta: np.ndarray):
        """Per-member mode diagonals (N, Px, Py, Pz) and 1-D bases."""
        N = alpha.size
        ub, inv = np.unique(beta, return_inverse=True)
        nus, Phis = [], []
        for a in range(3):
            eig = [self._axis_eig(a, b) for b in ub]
            if a in self._shared or ub.size == 1:
                Phis.append(eig[0][1])
            else:
                Phis.append(np.stack([eig[i][1] for i in inv]))
            nus.append(np.stack([eig[i][0] for i in inv]))  # (N, P_a)
        d = (alpha[:, None, None, None] + nus[0][:, :, None, None]
             + nus[1][:, None, :, None] + nus[2][:, None, None, :])
        return 1.0 / d, Phis, N

    # --------------------------------------------------------------- edges
    def _setup_edges(self, M_true, K_true, R_true):
        g = self.grid
        free = self.free_nodes
        # Kronecker forms on the full grid (unit coefficients), then restrict
        mk, Kk = [], []
        for n, h in zip(g.shape, g.spacing, strict=True):
            m, K = one_d_operators(n, h)
            mk.append(sp.diags_array(m))
            Kk.append(sp.csr_matrix(K))
        Mx, My, Mz = mk
        Kx, Ky, Kz = Kk
        Mkron = np.kron(np.kron(Mx.diagonal(), My.diagonal()), Mz.diagonal())
        Kkron = (sp.kron(sp.kron(Kx, My), Mz) + sp.kron(sp.kron(Mx, Ky), Mz)
                 + sp.kron(sp.kron(Mx, My), Kz)).tocsr()
        Rkron = np.zeros(g.npoints)
        for a in range(3):
            n = g.shape[a]
            H = np.zeros(n + 1)
            # H1 holds only free nodes; rebuild the full 1-D vector
            H[self.free1[a]] = self.H1[a]
            diag = [Mx.diagonal(), My.diagonal(), Mz.diagonal()]
            diag[a] = H
            Rkron += np.kron(np.kron(diag[0], diag[1]), diag[2])
        dM = (M_true / self.vhc - Mkron)[free]
        dK = (K_true / self.tc - Kkron)[free][:, free].tocoo()
        dR = (R_true - Rkron)[free]
        scale = np.abs(Kkron.diagonal()).max()
        dK.data[np.abs(dK.data) <= 1e-12 * scale] = 0
        dK.eliminate_zeros()
        mscale, rscale = Mkron.max(), max(np.abs(R_true).max(), 1e-300)
        dM[np.abs(dM) <= 1e-12 * mscale] = 0
        dR[np.abs(dR) <= 1e-12 * rscale] = 0

        # edge nodes, grouped by the line they lie on, as free-grid positions
        bnd, inn = [], []
        for a in range(3):
            idx = self.free1[a]
            on = (idx == 0) | (idx == g.shape[a])
            bnd.append(np.flatnonzero(on))
            inn.append(np.flatnonzero(~on))
        allx = np.arange(self.shape_f[0])
        self._bnd, self._inn = bnd, inn
        # x-lines, y-lines (without corners), z-lines (without corners)
        groups = [(allx, bnd[1], bnd[2]), (bnd[0], inn[1], bnd[2]), (bnd[0], bnd[1], inn[2])]
        pos = []
        for ix, iy, iz in groups:
            P = np.ix_(ix, iy, iz)
            pos.append(np.ravel_multi_index(P, self.shape_f).ravel())
        self.E = np.concatenate(pos)  # positions among the free nodes
        m = self.E.size
        inE = np.zeros(free.size, dtype=bool)
        inE[self.E] = True
        support = np.unique(np.concatenate([dK.row, dK.col, np.flatnonzero(dM),
                                            np.flatnonzero(dR)]))
        if support.size and not inE[support].all():
            raise NotApplicable("P1 and Kronecker operators differ away from the box edges")
        if support.size == 0:
            self.m = 0
            return
        loc = np.full(free.size, -1)
        loc[self.E] = np.arange(m)
        self.dM = np.diag(dM[self.E])
        self.dR = np.diag(dR[self.E])
        self.dK = np.zeros((m, m))
        np.add.at(self.dK, (loc[dK.row], loc[dK.col]), dK.data)
        self.m = m

    def _rows2(self, Phi: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Rows of a shared (L, P) or per-member (B, L, P) basis as (B or 1, 2, P),
        zero-padded to 2 rows (a box axis has at most 2 boundary nodes)."""
        R = _rows(Phi, rows)
        R = R[None] if R.ndim == 2 else R
        out = np.zeros((R.shape[0], 2, R.shape[2]))
        out[:, :R.shape[1]] = R
        return out

    def _gather(self, X: np.ndarray, dinv: np.ndarray, Phis) -> np.ndarray:
        """Node values on E of the modes Y = X * dinv (B, Px, Py, Pz) -> (B, m).

        One numba pass makes the thin contractions of Y onto the z- and
        x-boundary rows; the rest are contractions of small arrays.
        """
        (bx, by, bz), (_, iy, iz) = self._bnd, self._inn
        B = X.shape[0]
        Px, Py, Pz = self.shape_f
        Z1 = np.empty((B, Px, Py, 2))
        X1 = np.empty((B, 2, Py, Pz))
        _kernels.edge_partials(X, dinv, self._rows2(Phis[2], bz), self._rows2(Phis[0], bx),
                               Z1, X1)
        Z1, X1 = Z1[..., :bz.size], X1[:, :bx.size]

        def T(a, rows):
            return _transpose(_rows(Phis[a], rows))

        out = [np.zeros((B, 0))] * 3
        if bz.size and by.size:
            out[0] = _contract(_contract(Z1, T(1, by), 1), _transpose(Phis[0]), 0)
        if bz.size and bx.size and iy.size:
            out[1] = _contract(_contract(Z1, T(0, bx), 0), T(1, iy), 1)
        if bx.size and by.size and iz.size:
            out[2] = _contract(_contract(X1, T(1, by), 1), T(2, iz), 2)
        return np.concatenate([o.reshape(B, -1) for o in out], axis=1)

    def _correct(self, X: np.ndarray, dinv: np.ndarray, s: np.ndarray, Phis) -> np.ndarray:
        """Corrected modes (X - Phi^T P_E s) * dinv for values s (B, m) on E."""
        (bx, by, bz), (_, iy, iz) = self._bnd, self._inn
        B = s.shape[0]
        Px, Py, Pz = self.shape_f
        n0, n1 = Px * by.size * bz.size, bx.size * iy.size * bz.size
        sx, sy, sz = s[:, :n0], s[:, n0:n0 + n1], s[:, n0 + n1:]
        Axy = np.zeros((B, Px, Py, 2))
        if n0:
            Y = _contract(sx.reshape(B, Px, by.size, bz.size), Phis[0], 0)
            Axy[..., :bz.size] += _contract(Y, _rows(Phis[1], by), 1)
        if n1:
            Y = _contract(sy.reshape(B, bx.size, iy.size, bz.size), _rows(Phis[1], iy), 1)
            Axy[..., :bz.size] += _contract(Y, _rows(Phis[0], bx), 0)
        Bz = np.zeros((B, 2, Py, Pz))
        if sz.shape[1]:
            Y = _contract(sz.reshape(B, bx.size, by.size, iz.size), _rows(Phis[2], iz), 2)
            Bz[:, :bx.size] += _contract(Y, _rows(Phis[1], by), 1)
        out = np.empty_like(X)
        _kernels.correct_modes(X, dinv, Axy, self._rows2(Phis[2], bz), Bz,
                               self._rows2(Phis[0], bx), out)
        return out

    def _edge_green(self, dinv: np.ndarray, Phis) -> np.ndarray:
        """G = [(A^kron)^-1]_EE (m x m) for one member, block by block.

        Entry (e, e') is sum over modes of prod_a Phi_a[i_a(e), p_a] Phi_a[i_a(e'), p_a]
        times 1/d; each block between two line groups is one einsum whose cost is
        about (number of modes) x 16 plus (line length)^3.
        """
        (bx, by, bz), (_, iy, iz) = self._bnd, self._inn
        allx = np.arange(self.shape_f[0])
        groups = [(allx, by, bz), (bx, iy, bz), (bx, by, iz)]
        sizes = [int(np.prod([r.size for r in g])) for g in groups]
        offs = np.concatenate([[0], np.cumsum(sizes)])
        G = np.empty((self.m, self.m))
        for A, ga in enumerate(groups):
            for B, gb in enumerate(groups):
                if sizes[A] == 0 or sizes[B] == 0:
                    continue
                F = [Phis[a][ga[a]][:, None, :] * Phis[a][gb[a]][None, :, :] for a in range(3)]
                blk = np.einsum("uvp,wxq,yzr,pqr->uwyvxz", *F, dinv, optimize="optimal")
                G[offs[A]:offs[A + 1], offs[B]:offs[B + 1]] = blk.reshape(sizes[A], sizes[B])
        return G

    def _W(self, alpha: float, beta: float) -> np.ndarray:
        """(I + Delta G)^-1 Delta for one pair of coefficients, cached."""
        key = (alpha, beta)
        if key in self._W_cache:
            return self._W_cache[key]
        dinv, Phis, _ = self._member_data(np.array([alpha]), np.array([beta]))
        Phis = [P if P.ndim == 2 else P[0] for P in Phis]
        G = self._edge_green(dinv[0], Phis)
        D = alpha * self.dM + beta * self.dK + self.theta * self.dR
        W = np.linalg.solve(np.eye(self.m) + D @ G, D)
        self._W_cache[key] = W
        return W

    # --------------------------------------------------------------- solve
    def solve(self, r: np.ndarray, vhc_scale: np.ndarray, tc_scale: np.ndarray,
              blocks: int = 2) -> np.ndarray:
        """Solve ``A_n x_n = r_n`` on the free nodes.

        Parameters
        ----------
        r : array (N, nfree)
            W, right-hand sides in the order of ``self.free_nodes``.
        vhc_scale, tc_scale : arrays (N,)
            Per-member factors on VHC and TC.
        blocks : int, default 2
            Member blocks, solved side by side on the threads of
            :func:`fem.threads.run_blocks` (numpy and the numba kernels release the GIL;
            BLAS runs single-threaded inside each). The numbers depend on the blocks,
            not on the number of threads.

        Returns
        -------
        array (N, nfree)
        """
        alpha = vhc_scale * (self.vhc / self.dt)
        beta = tc_scale * (self.theta * self.tc)
        N = r.shape[0]
        with blas_threads(1):
            dinv, Phis, W = self._cached(alpha, beta)
            out = np.empty_like(r, dtype=float)

            def run(i0, i1):
                sl = slice(i0, i1)
                P = [Ph[sl] if Ph.ndim == 3 else Ph for Ph in Phis]
                out[sl] = self._solve_block(r[sl], dinv[sl], P, None if W is None else W[sl])

            run_blocks(N, run, blocks)
            return out

    def _cached(self, alpha, beta):
        last = self._last
        if last is not None and np.array_equal(last[0], alpha) and np.array_equal(last[1], beta):
            return last[2]
        dinv, Phis, _ = self._member_data(alpha, beta)
        W = None
        if self.m:
            W = np.stack([self._W(a, b) for a, b in zip(alpha, beta, strict=True)])
        self._last = (alpha.copy(), beta.copy(), (dinv, Phis, W))
        return dinv, Phis, W

    def _solve_block(self, r, dinv, Phis, W):
        N = r.shape[0]
        if W is None and all(P.ndim == 2 for P in Phis):
            return _shared_basis_solve(r, dinv, Phis, self.shape_f)
        X = r.reshape((N,) + self.shape_f)
        for a in range(3):
            X = _contract(X, Phis[a], a)
        if W is None:
            Yhat = X * dinv
        else:
            X = np.ascontiguousarray(X)
            yE = self._gather(X, dinv, Phis)
            s = np.matmul(W, yE[:, :, None])[:, :, 0]
            Yhat = self._correct(X, dinv, s, Phis)  # (r_hat - Phi^T P_E s) / d
        for a in range(3):
            Yhat = _contract(Yhat, _transpose(Phis[a]), a)
        return Yhat.reshape(N, -1)
