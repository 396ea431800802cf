"""The set-up of :class:`fem.stepper.HeatStepper`: which operator, which solver.

:class:`~fem.stepper.HeatStepper` validates its input, builds its operator, chooses its
method and steps; the choices live here, as functions of the stepper ``st`` being built.
They read the fields the stepper has validated:

``mesh``
    the skfem.MeshTet;
``vhc``, ``tc``
    array (nelements,): J cm^-3 K^-1 and W cm^-1 K^-1 per element;
``dt``, ``theta``
    s, the time step; the implicitness in [0, 1];
``boundary``, ``lumped``, ``mass``
    the :class:`fem.bc.HeatBoundary`, the lumped P1 mass (bool), the mass kind
    (:data:`fem.fastdiag.MASS_KINDS`);
``operator``, ``layers``
    ``"p1"`` or ``"kronecker"``; (array (nz,), array (nz,)) or None, VHC and TC per
    element layer;
``M``, ``K``, ``R``, ``g``
    csr (npoints, npoints) J/K, W/K, W/K, and array (npoints,) W;
``free``, ``npoints``
    int array, the nodes not held by fixed faces; the node count,

and set what they build in it: ``layers``, ``M``, ``K``, ``R``, ``g`` (the
tensor-product operator), and the private state of the steps: ``_grid`` (the
:class:`fem.mesh.BoxGrid` of a box mesh, looked for once), ``_m_lumped`` (array
(npoints,), J/K, or None), ``_m_tridiag`` (the 1-D mass factors of the right-hand side),
``_theta_tridiag`` (with them the 1-D stiffness factors, where a theta < 1 step's
right-hand side is computed in one pass),
``_solver``, ``_order`` (int array, the unknowns in the solver's order),
``_identity_order`` and ``_layer_mean`` (bool). Nothing else imports them; the stepper
is the public face (its docstring describes the choices).
"""

from __future__ import annotations

import numpy as np

from .fastdiag import KroneckerSolver, NotApplicable
from .layered import (
    LayeredKroneckerSolver,
    layer_coefficients,
    layer_means,
    tensor_product_operators,
)
from .linsolve import BatchedPCG, DirectSolver
from .mesh import element_volumes, structured_grid

__all__ = [
    "JACOBI_BELOW",
    "KRON_PRECONDITIONER_MAX_RATIO",
    "auto_operator",
    "choose_solver",
    "fast_unavailable",
    "kron_preconditioner",
    "kronecker_operators",
    "layers_or_none",
]

#: the faces whose convection keeps x and y from separating in a layered operator
_SIDE_FACES = ("x-", "x+", "y-", "y+")
#: largest max/min ratio of the elements' VHC and of their TC for which PCG is preconditioned
#: by the fast diagonalization of the volume-averaged operator; beyond, Jacobi. One
#: application costs about 3.5 Jacobi iterations (101^3 nodes), and its iterations grow with
#: the contrast: two layers at MCmatlab's large steps took 7 / 10 / 12 iterations against
#: Jacobi's 23 / 21 / 20 at VHC ratios 2 / 4 / 8 (equal time at 2), 5 / 6 / 7 against 26 /
#: 25 / 23 at TC ratios 2 / 4 / 8 (equal time near 4); MCmatlab's Example 14 (VHC ratio 477)
#: 40 against 13, ten times slower.
KRON_PRECONDITIONER_MAX_RATIO = {"vhc": 2.0, "tc": 4.0}
#: with the layer-mean preconditioner, solves whose stiffness over mass on the diagonal
#: (:class:`fem.linsolve.BatchedPCG`'s ``jacobi_below``) is below this use Jacobi: short steps,
#: where the mass dominates. On MCmatlab's Example 4 (41^3 nodes, rtol 1e-9), at ratios 0.05 /
#: 0.18 / 0.53 / 1.8 / 5.3 / 18, Jacobi took 3 / 5 / 8 / 14 / 24 / 47 iterations, the layer
#: means 7 / 7 / 8 / 8 / 8 / 8 at about 2.5-4 times the cost each: equal time near 3-5.
JACOBI_BELOW = 3.0
_INHOMOGENEOUS = "VHC and TC must be homogeneous"


# ------------------------------------------------------------------ where it applies
def fast_unavailable(st) -> str | None:
    """Why the fast diagonalization of one medium does not apply, or None where it does.

    Sets ``st._grid`` (the :class:`fem.mesh.BoxGrid` of the mesh, or None) when only the
    mesh is left to check.

    Returns
    -------
    str or None
        The reason, a phrase for the error messages; ``"VHC and TC must be homogeneous"``
        is the one that leaves the layered solve open.
    """
    if not st.lumped and st.mass == "lumped":
        return "consistent mass is not a Kronecker product"
    if np.ptp(st.vhc) != 0 or np.ptp(st.tc) != 0:
        return _INHOMOGENEOUS
    if not st.tc.any():
        return "TC = 0 (no conduction: the step is a diagonal solve)"
    st._grid = structured_grid(st.mesh)
    if st._grid is None:
        return "the mesh is not a fem.mesh.box_mesh"
    return None


def layers_or_none(st):
    """VHC and TC per element layer, or None.

    Returns
    -------
    (array (nz,), array (nz,)) or None
        J cm^-3 K^-1 and W cm^-1 K^-1 per element layer on a box mesh whose media vary
        only with z and conduct somewhere, with a Kronecker-product mass; else None. The
        box mesh's grid is kept in ``st._grid``.
    """
    if not st.lumped and st.mass == "lumped" or not st.tc.any():
        return None
    grid = getattr(st, "_grid", None) or structured_grid(st.mesh)
    if grid is None:
        return None
    st._grid = grid
    c, k = layer_coefficients(grid, st.vhc), layer_coefficients(grid, st.tc)
    return None if c is None or k is None else (c, k)


# ------------------------------------------------------------------------ operator
def auto_operator(st) -> str:
    """``operator="auto"``'s choice, ``"p1"`` or ``"kronecker"`` (see the stepper).

    The layers it finds are kept in ``st.layers``, so that the tensor-product operator
    does not look for them again.
    """
    if st.mass == "consistent":
        return "kronecker"  # the trilinear hexahedron's mass: the tensor product's only
    if not st.tc.all():
        return "p1"  # an insulator somewhere: no direct layered solve
    if np.ptp(st.vhc) == 0 and np.ptp(st.tc) == 0:
        if st.mass == "lumped":
            return "p1"  # the P1 operator's exact fast diagonalization
        return "kronecker" if structured_grid(st.mesh) is not None else "p1"
    if any(st.boundary[face].kind == "convective" for face in _SIDE_FACES):
        return "p1"  # x and y do not separate: LayeredKroneckerSolver does not apply
    st.layers = layers_or_none(st)
    return "p1" if st.layers is None else "kronecker"


def kronecker_operators(st) -> None:
    """Set ``st``'s M, K, R (csr (npoints, npoints): J/K, W/K, W/K) and g ((npoints,), W)
    to their tensor-product forms (``operator="kronecker"``), with ``st.layers`` and the
    mass of the right-hand side (``_m_lumped`` or ``_m_tridiag``).

    Raises
    ------
    ValueError
        Where the tensor product does not apply (not a box mesh, media that vary
        across x or y, consistent P1 mass, no conduction).
    """
    why = fast_unavailable(st)
    layers = None
    if why == _INHOMOGENEOUS:
        layers = st.layers if st.layers is not None else layers_or_none(st)
        if layers is None:
            why = "VHC and TC must be homogeneous or vary only with depth z"
    if why is not None and layers is None:
        raise ValueError(f"operator='kronecker' is not applicable: {why}")
    st.layers = layers
    ops = tensor_product_operators(st._grid, st.boundary, st.mass,
                                   float(st.vhc[0]), float(st.tc[0]), layers)
    st.M, st.K, st.R, st.g = ops["M"], ops["K"], ops["R"], ops["g"]
    st._m_lumped = ops["m_lumped"]
    if ops["m_tridiag"] is not None:
        # the right-hand side's mass product, axis by axis (numba), not the 27-point M
        st._m_tridiag = ops["m_tridiag"]
        if st.theta != 1.0 and st.R.nnz == 0:  # no convective face: K's product fused in
            st._theta_tridiag = ops["theta_tridiag"]


# -------------------------------------------------------------------------- solver
def choose_solver(st, method: str, direct_max_nodes: int, rtol: float,
                  gpu_device: int = 0) -> str:
    """Build the stepper's solver (``st._solver``, with ``st._order`` and
    ``st._identity_order``) for ``method`` and return the method in use.

    Parameters
    ----------
    st : HeatStepper
        With its operator and fixed nodes set.
    method : {"auto", "fast", "direct", "pcg", "gpu"}
        As the stepper's.
    direct_max_nodes : int
        Largest mesh for the sparse LU under ``"auto"``.
    rtol : float
        Relative residual tolerance of PCG and of the GPU's CG.
    gpu_device : int
        The CUDA device of ``"gpu"``.

    Returns
    -------
    str
        ``"fast"``, ``"direct"``, ``"pcg"`` or ``"gpu"``.

    Raises
    ------
    ValueError
        ``method="fast"`` where no fast solver applies (the reason in the message).
    """
    f = st.free
    if method in ("auto", "fast"):
        why = fast_unavailable(st)
        if why is None:
            try:
                exact = st.operator == "p1"
                st._solver = KroneckerSolver(
                    st._grid, st.boundary, float(st.vhc[0]), float(st.tc[0]),
                    st.dt, st.theta, st._m_lumped if exact else None,
                    st.K if exact else None, st.R.diagonal() if exact else None,
                    st._free_mask(), exact=exact, mass=st.mass)
                st._order = st._solver.free_nodes
                st._identity_order = np.array_equal(st._order, np.arange(st.npoints))
                return "fast"
            except NotApplicable as exc:
                why = str(exc)
        layers = st.layers  # set by kronecker_operators
        if why == _INHOMOGENEOUS and layers is not None:
            try:
                st._solver = LayeredKroneckerSolver(
                    st._grid, st.boundary, layers[0], layers[1], st.dt, st.theta,
                    mass=st.mass)
                if not np.array_equal(np.sort(st._solver.free_nodes), f):
                    raise NotApplicable("fixed nodes are not whole faces of the box")
                st._order = st._solver.free_nodes
                st._identity_order = np.array_equal(st._order, np.arange(st.npoints))
                return "fast"
            except NotApplicable as exc:
                why = str(exc)
        if method == "fast":
            raise ValueError(f"method='fast' is not applicable: {why}")
    st._order = f
    st._identity_order = f.size == st.npoints
    if st._identity_order:
        Mf, Kf, Rf = st.M, st.K, st.theta * st.R
    else:
        Mf, Kf, Rf = st.M[f][:, f], st.K[f][:, f], st.theta * st.R[f][:, f]
    if method == "gpu":
        from .gpu import make_solver  # numba.cuda only where asked for

        st._solver = make_solver(Mf, Kf, Rf, rtol=rtol, device=gpu_device)
        return "gpu"
    if method == "direct" or (method == "auto" and st.npoints <= direct_max_nodes):
        st._solver = DirectSolver(Mf, Kf, Rf)
        return "direct"
    precond = kron_preconditioner(st)
    st._solver = BatchedPCG(Mf, Kf, Rf, rtol=rtol, precond=precond,
                            jacobi_below=JACOBI_BELOW if st._layer_mean else 0.0)
    return "pcg"


def kron_preconditioner(st):
    """A tensor-product solve close to the step matrix, on structured meshes whose VHC and
    TC vary little where it does not follow them (:data:`KRON_PRECONDITIONER_MAX_RATIO`);
    else None (Jacobi). Sets ``st._layer_mean``: whether it is the layer-mean one.

    Media that vary in z: the layered operator of each element layer's mean VHC and TC
    (:class:`fem.layered.LayeredKroneckerSolver`), so that only what crosses the layers
    (a vessel in the dermis) is left to the iterations; the ratio is then taken within
    each layer. One medium, a convective x or y face (the layers do not separate) or a
    layer-mean solve that does not apply: the volume-averaged operator
    (:class:`fem.fastdiag.KroneckerSolver`), the ratio over the whole mesh. On MCmatlab's
    Example 4 (gel, epidermis, dermis and a vessel across the layers, 41^3 nodes, rtol
    1e-9) the layer means took 7-8 iterations per solve where the volume mean took 9-12
    (13.6-13.9 ms against 20.5-23.8 ms at steps of 1-10 ms, one thread). What is left is
    mostly not the vessel but the P1 operator's departure from the tensor-product one on
    the box's edges and where an interface meets a side face: the same preconditioner on
    the 7-point finite-volume operator of the same media took 2 iterations at 1 ms and 6
    at 10 ms. Short steps go to Jacobi (:data:`JACOBI_BELOW`).

    Returns
    -------
    callable or None
        ``precond(Rr, a, b) -> Z`` for :class:`fem.linsolve.BatchedPCG`: residual
        columns ``Rr`` (nfree, N), W; ``a`` (N,), 1/s, the members' VHC scales over dt;
        ``b`` (N,), theta times their TC scales; ``Z`` (nfree, N), K.
    """
    st._layer_mean = False
    averaged = st.mass == "averaged"  # P1's averaged mass: the Kronecker one's
    if not (st.lumped or averaged) or st.theta == 0 or not st.tc.any():
        return None
    grid = getattr(st, "_grid", None) or structured_grid(st.mesh)
    if grid is None:
        return None
    kind = "averaged" if averaged else "lumped"
    solver = None
    if np.ptp(st.vhc) != 0 or np.ptp(st.tc) != 0:
        (c_layers, c_ratio), (k_layers, k_ratio) = (layer_means(grid, st.vhc),
                                                    layer_means(grid, st.tc))
        if (c_ratio <= KRON_PRECONDITIONER_MAX_RATIO["vhc"]
                and k_ratio <= KRON_PRECONDITIONER_MAX_RATIO["tc"]):
            try:
                solver = LayeredKroneckerSolver(grid, st.boundary, c_layers, k_layers,
                                                st.dt, st.theta, mass=kind)
            except NotApplicable:
                solver = None
    if solver is None:
        for name, coefficient in (("vhc", st.vhc), ("tc", st.tc)):
            if coefficient.max() > KRON_PRECONDITIONER_MAX_RATIO[name] * coefficient.min():
                return None
        vol = element_volumes(st.mesh)
        c_mean = float(vol @ st.vhc / vol.sum())
        k_mean = float(vol @ st.tc / vol.sum())
        try:
            solver = KroneckerSolver(grid, st.boundary, c_mean, k_mean, st.dt,
                                     st.theta, None, None, None, st._free_mask(),
                                     exact=False, mass=kind)
        except NotApplicable:
            return None
    if not np.array_equal(solver.free_nodes, st.free):
        return None
    st._layer_mean = isinstance(solver, LayeredKroneckerSolver)
    dt = st.dt

    def precond(Rr, a, b):
        return solver.solve(np.ascontiguousarray(Rr.T), a * dt, b / st.theta).T

    return precond
