r"""Direct implicit solves on a structured box mesh whose media vary only with depth z.

On :func:`fem.mesh.box_mesh` with VHC :math:`c_l` and TC :math:`k_l` constant over each
element layer :math:`z_l < z < z_{l+1}` (water over tissue, epidermis over dermis), the
tensor-product ("kronecker") operators of :class:`fem.HeatStepper` are

.. math::

    M = M_x\otimes M_y\otimes M_z^{c},\qquad
    K = K_x\otimes M_y\otimes M_z^{k} + M_x\otimes K_y\otimes M_z^{k}
        + M_x\otimes M_y\otimes K_z^{k},

with the unit-coefficient 1-D matrices of x and y (:func:`fem.fastdiag.one_d_mass`) and the
1-D z matrices assembled interval by interval with the layer's coefficient
(:func:`layered_one_d`): :math:`K_z^{k} = \sum_l k_l\,[1, -1; -1, 1]/h` and
:math:`M_z^{w} = \sum_l w_l\,m_l` with :math:`m_l` the lumped (:math:`h/2\,I`),
consistent (:math:`h/6\,[2, 1; 1, 2]`) or averaged interval mass. This is the Galerkin form
of :math:`\int c\,u v` and :math:`\int k \nabla u\cdot\nabla v` on trilinear bricks whose
z factors are integrated exactly (the "consistent" kind) or lumped, i.e. the vertex-centred
finite-volume scheme (lumped kind). The nodes sit on the layer interfaces, so no mean of
the TC is taken across an interface: the vertical flux between nodes :math:`k` and
:math:`k+1` crosses one medium, :math:`k_l (T_{k+1} - T_k)/h` exactly; an interface
node's dual cell is half in each layer, so its lateral conductance is the thickness-
weighted arithmetic mean :math:`(k_{l-1} + k_l)/2` (conduction in parallel), and its heat
capacity likewise. A harmonic mean belongs to cell-centred schemes (MCmatlab's), where an
interface lies between two unknowns; used here on the lateral terms it would make the
scheme first order at the interface (``tests/test_fem_layered_kron.py`` fits both rates).
On a Kuhn mesh the P1 stiffness and lumped mass of such media equal these forms except on
the twelve box edges and on the lines where an interface meets the four side faces (an
interior interface node has twelve tetrahedra on either side, a side-face one 8 against 4).

With the 1-D generalized eigenpairs :math:`K_a\Phi_a = M_a\Phi_a\,\mathrm{diag}(\mu_a)`,
:math:`\Phi_a^T M_a\Phi_a = I` (a = x, y), the step matrix of member ``n``,
:math:`A_n = \alpha_n M + \beta_n K + \theta R` (:math:`\alpha_n = s^c_n/\Delta t`,
:math:`\beta_n = \theta s^k_n`), becomes block diagonal in the x-y modes:

.. math::

    (\Phi_x\otimes\Phi_y\otimes I)^T A_n (\Phi_x\otimes\Phi_y\otimes I)
      = \bigoplus_{p,q}\Big(\alpha_n M_z^{c} + \beta_n\big(K_z^{k}
        + (\mu_{x,p} + \mu_{y,q}) M_z^{k}\big) + \theta H_z\Big),

one tridiagonal system in z per mode (:math:`H_z`: the convective z faces), solved by
Thomas's algorithm. A solve costs four products with the 1-D bases of x and y, about
:math:`4(n_x + n_y)` flops per node, plus 15 per node for the tridiagonal systems: exact,
with per-member VHC and TC scales at no extra cost (the modes do not depend on them).

Faces: x and y faces insulating or fixed (a fixed face removes its nodes from the 1-D
problem); z faces insulating, fixed or convective. A convective x or y face adds
:math:`h\,e e^T\otimes M_y\otimes M_z^{1}` whose z weight is not :math:`M_z^{k}`: x and y
no longer separate, and :class:`LayeredKroneckerSolver` raises
:class:`fem.fastdiag.NotApplicable` (the stepper then falls back to its sparse solvers).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from . import _kernels
from .bc import FACES, HeatBoundary
from .fastdiag import MASS_KINDS, NotApplicable, _contract, _transpose, one_d_mass, one_d_operators
from .mesh import BoxGrid
from .threads import blas_threads, run_blocks

__all__ = ["LayeredKroneckerSolver", "layer_coefficients", "layer_means", "layered_one_d",
           "tensor_product_operators"]


def layer_coefficients(grid: BoxGrid, coefficient: np.ndarray) -> np.ndarray | None:
    """Per-layer values ((nz,)) of a per-element coefficient of ``box_mesh(grid)``, or None.

    Parameters
    ----------
    grid : BoxGrid
    coefficient : array (6 nx ny nz,)
        Per element, in :func:`fem.mesh.box_mesh`'s order (six elements per voxel, voxels
        in C order of ``(nx, ny, nz)``).

    Returns
    -------
    array (nz,) or None
        The value of each element layer, or None if it is not constant over a layer.
    """
    c = np.asarray(coefficient, dtype=float)
    if c.shape != (6 * grid.nvoxels,):
        return None
    c4 = c.reshape(grid.nx, grid.ny, grid.nz, 6)
    layers = c4[0, 0, :, 0]
    if not np.array_equal(c4, np.broadcast_to(layers[None, None, :, None], c4.shape)):
        return None
    return layers.copy()


def layer_means(grid: BoxGrid, coefficient: np.ndarray) -> tuple[np.ndarray, float]:
    """Per-layer volume means ((nz,)) of a per-element coefficient of ``box_mesh(grid)``, and
    the largest max/min ratio within a layer.

    The media of a layer differ from its mean only where something crosses the layers (a
    vessel in the dermis): the layered operator of the means is then a close preconditioner
    of the full one (:class:`fem.HeatStepper`'s PCG path). The Kuhn split cuts a voxel into
    six tetrahedra of equal volume, so the volume mean of a layer is its elements' plain mean.

    Parameters
    ----------
    grid : BoxGrid
    coefficient : array (6 nx ny nz,)
        Per element, in :func:`fem.mesh.box_mesh`'s order.

    Returns
    -------
    (means, ratio) : array (nz,), float
        ``ratio`` is inf where a layer holds both zero and nonzero values.
    """
    c = np.asarray(coefficient, dtype=float)
    if c.shape != (6 * grid.nvoxels,):
        raise ValueError(f"coefficient must have shape ({6 * grid.nvoxels},), got {c.shape}")
    c4 = np.moveaxis(c.reshape(grid.nx, grid.ny, grid.nz, 6), 2, 0).reshape(grid.nz, -1)
    lo, hi = c4.min(axis=1), c4.max(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(hi == lo, 1.0, hi / lo)
    return c4.mean(axis=1), float(ratio.max())


def layered_one_d(h: float, w: np.ndarray, kind: str = "lumped"):
    """1-D P1 mass and stiffness on uniform intervals of width ``h`` with weights ``w``.

    Parameters
    ----------
    h : float
        cm, interval width.
    w : array (n,)
        The coefficient of each interval (VHC or TC of the layer).
    kind : {"lumped", "averaged", "consistent"}
        The interval mass, as :func:`fem.fastdiag.one_d_mass`.

    Returns
    -------
    (mass_diag, mass_off, stiff_diag, stiff_off) : arrays (n+1,), (n,), (n+1,), (n,)
        The diagonals and off-diagonals (``off[i]`` couples nodes i and i + 1) of
        :math:`\\sum_l w_l m_l` and :math:`\\sum_l w_l [1, -1; -1, 1]/h`.
    """
    if kind not in MASS_KINDS:
        raise ValueError(f"mass must be one of {MASS_KINDS}, got {kind!r}")
    w = np.asarray(w, dtype=float)
    n = w.size
    # per interval: lumped diag h/2 (off 0), consistent diag h/3 (off h/6)
    d_int, o_int = {"lumped": (h / 2, 0.0), "consistent": (h / 3, h / 6),
                    "averaged": (5 * h / 12, h / 12)}[kind]
    md = np.zeros(n + 1)
    md[:-1] += w * d_int
    md[1:] += w * d_int
    mo = w * o_int
    kd = np.zeros(n + 1)
    kd[:-1] += w / h
    kd[1:] += w / h
    ko = -w / h
    return md, mo, kd, ko


class LayeredKroneckerSolver:
    """Exact solves of the tensor-product step matrix for media layered in z.

    Parameters
    ----------
    grid : BoxGrid
        The grid whose :func:`fem.mesh.box_mesh` is the mesh.
    boundary : HeatBoundary
        x and y faces insulating or fixed; z faces any kind.
    vhc, tc : arrays (nz,)
        J cm^-3 K^-1 and W cm^-1 K^-1, per element layer (top first); TC >= 0.
    dt : float
        s, time step.
    theta : float
        Implicitness (1 backward Euler, 0.5 Crank-Nicolson).
    mass : {"lumped", "averaged", "consistent"}
        The 1-D mass matrices (:func:`layered_one_d`).

    Attributes
    ----------
    free_nodes : int array (nfree,)
        The mesh nodes the solve works on, in C order of the free node grid.
    shape_f : tuple
        The free node grid.

    Raises
    ------
    NotApplicable
        For a convective x or y face, or an axis without free nodes.
    """

    def __init__(self, grid: BoxGrid, boundary: HeatBoundary, vhc, tc, dt: float,
                 theta: float, mass: str = "lumped"):
        vhc, tc = np.asarray(vhc, dtype=float), np.asarray(tc, dtype=float)
        if vhc.shape != (grid.nz,) or tc.shape != (grid.nz,):
            raise ValueError(f"vhc and tc must have shape ({grid.nz},) (one value per layer), "
                             f"got {vhc.shape} and {tc.shape}")
        if not (np.all(vhc > 0) and np.all(tc >= 0)):
            raise ValueError("vhc must be > 0 and tc >= 0 in every layer")
        self.grid, self.dt, self.theta, self.mass = grid, float(dt), float(theta), mass
        free1 = []
        for a, n in enumerate(grid.shape):
            keep = np.ones(n + 1, dtype=bool)
            for side, node in (("-", 0), ("+", n)):
                bc = boundary["xyz"[a] + side]
                if bc.kind == "fixed":
                    keep[node] = False
                elif bc.kind == "convective" and a < 2:
                    raise NotApplicable("a convective x or y face does not separate from "
                                        "media layered in z")
            idx = np.flatnonzero(keep)
            if idx.size == 0:
                raise NotApplicable(f"no free nodes along axis {'xyz'[a]}")
            free1.append(idx)
        self.free1 = free1
        self.shape_f = tuple(len(i) for i in free1)
        I, J, Kk = np.meshgrid(*free1, indexing="ij")
        self.free_nodes = grid.node_index(I.ravel(), J.ravel(), Kk.ravel())
        # x, y: unit-coefficient pencils (K_a, M_a), shared by every member
        self.mu, self.Phi = [], []
        for a in range(2):
            n, h = grid.shape[a], grid.spacing[a]
            idx = free1[a]
            K = one_d_operators(n, h)[1][np.ix_(idx, idx)]
            mu, Phi = sla.eigh(K, one_d_mass(n, h, mass)[np.ix_(idx, idx)])
            self.mu.append(np.ascontiguousarray(mu))
            self.Phi.append(Phi)
        # z: tridiagonals weighted by the layers, restricted to the free z nodes
        hz = grid.dz
        cd, co, _, _ = layered_one_d(hz, vhc, mass)
        md, mo, kd, ko = layered_one_d(hz, tc, mass)
        H = np.zeros(grid.nz + 1)
        for side, node in (("-", 0), ("+", grid.nz)):
            bc = boundary["z" + side]
            if bc.kind == "convective":
                H[node] += bc.h
        iz = free1[2]
        lo, hi = iz[0], iz[-1]  # free z nodes are contiguous: off-diagonals lo .. hi-1
        self._z = tuple(np.ascontiguousarray(v) for v in (
            cd[iz], co[lo:hi], kd[iz], ko[lo:hi], md[iz], mo[lo:hi], self.theta * H[iz]))

    def solve(self, r: np.ndarray, vhc_scale: np.ndarray, tc_scale: np.ndarray,
              blocks: int = 2) -> np.ndarray:
        """Solve ``A_n x_n = r_n`` on the free nodes (the interface of
        :meth:`fem.fastdiag.KroneckerSolver.solve`).

        Parameters
        ----------
        r : array (N, nfree)
            W, right-hand sides in the order of ``self.free_nodes``.
        vhc_scale, tc_scale : arrays (N,)
            Per-member factors on VHC and TC.
        blocks : int, default 2
            Member blocks solved side by side (:func:`fem.threads.run_blocks`).

        Returns
        -------
        array (N, nfree)
        """
        r = np.asarray(r, dtype=float)
        N = r.shape[0]
        alpha = np.ascontiguousarray(np.asarray(vhc_scale, dtype=float) / self.dt)
        beta = np.ascontiguousarray(self.theta * np.asarray(tc_scale, dtype=float))
        Px, Py = self.Phi
        out = np.empty((N, r.shape[1]))

        a0, a1, a2 = self.shape_f

        def run(i0, i1):
            B = i1 - i0
            X = _contract(r[i0:i1].reshape(B, a0, a1, a2), Px, 0)  # (B, px, a1, a2)
            # y modes last (the kernel's layout): (a2, a1) @ (a1, py) per x mode, the
            # transpose read by BLAS in place
            Y = np.matmul(np.swapaxes(X.reshape(B * a0, a1, a2), 1, 2), Py)
            Y = Y.reshape(B, a0, a2, a1)
            _kernels.layered_modes_solve(Y, self.mu[0], self.mu[1], alpha[i0:i1],
                                         beta[i0:i1], *self._z)
            X = np.matmul(Py, np.swapaxes(Y.reshape(B * a0, a2, a1), 1, 2))  # (., a1, a2)
            X = _contract(X.reshape(B, a0, a1, a2), _transpose(Px), 0)
            out[i0:i1] = X.reshape(B, -1)

        with blas_threads(1):
            run_blocks(N, run, blocks)
        return out


def tensor_product_operators(grid: BoxGrid, boundary, mass: str, vhc: float, tc: float,
                             layers=None) -> dict:
    """The heat matrices of the tensor-product operator on ``box_mesh(grid)``.

    Parameters
    ----------
    grid : BoxGrid
    boundary : fem.HeatBoundary
        Convective faces add their face mass (times ``h``) to ``R`` and ``g``.
    mass : {"lumped", "averaged", "consistent"}
        The 1-D mass (:func:`fem.fastdiag.one_d_mass`).
    vhc, tc : float
        J cm^-3 K^-1 and W cm^-1 K^-1 of one medium (ignored with ``layers``).
    layers : (vhc (nz,), tc (nz,)) or None
        Per element layer: the z factors are then weighted layer by layer.

    Returns
    -------
    dict
        ``M``, ``K``, ``R`` (sparse, npoints x npoints), ``g`` (npoints,) W, ``m_lumped``
        (the diagonal mass, or None) and ``m_tridiag`` (``(c, node_shape, diagonals,
        off-diagonals)`` of the 1-D masses for the right-hand side's product, or None).
    """
    K1 = [one_d_operators(n, h)[1] for n, h in zip(grid.shape, grid.spacing, strict=True)]
    M1 = [one_d_mass(n, h, mass) for n, h in zip(grid.shape, grid.spacing, strict=True)]
    Ms = [sp.csr_array(m) for m in M1]
    if layers is None:
        c, k = float(vhc), float(tc)
        K = (sp.kron(sp.kron(sp.csr_array(K1[0]), Ms[1]), Ms[2])
             + sp.kron(sp.kron(Ms[0], sp.csr_array(K1[1])), Ms[2])
             + sp.kron(sp.kron(Ms[0], Ms[1]), sp.csr_array(K1[2])))
    else:  # z factors weighted layer by layer; c, k are then folded into them
        c = k = 1.0
        cd, co, _, _ = layered_one_d(grid.dz, layers[0], mass)
        md, mo, kd, ko = layered_one_d(grid.dz, layers[1], mass)
        Mzc = sp.csr_array(sp.diags_array([co, cd, co], offsets=[-1, 0, 1]))
        Mzk = sp.csr_array(sp.diags_array([mo, md, mo], offsets=[-1, 0, 1]))
        Kzk = sp.csr_array(sp.diags_array([ko, kd, ko], offsets=[-1, 0, 1]))
        K = (sp.kron(sp.kron(sp.csr_array(K1[0]), Ms[1]), Mzk)
             + sp.kron(sp.kron(Ms[0], sp.csr_array(K1[1])), Mzk)
             + sp.kron(sp.kron(Ms[0], Ms[1]), Kzk))
        M1c = [M1[0], M1[1], Mzc.toarray()]
    R = sp.csr_array((K.shape[0], K.shape[0]))
    g = np.zeros(K.shape[0])
    for face in FACES:
        bc = boundary[face]
        if bc.kind != "convective":
            continue
        a = "xyz".index(face[0])
        w = list(Ms)
        e = np.zeros(grid.shape[a] + 1)
        e[0 if face[1] == "-" else -1] = 1.0
        w[a] = sp.csr_array(np.diag(e))
        area = sp.kron(sp.kron(w[0], w[1]), w[2]).tocsr()  # face mass, cm^2
        R = R + bc.h * area
        g += bc.h * bc.temperature * np.asarray(area.sum(axis=1)).ravel()
    if layers is not None:  # the mass carries the layers' VHC
        M1, Ms = M1c, [Ms[0], Ms[1], Mzc]
    out = {"K": sp.csr_matrix(k * K), "g": g, "m_tridiag": None, "theta_tridiag": None}
    if mass == "lumped":
        out["m_lumped"] = c * np.einsum("i,j,k->ijk", *(np.diag(m) for m in M1)).ravel()
        out["M"] = sp.diags_array(out["m_lumped"], format="csr")
        out["R"] = sp.diags_array(R.diagonal(), format="csr")
    else:
        out["m_lumped"] = None
        out["M"] = sp.csr_matrix(c * sp.kron(sp.kron(Ms[0], Ms[1]), Ms[2]))
        out["R"] = sp.csr_matrix(R)
        out["m_tridiag"] = (c, grid.node_shape, [np.ascontiguousarray(np.diagonal(m))
                                                 for m in M1],
                            [np.ascontiguousarray(np.diagonal(m, 1)) for m in M1])
        # the theta step's whole right-hand side, axis by axis (fem._kernels.
        # tridiag3_theta_rhs): x and y factors unit, the VHC and TC in the z factors
        _, _, md, mo = out["m_tridiag"]
        zm, zk = (k * M1[2], k * K1[2]) if layers is None else (Mzk.toarray(), Kzk.toarray())

        def dia(m, off):
            return np.ascontiguousarray(np.diagonal(np.asarray(m, float), off))

        out["theta_tridiag"] = (
            (md[0], mo[0], md[1], mo[1], c * md[2], c * mo[2]),
            tuple(dia(m, o) for m in (K1[0], K1[1], zk) for o in (0, 1)),
            (dia(zm, 0), dia(zm, 1)))
    return out
