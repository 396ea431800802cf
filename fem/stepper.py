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
    (:data:`fem.stepper_setup.KRON_PRECONDITIONER_MAX_RATIO`);
``"gpu"``
    never chosen by ``"auto"``: Jacobi-preconditioned CG on an NVIDIA GPU
    (:class:`fem.gpu.CudaPCG`, made by :func:`fem.gpu.make_solver`; the ``gpu`` extra),
    warm-started from the last solution kept on the device.

The operator, P1 or tensor-product, can be chosen the same way (``operator="auto"``):
the tensor product where it is solved directly and P1 is not (media that vary only with
depth; one medium with a mass that is not lumped). Both choices, and the building of the
tensor-product operator and of the solver, are in :mod:`fem.stepper_setup`.
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
from .fastdiag import MASS_KINDS
from .stepper_setup import (
    JACOBI_BELOW,
    KRON_PRECONDITIONER_MAX_RATIO,
    auto_operator,
    choose_solver,
    kronecker_operators,
)
from .threads import run_blocks

__all__ = ["JACOBI_BELOW", "KRON_PRECONDITIONER_MAX_RATIO", "HeatStepper"]

_METHODS = ("auto", "fast", "direct", "pcg", "gpu")
_OPERATORS = ("p1", "kronecker", "auto")


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
            operator = auto_operator(self)
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
            kronecker_operators(self)
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

        self.method = choose_solver(self, method, direct_max_nodes, rtol, gpu_device)

    # -------------------------------------------------------------- set-up
    def _free_mask(self) -> np.ndarray:
        """bool array (npoints,): True on the nodes not held by fixed faces."""
        mask = np.zeros(self.npoints, dtype=bool)
        mask[self.free] = True
        return mask

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
        # the tensor-product operator's theta step: its stiffness product in the mass's pass
        fused = getattr(self, "_theta_tridiag", None)
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

            beta = None if fused is None else np.ascontiguousarray((1.0 - th) * b)

            def block(i0, i1):
                fb = f2 if f2.shape[0] == 1 else f2[i0:i1]
                if fused is not None:
                    _kernels.tridiag3_theta_rhs(T4[i0:i1], a_c[i0:i1], beta[i0:i1], *fused,
                                                self.g, fb, rhs[i0:i1])
                else:
                    _kernels.tridiag3_rhs(T4[i0:i1], a_c[i0:i1], d[0], o[0], d[1], o[1], d[2],
                                          o[2], c, self.g, fb, rhs[i0:i1])

            run_blocks(N, block, 2 if N >= 8 else 1)
        else:
            rhs = self._apply(self.M, T2) * a[:, None] + self.g
            if f is not None:
                rhs += f
        if th != 1.0 and fused is None:
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

