r"""Implicit theta-scheme time stepping of the P1 heat equation for ensembles.

One step of size :math:`\Delta t` solves

.. math::

    \Big(\frac{M}{\Delta t} + \theta (K + R)\Big) T^{n+1}
      = \Big(\frac{M}{\Delta t} - (1-\theta)(K + R)\Big) T^{n} + f + g,

with ``f`` the nodal heat load (W) given to :meth:`HeatStepper.step`, ``g`` the
convective load :math:`h T_{amb}\int\phi_i`, and the nodes of fixed faces held
at their temperature (Dirichlet rows).  ``theta = 1`` is backward Euler
(first order, monotone with lumped mass), ``theta = 0.5`` Crank-Nicolson
(second order).  Per-member factors on VHC and TC multiply ``M`` and ``K``.

Three solvers, chosen automatically (``method="auto"``), and a fourth on request:

``"fast"``
    structured :func:`fem.mesh.box_mesh`, homogeneous VHC and TC, lumped
    mass: fast diagonalization (:class:`fem.fastdiag.KroneckerSolver`),
    exact for the P1 system, per-member scales at no extra cost; with
    ``operator="kronecker"`` also media that vary only with depth z
    (:class:`fem.layered.LayeredKroneckerSolver`: x-y modes, a tridiagonal
    solve in z per mode) when the x and y faces are insulating or fixed;
``"direct"``
    up to ``direct_max_nodes`` (30,000) nodes: sparse LU, cached per
    distinct pair of member scales (the LU of a 3-D mesh fills in: at 115,000 nodes of
    two media it took 251 s and 1.2 GB where PCG took 4 s and 0.2 GB for two steps);
``"pcg"``
    larger meshes: batched preconditioned CG warm-started from the previous
    temperatures; on box meshes whose VHC and TC vary little within each element
    layer the preconditioner is the direct solve of the operator of the layers' mean
    VHC and TC (:class:`fem.layered.LayeredKroneckerSolver`; one medium: the fast
    diagonalization of the volume-averaged operator), else Jacobi
    (:data:`KRON_PRECONDITIONER_MAX_RATIO`);
``"gpu"``
    never chosen by ``"auto"``: Jacobi-preconditioned CG on an NVIDIA GPU
    (:class:`fem.gpu.CudaPCG`, made by :func:`fem.gpu.make_solver`; the ``gpu`` extra),
    warm-started from the last solution kept on the device.

The operator, P1 or tensor-product, can be chosen the same way (``operator="auto"``):
the tensor product where it is solved directly and P1 is not (media that vary only with
depth; one medium with a mass that is not lumped).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import _kernels
from .assembly import (
    element_coefficient,
    lumped_mass,
    mass_matrix,
    robin_load,
    robin_matrix,
    stiffness_matrix,
)
from .bc import FACES, HeatBoundary, face_nodes
from .fastdiag import MASS_KINDS, KroneckerSolver, NotApplicable
from .layered import (
    LayeredKroneckerSolver,
    layer_coefficients,
    layer_means,
    tensor_product_operators,
)
from .linsolve import BatchedPCG, DirectSolver
from .mesh import element_volumes, structured_grid
from .threads import run_blocks

__all__ = ["JACOBI_BELOW", "KRON_PRECONDITIONER_MAX_RATIO", "HeatStepper"]

_METHODS = ("auto", "fast", "direct", "pcg", "gpu")
_OPERATORS = ("p1", "kronecker", "auto")
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


class HeatStepper:
    """Implicit heat steps on a tetrahedral mesh, batched over ensemble members.

    Parameters
    ----------
    mesh : skfem.MeshTet
    vhc : float or array (nelements,)
        J cm^-3 K^-1, volumetric heat capacity per element (> 0).
    tc : float or array (nelements,)
        W cm^-1 K^-1, thermal conductivity per element (>= 0; 0: a perfect insulator).
    dt : float
        s, time step (> 0).
    theta : float
        In [0, 1]; 1 backward Euler (default), 0.5 Crank-Nicolson.
    boundary : HeatBoundary, optional
        Default: all faces insulating.
    lumped : bool
        Lumped (row-sum) mass (default) or consistent mass.
    operator : {"p1", "kronecker", "auto"}
        ``"p1"`` (default): the exact P1 matrices of the mesh. ``"kronecker"``: on a
        structured box mesh with homogeneous VHC and TC, the tensor-product operators
        ``Mx⊗My⊗Mz`` and the Kronecker sum of 1-D stiffnesses (the vertex-centred
        finite-volume scheme, 7-point stencil). It equals P1 except on the twelve box
        edges, where the Kuhn split weighs mass and stiffness by 4/3 or 2/3; it is as
        accurate away from them and, unlike P1, needs no per-member edge correction
        when every member has its own VHC and TC, so ensembles whose scales change at
        every step (joint estimation of VHC, TC) cost the same as fixed ones. VHC and TC
        may also vary with depth only (constant over each element layer): the z factors
        are then weighted layer by layer (:mod:`fem.layered`), and with insulating or
        fixed x and y faces the solve is direct (:class:`fem.layered.LayeredKroneckerSolver`).
        ``"auto"``: ``"kronecker"`` where it is solved directly and P1 is not, i.e. media
        that conduct everywhere and vary only with depth on a box mesh with no convective
        x or y face, or one conducting medium with a mass that is not lumped (P1 with
        lumped mass has its own exact fast solver); else ``"p1"``. The choice is in the
        ``operator`` attribute.
    mass : {"lumped", "averaged", "consistent"}
        With ``operator="kronecker"``: the 1-D mass matrices of the tensor product
        (:func:`fem.fastdiag.one_d_mass`). ``"averaged"`` (the mean of the lumped and
        the consistent mass) cancels the leading dispersion error of both: fourth-order
        modes on the same mesh, at the cost of a 27-point mass stencil in the
        right-hand side. ``"consistent"``: the trilinear hexahedron's mass and stiffness.
        With ``operator="p1"``: ``"averaged"`` is the mean of the lumped and the
        consistent P1 mass (any mesh and media; solved by PCG, preconditioned by the
        Kronecker operator with the averaged mass on box meshes).
    method : {"auto", "fast", "direct", "pcg", "gpu"}
        ``"gpu"``: the solves on a CUDA GPU (:func:`fem.gpu.make_solver`); raises
        RuntimeError where numba-cuda or a GPU is missing. Its error message names
        ``HS.use_gpu``, the switch of the heat front end that asks for it.
    direct_max_nodes : int
        Largest mesh for the sparse LU path under ``"auto"``.
    rtol : float
        Relative residual tolerance of the PCG path (the right-hand side
        includes ``M T / dt``, so 1e-9 is about 1e-9 of the temperatures); also the
        GPU's.
    gpu_device : int
        The CUDA device of ``method="gpu"`` (``numba.cuda.select_device``).

    Attributes
    ----------
    method : str
        The solver in use.
    operator : str
        The operator in use, ``"p1"`` or ``"kronecker"`` (the choice of ``"auto"``).
    layers : (array (nz,), array (nz,)) or None
        J cm^-3 K^-1 and W cm^-1 K^-1: VHC and TC per element layer of a tensor-product
        operator of media that vary only with depth; None otherwise.
    M : csr (npoints, npoints)
        J/K, mass matrix (VHC-weighted).
    K : csr (npoints, npoints)
        W/K, stiffness matrix (TC-weighted).
    R : csr (npoints, npoints)
        W/K, convective boundary matrix.
    g : array (npoints,)
        W, convective load.
    fixed : int array
        Nodes held by fixed faces; ``fixed_values`` their temperature (NaN:
        hold the temperature they have).

    Examples
    --------
    >>> from fem import box_mesh, HeatStepper
    >>> mesh = box_mesh(4, 4, 2, 0.5, 0.5, 0.25)
    >>> stepper = HeatStepper(mesh, vhc=3.9, tc=0.0052, dt=0.1)
    >>> T = np.full(mesh.p.shape[1], 37.0)
    >>> T = stepper.step(T, load=np.zeros_like(T))
    >>> stepper.method
    'fast'
    """

    def __init__(self, mesh, vhc, tc, dt: float, theta: float = 1.0,
                 boundary: HeatBoundary | None = None, lumped: bool = True,
                 method: str = "auto", direct_max_nodes: int = 30_000, rtol: float = 1e-9,
                 operator: str = "p1", mass: str = "lumped", gpu_device: int = 0):
        self.mesh = mesh
        n = mesh.p.shape[1]
        self.vhc = element_coefficient(mesh, vhc, "vhc")
        self.tc = element_coefficient(mesh, tc, "tc", allow_zero=True)
        dt_f = float(dt)
        if not np.isfinite(dt_f) or dt_f <= 0:
            raise ValueError(f"dt must be > 0, got {dt_f!r}")
        th = float(theta)
        if not 0.0 <= th <= 1.0:
            raise ValueError(f"theta must be in [0, 1], got {th!r}")
        if method not in _METHODS:
            raise ValueError(f"method must be one of {_METHODS}, got {method!r}")
        if boundary is None:
            boundary = HeatBoundary()
        if not isinstance(boundary, HeatBoundary):
            raise ValueError(f"boundary must be a HeatBoundary, got {type(boundary).__name__}")
        self.dt, self.theta, self.boundary, self.lumped = dt_f, th, boundary, lumped
        self.npoints = n

        if operator not in _OPERATORS:
            raise ValueError(f"operator must be one of {_OPERATORS}, got {operator!r}")
        if mass not in MASS_KINDS:
            raise ValueError(f"mass must be one of {MASS_KINDS}, got {mass!r}")
        self.mass = mass
        self.layers = None
        if operator == "auto":
            operator = self._auto_operator()
        self.operator = operator
        if mass == "consistent" and operator != "kronecker":
            raise ValueError("mass='consistent' needs operator='kronecker' (with 'p1': "
                             "lumped=False)")
        if mass == "averaged" and operator == "p1" and not lumped:
            raise ValueError("mass='averaged' takes the place of lumped=False")
        if operator == "kronecker":
            # the tensor-product forms only: assembling the P1 matrices first would hold
            # both at once (about 110 more bytes per node at the peak of a 10^6-node run)
            self._m_lumped = None
            self._kronecker_operators()
        else:
            self._m_lumped = lumped_mass(mesh, self.vhc) if lumped else None
            self.M = (sp.diags_array(self._m_lumped, format="csr") if lumped
                      else mass_matrix(mesh, self.vhc, lumped=False))
            self.K = stiffness_matrix(mesh, self.tc)
            self.R = robin_matrix(mesh, boundary, lumped=lumped)
            self.g = robin_load(mesh, boundary)
            if mass == "averaged":  # the mean of the lumped and consistent
                self.M = 0.5 * (self.M + mass_matrix(mesh, self.vhc, lumped=False))
                self._m_lumped = None

        # fixed nodes: later faces in FACES order win on shared edges
        values = np.full(n, np.inf)
        for face in FACES:
            bc = boundary[face]
            if bc.kind == "fixed":
                nodes = face_nodes(mesh, face)
                values[nodes] = np.nan if bc.temperature is None else bc.temperature
        is_fixed = ~np.isinf(values)
        self.fixed = np.flatnonzero(is_fixed)
        self.fixed_values = values[self.fixed]
        self.free = np.flatnonzero(~is_fixed)
        if self.free.size == 0:
            raise ValueError("boundary fixes every node; nothing to solve")
        f, d = self.free, self.fixed
        # slicing the matrices of a 10^6-node mesh takes seconds: only when nodes are held
        self._A_fd = (self.M[f][:, d], self.K[f][:, d], self.R[f][:, d]) if d.size else None

        self.method = self._choose(method, direct_max_nodes, rtol, gpu_device)

    # -------------------------------------------------------------- set-up
    def _auto_operator(self) -> str:
        """``operator="auto"``'s choice (see the class); the layers it finds are kept in
        ``self.layers``, so that the tensor-product operator does not look for them again."""
        if self.mass == "consistent":
            return "kronecker"  # the trilinear hexahedron's mass: the tensor product's only
        if not self.tc.all():
            return "p1"  # an insulator somewhere: no direct layered solve
        if np.ptp(self.vhc) == 0 and np.ptp(self.tc) == 0:
            if self.mass == "lumped":
                return "p1"  # the P1 operator's exact fast diagonalization
            return "kronecker" if structured_grid(self.mesh) is not None else "p1"
        if any(self.boundary[face].kind == "convective" for face in _SIDE_FACES):
            return "p1"  # x and y do not separate: LayeredKroneckerSolver does not apply
        self.layers = self._layers_or_none()
        return "p1" if self.layers is None else "kronecker"

    def _kronecker_operators(self) -> None:
        """Replace M, K, R, g by their tensor-product forms (``operator="kronecker"``)."""
        why = self._fast_unavailable()
        layers = None
        if why == _INHOMOGENEOUS:
            layers = self.layers if self.layers is not None else self._layers_or_none()
            if layers is None:
                why = "VHC and TC must be homogeneous or vary only with depth z"
        if why is not None and layers is None:
            raise ValueError(f"operator='kronecker' is not applicable: {why}")
        self.layers = layers
        ops = tensor_product_operators(self._grid, self.boundary, self.mass,
                                       float(self.vhc[0]), float(self.tc[0]), layers)
        self.M, self.K, self.R, self.g = ops["M"], ops["K"], ops["R"], ops["g"]
        self._m_lumped = ops["m_lumped"]
        if ops["m_tridiag"] is not None:
            # the right-hand side's mass product, axis by axis (numba), not the 27-point M
            self._m_tridiag = ops["m_tridiag"]

    def _choose(self, method: str, direct_max_nodes: int, rtol: float,
                gpu_device: int = 0) -> str:
        f = self.free
        if method in ("auto", "fast"):
            why = self._fast_unavailable()
            if why is None:
                try:
                    exact = self.operator == "p1"
                    self._solver = KroneckerSolver(
                        self._grid, self.boundary, float(self.vhc[0]), float(self.tc[0]),
                        self.dt, self.theta, self._m_lumped if exact else None,
                        self.K if exact else None, self.R.diagonal() if exact else None,
                        self._free_mask(), exact=exact, mass=self.mass)
                    self._order = self._solver.free_nodes
                    self._identity_order = np.array_equal(self._order, np.arange(self.npoints))
                    return "fast"
                except NotApplicable as exc:
                    why = str(exc)
            layers = self.layers  # set by _kronecker_operators
            if why == _INHOMOGENEOUS and layers is not None:
                try:
                    self._solver = LayeredKroneckerSolver(
                        self._grid, self.boundary, layers[0], layers[1], self.dt, self.theta,
                        mass=self.mass)
                    if not np.array_equal(np.sort(self._solver.free_nodes), f):
                        raise NotApplicable("fixed nodes are not whole faces of the box")
                    self._order = self._solver.free_nodes
                    self._identity_order = np.array_equal(self._order, np.arange(self.npoints))
                    return "fast"
                except NotApplicable as exc:
                    why = str(exc)
            if method == "fast":
                raise ValueError(f"method='fast' is not applicable: {why}")
        self._order = f
        self._identity_order = f.size == self.npoints
        if self._identity_order:
            Mf, Kf, Rf = self.M, self.K, self.theta * self.R
        else:
            Mf, Kf, Rf = self.M[f][:, f], self.K[f][:, f], self.theta * self.R[f][:, f]
        if method == "gpu":
            from .gpu import make_solver  # numba.cuda only where asked for

            self._solver = make_solver(Mf, Kf, Rf, rtol=rtol, device=gpu_device)
            return "gpu"
        if method == "direct" or (method == "auto" and self.npoints <= direct_max_nodes):
            self._solver = DirectSolver(Mf, Kf, Rf)
            return "direct"
        precond = self._kron_preconditioner()
        self._solver = BatchedPCG(Mf, Kf, Rf, rtol=rtol, precond=precond,
                                  jacobi_below=JACOBI_BELOW if self._layer_mean else 0.0)
        return "pcg"

    def _kron_preconditioner(self):
        """A tensor-product solve close to the step matrix, on structured meshes whose VHC and
        TC vary little where it does not follow them (:data:`KRON_PRECONDITIONER_MAX_RATIO`);
        else None (Jacobi).

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
        """
        self._layer_mean = False
        averaged = self.mass == "averaged"  # P1's averaged mass: the Kronecker one's
        if not (self.lumped or averaged) or self.theta == 0 or not self.tc.any():
            return None
        grid = getattr(self, "_grid", None) or structured_grid(self.mesh)
        if grid is None:
            return None
        kind = "averaged" if averaged else "lumped"
        solver = None
        if np.ptp(self.vhc) != 0 or np.ptp(self.tc) != 0:
            (c_layers, c_ratio), (k_layers, k_ratio) = (layer_means(grid, self.vhc),
                                                        layer_means(grid, self.tc))
            if (c_ratio <= KRON_PRECONDITIONER_MAX_RATIO["vhc"]
                    and k_ratio <= KRON_PRECONDITIONER_MAX_RATIO["tc"]):
                try:
                    solver = LayeredKroneckerSolver(grid, self.boundary, c_layers, k_layers,
                                                    self.dt, self.theta, mass=kind)
                except NotApplicable:
                    solver = None
        if solver is None:
            for name, coefficient in (("vhc", self.vhc), ("tc", self.tc)):
                if coefficient.max() > KRON_PRECONDITIONER_MAX_RATIO[name] * coefficient.min():
                    return None
            vol = element_volumes(self.mesh)
            c_mean = float(vol @ self.vhc / vol.sum())
            k_mean = float(vol @ self.tc / vol.sum())
            try:
                solver = KroneckerSolver(grid, self.boundary, c_mean, k_mean, self.dt,
                                         self.theta, None, None, None, self._free_mask(),
                                         exact=False, mass=kind)
            except NotApplicable:
                return None
        if not np.array_equal(solver.free_nodes, self.free):
            return None
        self._layer_mean = isinstance(solver, LayeredKroneckerSolver)
        dt = self.dt

        def precond(Rr, a, b):
            return solver.solve(np.ascontiguousarray(Rr.T), a * dt, b / self.theta).T

        return precond

    def _free_mask(self) -> np.ndarray:
        mask = np.zeros(self.npoints, dtype=bool)
        mask[self.free] = True
        return mask

    def _layers_or_none(self):
        """(vhc, tc) per element layer ((nz,) each) on a box mesh whose media vary only
        with z and conduct somewhere, with a Kronecker-product mass; else None."""
        if not self.lumped and self.mass == "lumped" or not self.tc.any():
            return None
        grid = getattr(self, "_grid", None) or structured_grid(self.mesh)
        if grid is None:
            return None
        self._grid = grid
        c, k = layer_coefficients(grid, self.vhc), layer_coefficients(grid, self.tc)
        return None if c is None or k is None else (c, k)

    def _fast_unavailable(self) -> str | None:
        if not self.lumped and self.mass == "lumped":
            return "consistent mass is not a Kronecker product"
        if np.ptp(self.vhc) != 0 or np.ptp(self.tc) != 0:
            return _INHOMOGENEOUS
        if not self.tc.any():
            return "TC = 0 (no conduction: the step is a diagonal solve)"
        self._grid = structured_grid(self.mesh)
        if self._grid is None:
            return "the mesh is not a fem.mesh.box_mesh"
        return None

    # ---------------------------------------------------------------- step
    def _scales(self, scale, N: int, name: str) -> np.ndarray:
        if scale is None:
            return np.ones(N)
        s = np.asarray(scale, dtype=float)
        if s.ndim == 0:
            s = np.full(N, float(s))
        if s.shape != (N,):
            raise ValueError(f"{name} must be a scalar or have shape ({N},), got shape {s.shape}")
        bad = np.flatnonzero(~np.isfinite(s) | (s <= 0))
        if bad.size:
            raise ValueError(f"{name} must be > 0, got {name}[{bad[0]}]={float(s[bad[0]])!r}")
        return s

    def step(self, T, load=None, vhc_scale=None, tc_scale=None) -> np.ndarray:
        """Advance temperatures by one time step.

        Parameters
        ----------
        T : array (npoints,) or (N, npoints)
            deg C, temperatures at the start of the step.
        load : array (npoints,) or (N, npoints), optional
            W, nodal heat load over the step (e.g. ``L @ S.ravel()`` from
            :func:`fem.source.voxel_load_matrix`); a single vector applies to
            every member.
        vhc_scale, tc_scale : float or array (N,), optional
            Per-member factors on VHC and TC.

        Returns
        -------
        array, the shape of T
            deg C, temperatures at the end of the step.
        """
        T_in = np.asarray(T, dtype=float)
        single = T_in.ndim == 1
        T2 = T_in[None, :] if single else T_in
        if T2.ndim != 2 or T2.shape[1] != self.npoints:
            raise ValueError(f"T must have shape ({self.npoints},) or (N, {self.npoints}), "
                             f"got {T_in.shape}")
        N = T2.shape[0]
        a = self._scales(vhc_scale, N, "vhc_scale") / self.dt
        b = self._scales(tc_scale, N, "tc_scale")
        th = self.theta

        f = None
        if load is not None:
            f = np.asarray(load, dtype=float)
            if f.shape not in ((self.npoints,), (N, self.npoints)):
                raise ValueError(f"load must have shape ({self.npoints},) or "
                                 f"({N}, {self.npoints}), got {f.shape}")
        if self._m_lumped is not None:
            f2 = np.zeros((1, self.npoints)) if f is None else f.reshape(-1, self.npoints)
            rhs = np.empty((N, self.npoints))
            _kernels.lumped_rhs(np.ascontiguousarray(T2), np.ascontiguousarray(a),
                                self._m_lumped, self.g, np.ascontiguousarray(f2), rhs)
        elif getattr(self, "_m_tridiag", None) is not None:
            c, shape, d, o = self._m_tridiag
            f2 = np.zeros((1, self.npoints)) if f is None else f.reshape(-1, self.npoints)
            rhs = np.empty((N, self.npoints))
            # rows may be a strided view (the state part of an augmented ensemble): the
            # kernel reads it in place; member blocks on the threads of fem.threads
            T4 = T2.reshape(N, *shape)
            a_c = np.ascontiguousarray(a)

            def block(i0, i1):
                fb = f2 if f2.shape[0] == 1 else f2[i0:i1]
                _kernels.tridiag3_rhs(T4[i0:i1], a_c[i0:i1], d[0], o[0], d[1], o[1], d[2], o[2],
                                      c, self.g, fb, rhs[i0:i1])

            run_blocks(N, block, 2 if N >= 8 else 1)
        else:
            rhs = self._apply(self.M, T2) * a[:, None] + self.g
            if f is not None:
                rhs += f
        if th != 1.0:
            rhs -= (1.0 - th) * (self._apply(self.K, T2) * b[:, None] + self._apply(self.R, T2))

        if self.fixed.size == 0 and self._identity_order:
            x = self._solve(rhs, a, b, T2)
            return x[0] if single else x
        out = np.array(T2, dtype=float, copy=True)
        if self.fixed.size:
            TD = np.where(np.isnan(self.fixed_values), T2[:, self.fixed], self.fixed_values)
            Mfd, Kfd, Rfd = self._A_fd
            lift = ((Mfd @ TD.T).T * a[:, None] + (Kfd @ TD.T).T * (th * b[:, None])
                    + th * (Rfd @ TD.T).T)
            out[:, self.fixed] = TD
            rhs[:, self.free] -= lift
        order = self._order
        out[:, order] = self._solve(rhs[:, order], a, b, T2[:, order])
        return out[0] if single else out

    def _solve(self, r, a, b, x0):
        if self.method == "fast":
            return self._solver.solve(r, a * self.dt, b)
        return self._solver.solve(r, a, self.theta * b, x0=x0 if self.method == "pcg" else None)

    def _apply(self, A, T2: np.ndarray) -> np.ndarray:
        """A @ T for each member row of T2 (N, npoints)."""
        if A is self.M and self._m_lumped is not None:
            return T2 * self._m_lumped
        return (A @ T2.T).T

    # ------------------------------------------------------------- helpers
    def energy(self, T) -> np.ndarray:
        r"""Heat content :math:`\int c\,T` (J), i.e. ``1^T M T``; (N,) or scalar."""
        T = np.asarray(T, dtype=float)
        return T @ np.asarray(self.M.sum(axis=0)).ravel()

    def run(self, T0, n_steps: int, load=None, vhc_scale=None, tc_scale=None) -> np.ndarray:
        """``n_steps`` steps with a constant load; returns the final temperatures."""
        T = np.asarray(T0, dtype=float)
        for _ in range(int(n_steps)):
            T = self.step(T, load, vhc_scale, tc_scale)
        return T

