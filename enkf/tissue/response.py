r"""The sensors' readings over a window as a linear function of the members' sources.

With the thermal properties known (not estimated), the filter's heat model is affine in
its nodal loads: after the reading at the end of interval ``m`` the sensors read

.. math::

    y_m = y^{\mathrm{free}}_m + \sum_{s \le s_m} p_s\, G_{s_m - s}\, L\, v(\theta_{k(s)}),

``s`` the heat steps (all of one length ``dt``), ``p_s`` the laser's power over step
``s``, ``k(s)`` its interval, ``v`` the absorption model's values (N, n_unique) at the
interval's optics, ``L`` the nodal loads per W of those values
(:attr:`~enkf.tissue.forward.TissueForwardModel.value_operator`) and
:math:`G_j = P A^j B` the sensors' response ``j`` steps after a unit load, ``A`` the
step's propagator and ``B`` its solve. The step's matrices are symmetric
(:math:`A = C^{-1}E` with symmetric ``C`` and ``E``), so :math:`G_j^\top = A^j (B P^\top)`:
all the responses come from one run of the stepper itself with ``p`` members (the
sensors), no adjoint code. The rows :math:`G_j L` over every lag have a rapidly falling
spectrum (32 of 150 above 1e-13 of the largest on the paper's 20 x 20 x 10 model);
their leading right singular vectors ``V`` (n_unique, r) carry each member's values into
``r`` numbers, and the readings follow from one product with a block-Toeplitz matrix.

The smoother (:mod:`enkf.tissue.smooth`) re-runs every member over the whole window for
every update; this gives the same readings (to 1e-13 K on the paper's model, to 1e-9 K in
``tests/test_response.py``) at a twentieth of the cost (50 members over 150 readings in
22 ms against 510 ms, ``benchmarks/bench_filter.py --smoother``), the absorption model's
values then taking most of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SensorResponse", "sensor_response"]

#: singular values of the stacked responses kept: above this share of the largest
RANK_RTOL = 1e-13
#: the responses and the block-Toeplitz matrix are built only below this many bytes
#: each (a camera's hundreds of pixels over a long window: the member runs instead)
MAX_BYTES = 256 * 2 ** 20


@dataclass
class SensorResponse:
    """The readings of a window as an affine function of each interval's optics.

    ``free`` (M, p) deg C: the readings with the laser off; ``basis`` (n_unique, r): the
    values' directions the sensors see; ``toeplitz`` (M * r, M * p): the readings per unit
    of those ``r`` numbers in each interval (the laser's power folded in); ``heated``
    (M,) bool: the intervals with any power (the others add nothing).
    """

    model: object
    free: np.ndarray
    basis: np.ndarray
    toeplitz: np.ndarray
    heated: np.ndarray

    @property
    def rank(self) -> int:
        return self.basis.shape[1]

    def readings(self, theta: np.ndarray) -> np.ndarray:
        """(N, M, p) deg C: the sensors after each interval for the members' optics
        ``theta`` (M, N, n_par), each interval's row the optics over it."""
        M, N = theta.shape[:2]
        r = self.rank
        c = np.zeros((M, N, r))
        lit = theta[self.heated]
        if lit.size and (lit == lit[:1]).all():  # optics constant over the window
            c[self.heated] = self.model.values(np.ascontiguousarray(lit[0])) @ self.basis
        elif lit.size:  # every heated interval's members in one call
            flat = np.ascontiguousarray(lit).reshape(-1, theta.shape[2])
            c[self.heated] = (self.model.values(flat) @ self.basis).reshape(-1, N, r)
        y = c.transpose(1, 0, 2).reshape(N, M * r) @ self.toeplitz
        return y.reshape(N, M, -1) + self.free


def sensor_response(model, P, times, T0: np.ndarray) -> SensorResponse | None:
    """The window's :class:`SensorResponse` for the forward model ``model`` (a
    :class:`~enkf.tissue.forward.TissueForwardModel`), the sensors ``P`` (p, n_nodes) and
    the readings at ``times`` (M,) s after 0, every member starting from ``T0``
    (n_nodes,) deg C; None where the readings are not affine in the values (a
    damage-driven model, VHC or TC estimated, an absorption model that runs Monte
    Carlo), the steps differ in length, the solver is iterative, or the responses would
    not fit in :data:`MAX_BYTES`."""
    from .forward import TissueForwardModel

    if type(model) is not TissueForwardModel or model.absorption.exact \
            or {"VHC", "TC"} & set(model.col):
        return None
    edges = np.r_[0.0, np.asarray(times, float)]
    subs = [model.substeps(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    dts = {round(b - a, 9) for s in subs for a, b in s}
    if len(dts) != 1:
        return None
    stepper = model.stepper(subs[0][0][1] - subs[0][0][0])
    if stepper.method not in ("fast", "direct"):  # iterative: not linear to rounding
        return None
    n = model.mesh.p.shape[1]
    p, M = P.shape[0], len(subs)
    S = sum(len(s) for s in subs)
    L = model.value_operator
    if 8 * S * p * max(n, L.shape[1]) > MAX_BYTES:
        return None
    # the sensors' responses G_j^T = A^j (B P^T), from the stepper (module doc)
    zero = stepper.step(np.zeros((1, n)))
    Pt = np.asarray(P.toarray() if hasattr(P, "toarray") else P, float)
    g = stepper.step(np.zeros((p, n)), load=Pt) - zero
    G = np.empty((S, p, L.shape[1]))
    for j in range(S):
        G[j] = (L.T @ g.T).T
        g = stepper.step(g) - zero
    _, sv, Vt = np.linalg.svd(G.reshape(S * p, -1), full_matrices=False)
    r = max(1, int(np.sum(sv > RANK_RTOL * sv[0])))
    if 8 * M * r * M * p > MAX_BYTES:
        return None
    V = np.ascontiguousarray(Vt[:r].T)
    coef = (G.reshape(S * p, -1) @ V).reshape(S, p, r)
    # the readings with the laser off, and each step's power
    free = np.empty((M, p))
    T = np.asarray(T0, float)[None, :].copy()
    power = np.empty(S)
    end = np.empty(M, int)  # the step after which each reading is taken
    which = np.empty(S, int)  # each step's interval
    s = 0
    for k, steps in enumerate(subs):
        for a, b in steps:
            T = stepper.step(T)
            power[s] = model.setup.mean_power(a, b)
            which[s] = k
            s += 1
        end[k] = s - 1
        free[k] = P @ T[0]
    Z = np.zeros((M, r, M, p))
    for s in np.flatnonzero(power != 0):
        later = np.flatnonzero(end >= s)
        Z[which[s], :, later, :] += power[s] * coef[end[later] - s].transpose(0, 2, 1)
    heated = np.zeros(M, bool)
    heated[which[power != 0]] = True
    return SensorResponse(model, free, V, Z.reshape(M * r, M * p), heated)
