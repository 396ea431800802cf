r"""The advice's forecast: members' temperatures at a few points, and their damage.

The heat step of :class:`fem.HeatStepper` is
:math:`A T^{l+1} = B T^l + g + f^l` with symmetric :math:`A = M/\Delta t + \vartheta(K + R)`
and :math:`B = M/\Delta t - (1 - \vartheta)(K + R)` (``M``, ``K``, ``R``, ``g`` its public
matrices and load; nodes of fixed faces left out). The temperature at a point
:math:`e` (a row of :func:`fem.probe_matrix`) after :math:`m` steps from :math:`T` is

.. math::

    e^\top T^m = r_m^\top T + a_m + \sum_{l < m} w_{m-1-l}^\top f^l,
    \qquad r_0 = e,\quad w_l = A^{-1} r_l,\quad r_{l+1} = B\, w_l,

the adjoint recursion (:math:`e^\top (A^{-1}B)^m = ((B A^{-1})^m e)^\top`), with
:math:`a_m` the forecast of the zero state (the boundary's load and fixed faces). One
pass of the few point vectors through the heat steps gives, once, the rows that turn
any member's state and load into its point temperatures after every step
(:class:`PointForecast`, ``engine="adjoint"``; :math:`A^{-1}` is a heat step from zero
with the vector as its load, less that step without it). Those of neighbouring steps
are nearly alike: stored as a low-rank product (:func:`low_rank`, exact to 1e-10 of
their largest entry), a reading costs a fraction of the full rows' products. ``engine="direct"`` steps
every member instead: the reference, and the way when the members' heat steps differ
(VHC, TC estimated) or fixed faces hold each member's own temperature.
"""

from __future__ import annotations

import numpy as np

import fem
from fem.threads import blas_threads

from ._kernels import superpose

__all__ = ["PointForecast", "damage", "first_crossing", "heat", "low_rank", "nominal_peak",
           "region_points"]


class PointForecast:
    """Members' temperatures at the points ``P`` (p, n_nodes) after each of up to ``K``
    heat steps of ``dt`` s (the filter's forward model ``model``: its steps and loads).

    ``engine="adjoint"``: the rows of the module docstring, computed once and stored as a
    low-rank product (:func:`low_rank`, max-abs error ``rtol`` of their largest entry);
    ``"direct"``: every member stepped forward at each call."""

    def __init__(self, model, P, dt: float, K: int, engine: str, rtol: float = 1e-10):
        self.model, self.P = model, P.tocsr()
        self.dt, self.K, self.engine = float(dt), int(K), engine
        self.n_est = len(model.setup.parameters.estimate)
        self._BW32 = None  # the loads' right factor in float32 (made on first use)
        if engine == "adjoint":
            R, W = self._adjoint_rows(model.stepper(self.dt))
            p, n = self.P.shape
            with blas_threads(1):
                self.R = low_rank(R.reshape(-1, n), rtol)
                self.W = low_rank(W.reshape(-1, n), rtol)
            self.rank = (self.R[1].shape[0], self.W[1].shape[0])

    def _adjoint_rows(self, st) -> tuple[np.ndarray, np.ndarray]:
        """``R`` (K+1, p, n), ``W`` (K, p, n) and the affine part ``a`` (K+1, p): the point
        temperatures ``R_k T + a_k`` after k steps from ``T``, and ``W_(k-1) q`` after k
        steps from a load ``q`` over the first."""
        n, p, K = st.npoints, self.P.shape[0], self.K
        fixed = st.fixed
        B = (st.M / st.dt - (1.0 - st.theta) * (st.K + st.R)).tocsr()
        z1 = st.step(np.zeros(n))  # one step from zero: the boundary's part
        r = self.P.toarray()
        R, W = np.empty((K + 1, p, n)), np.empty((K, p, n))
        R[0] = r
        for m in range(K):
            # A^-1 r on the free nodes (a step ignores loads on fixed ones); B w's entries on
            # fixed nodes: how the state there before the step moves the free ones
            w = st.step(np.zeros((p, n)), load=r) - z1
            w[:, fixed] = 0.0
            W[m] = w
            R[m + 1] = r = np.asarray(B @ w.T).T
        self.a = self._series(np.zeros((1, n)), None, 0.0)[0]
        return R, W

    def _series(self, X, theta, power: float, K: int | None = None) -> np.ndarray:
        """(N, K+1, p) point temperatures of members stepped forward at ``power`` W over
        the first step, then none (``theta`` None: the bare heat step)."""
        K = self.K if K is None else K
        out = np.empty((X.shape[0], K + 1, self.P.shape[0]))
        out[:, 0] = (self.P @ X.T).T
        st = self.model.stepper(self.dt)
        T = np.array(X, float)
        for m in range(K):
            T = st.step(T) if theta is None else self.model.step(
                T, theta, 0.0, self.dt, power if m == 0 else 0.0)
            out[:, m + 1] = (self.P @ T.T).T
        return out

    def responses(self, X, theta, K: int | None = None, loads: bool = True
                  ) -> tuple[np.ndarray, np.ndarray | None]:
        """``H`` (N, K+1, p): the members' point temperatures (deg C) with the laser off,
        now and after each step; ``G`` (N, K, p): their response to 1 W over the first
        step, after steps 1..K (None without ``loads``: drifting optics have their own,
        :meth:`load_responses`). Under ``P_j`` W over step ``j`` the point temperatures
        are ``H_k + sum_(j<k) P_j G_(k-1-j)`` (:func:`heat`).

        ``X`` (N, n_nodes) deg C; ``theta`` (N, >= n_estimate): the members' parameters,
        ``setup.parameters.estimate`` first."""
        K = self.K if K is None else K
        X = np.asarray(X, float)
        theta = np.asarray(theta, float)[:, :self.n_est]
        N, p = X.shape[0], self.P.shape[0]
        if self.engine == "adjoint":
            QR, BR = self.R
            with blas_threads(1):  # small products: threads only wait on a busy machine
                H = (QR[:(K + 1) * p] @ (BR @ X.T)).T.reshape(N, K + 1, p) + self.a[:K + 1]
            return H, self.load_responses(theta, K) if loads else None
        H = self._series(X, theta, 0.0, K)
        return H, self.load_responses(theta, K) if loads else None

    def load_responses(self, theta, K: int | None = None, dtype=np.float64) -> np.ndarray:
        """``G`` (N, K, p): the point temperatures' response to 1 W over one step with the
        optics ``theta`` (N, >= n_estimate), 1..K steps after it (:meth:`responses`'s
        ``G`` alone: the drifting optics' later loads).

        ``dtype`` ``np.float32``: the adjoint engine's product of the loads with the
        stored rows' right factor (the large one, over the nodes) in single precision,
        twice as fast on the many loads of drifting optics; each response then within
        float32's rounding of that sum (about 1e-6 of the largest response,
        ``tests/test_advice_drift.py``)."""
        K = self.K if K is None else K
        theta = np.asarray(theta, float)[:, :self.n_est]
        N, p = theta.shape[0], self.P.shape[0]
        if self.engine == "adjoint":
            QW, BW = self.W
            if dtype == np.float32:
                if self._BW32 is None:
                    self._BW32 = BW.astype(np.float32)
                BW = self._BW32
            q = self.model.loads(theta, 1.0).astype(BW.dtype, copy=False)
            with blas_threads(1):
                return (QW[:K * p] @ (BW @ q.T).astype(float, copy=False)).T.reshape(N, K, p)
        n = self.P.shape[1]
        zero = self._series(np.zeros((N, n)), theta, 0.0, K)
        return (self._series(np.zeros((N, n)), theta, 1.0, K) - zero)[:, 1:]


def low_rank(M, rtol: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``(Q (m, r), B (r, n))`` with ``|M - Q B| <= rtol max|M|`` entrywise: the randomized
    range finder (Halko, Martinsson & Tropp 2011, SIAM Rev. 53), its rank doubled from 64
    until half the error holds, then cut by the SVD of ``B`` to the fewest singular values
    whose tail (a bound of any entry's error) is within the other half; at most ``m``
    (then ``Q`` is the identity)."""
    m, n = M.shape
    tol = 0.5 * rtol * np.abs(M).max()
    rng = np.random.default_rng(seed)
    r = min(64, m) if tol > 0 else m
    while r < m:
        Q, _ = np.linalg.qr(M @ rng.standard_normal((n, r)))
        B = Q.T @ M
        if np.abs(M - Q @ B).max() <= tol:
            U, sv, Vt = np.linalg.svd(B, full_matrices=False)
            tail = np.sqrt(np.cumsum((sv ** 2)[::-1]))[::-1]  # tail[k]: sv[k:]'s norm
            k = int(np.argmax(np.r_[tail, 0.0] <= tol))
            return Q @ U[:, :k], sv[:k, None] * Vt[:k]
        r = min(m, 2 * r)
    return np.eye(m), np.array(M)


def heat(H, G, P, c, seg=None) -> np.ndarray:
    """(N, K+1, p): the laser-off temperatures ``H`` plus the responses ``G`` to the
    powers ``P`` (K,) W over each member's first ``c`` (N,) steps (then off):
    ``Y_k = H_k + sum_(j < min(k, c)) P_j G_(k-1-j)``.

    ``G`` (N, K, p) holds for every step; with drifting optics it is (N, S, K, p), the
    responses of S sets of optics, and ``seg`` (K,) names the set of each step ``j``:
    ``Y_k = H_k + sum_(j < min(k, c)) P_j G_(seg_j, k-1-j)`` (summed by a numba
    kernel, ``_kernels.superpose``)."""
    if seg is None:
        G, seg = G[:, None], np.zeros(G.shape[1], np.int64)
    # the steps j < c each member heats, as a count (c may be inf or fractional)
    c = np.ceil(np.minimum(np.broadcast_to(np.asarray(c, float), (H.shape[0],)), G.shape[2]))
    Y = np.array(H, float)
    superpose(Y, np.asarray(G, float), np.asarray(P, float), c.astype(np.int64),
              np.asarray(seg, np.int64))
    return Y


def damage(E: float, A: float, h: float, omega0, Y, path: bool = False):
    """Omega from ``omega0`` (rows, p) along ``Y`` (rows, K+1, p) deg C sampled every ``h``
    s (:func:`fem.advance_damage`'s trapezoid, all steps in one call): the final (rows, p),
    and with ``path`` the smallest over the points at each sample (rows, K+1)."""
    om0 = np.asarray(omega0, float)
    inc = np.zeros((Y.shape[0], Y.shape[1] - 1, Y.shape[2]))
    fem.advance_damage(inc, Y[:, :-1], Y[:, 1:], h, E, A, rule="trapezoid")
    om = np.cumsum(inc, axis=1) + om0[:, None]
    final = om[:, -1] if om.shape[1] else om0.copy()
    if not path:
        return final
    return final, np.concatenate([om0.min(axis=1)[:, None], om.min(axis=2)], axis=1)


def first_crossing(om, t0: float, h: float) -> np.ndarray:
    """(N,) s: when ``om`` (N, M), Omega at ``t0 + i h``, first reaches 1 (linear between
    samples; inf when it does not)."""
    hit = om >= 1.0
    out = np.full(om.shape[0], np.inf)
    rows = np.flatnonzero(hit.any(axis=1))
    for r, k in zip(rows, hit[rows].argmax(axis=1), strict=True):
        if k == 0:
            out[r] = t0
            continue
        a, b = om[r, k - 1], om[r, k]
        out[r] = t0 + (k - 1 + (1.0 - a) / (b - a)) * h
    return out


def nominal_peak(model, plan, dt: float, n_steps: int) -> np.ndarray:
    """(n_nodes,) deg C: each node's hottest over ``n_steps`` heat steps of ``dt`` s of the
    ``plan`` (its ``mean_power``) from ``T_initial``, at the setup's nominal optics."""
    s = model.setup
    theta = np.array([[s.parameters.nominal[n] for n in s.parameters.estimate]])
    T = np.full((1, model.mesh.p.shape[1]), float(s.T_initial))
    peak = T[0].copy()
    for k in range(n_steps):
        T = model.step(T, theta, k * dt, (k + 1) * dt, plan.mean_power(k * dt, (k + 1) * dt))
        np.maximum(peak, T[0], out=peak)
    return peak


def region_points(mesh, spec, peak, n_max: int, *, coldest: bool, what: str) -> np.ndarray:
    """(m, 3) cm: the points ``spec`` ((m, 3) cm, in the tissue), or of a box ``((x0, x1),
    (y0, y1), (z0, z1))`` its nodes, the ``n_max`` coldest (``coldest``) or hottest by
    ``peak`` (:func:`nominal_peak`). ``what`` names it in errors."""
    p = mesh.p
    arr = np.asarray(spec, float)
    if arr.shape == (3, 2):  # a box
        nodes = np.flatnonzero(np.all((p.T >= arr[:, 0] - 1e-9) & (p.T <= arr[:, 1] + 1e-9),
                                      axis=1))
        if not nodes.size:
            raise ValueError(f"the {what} region {arr.tolist()} cm holds no node of the "
                             "filter's mesh: make it larger")
        order = np.argsort(peak[nodes] if coldest else -peak[nodes], kind="stable")
        return p[:, nodes[order[:n_max]]].T
    arr = arr.reshape(-1, 3)
    lo, hi = p.min(axis=1), p.max(axis=1)
    if not arr.size or np.any((arr < lo - 1e-9) | (arr > hi + 1e-9)):
        raise ValueError(f"the {what} points must lie in the tissue "
                         f"{[[float(a), float(b)] for a, b in zip(lo, hi, strict=True)]} cm, "
                         f"got {arr.tolist()}")
    return arr
