"""Finite-element heat diffusion on tetrahedral scikit-fem meshes.

This package knows nothing of photons or filters: it takes a voxel-wise
power density (W/cm^3), volumetric heat capacities (J cm^-3 K^-1) and thermal
conductivities (W cm^-1 K^-1) and returns temperatures (deg C).  See
``docs/fem.md`` for the design, verification and measured speed.

Glossary
--------
p, t
    Mesh points (3, npoints), cm, and elements (4, nelements), as scikit-fem.
grid
    :class:`BoxGrid`, a voxel grid (nx, ny, nz) over x in [-Lx/2, Lx/2],
    y in [-Ly/2, Ly/2], z in [0, Lz] (z into the tissue, z = 0 the top).
Kuhn mesh
    :func:`box_mesh`: nodes at voxel corners, 6 orthoscheme tetrahedra per voxel.
S, L, f
    Power density per voxel (W/cm^3); the voxel->node operator
    ``L = voxel_load_matrix(mesh, grid)`` (cm^3); nodal loads ``f = L @ S.ravel()`` (W).
vhc, tc
    Volumetric heat capacity c (J cm^-3 K^-1) and thermal conductivity k
    (W cm^-1 K^-1), per element.
layers
    Media that vary only with depth: vhc, tc constant over each element layer of a
    box mesh (:func:`layer_coefficients`), solved directly by
    :class:`LayeredKroneckerSolver` with the tensor-product operator.
M, K, R, g
    Mass (J/K, lumped by default), stiffness (W/K), convective boundary
    matrix (W/K) and convective load (W).
theta
    Time-stepping implicitness: 1 backward Euler, 0.5 Crank-Nicolson.
N, ensemble
    Member count; ensembles of temperatures are (N, npoints) (DAPPER layout);
    ``vhc_scale``, ``tc_scale`` (N,) are per-member factors on c and k.
omega
    Arrhenius damage integral; damaged fraction ``1 - exp(-omega)``; one step by
    the midpoint (MCmatlab's) or the trapezoid rule (:func:`advance_damage`).
P (probes)
    ``probe_matrix(mesh, points)`` (nprobes, npoints): ``T_probe = P @ T``.
march
    :func:`march`, the one time loop: ``step(T, t0, t1)`` over the times, the
    probes read after every step.
"""

from .assembly import (
    element_coefficient,
    lumped_mass,
    mass_matrix,
    robin_load,
    robin_matrix,
    stiffness_matrix,
)
from .bc import FACES, FaceBC, HeatBoundary, face_facets, face_nodes
from .damage import (
    GAS_CONSTANT,
    KELVIN,
    DamageIntegral,
    advance_damage,
    arrhenius_increment,
    element_to_node,
    fractional_damage,
    update_damage,
)
from .fastdiag import KroneckerSolver, NotApplicable
from .layered import LayeredKroneckerSolver, layer_coefficients
from .locate import locate
from .march import march
from .mesh import (
    BoxGrid,
    box_mesh,
    check_mesh,
    element_volumes,
    element_voxel_index,
    structured_grid,
)
from .probes import GroupMaxima, probe_matrix
from .source import corner_load_matrix, load_vector, voxel_load_matrix
from .stepper import HeatStepper


def __getattr__(name):  # I/O at the edge: meshio is imported only when used
    if name in ("write_vtu", "TimeSeriesWriter"):
        from . import export

        return getattr(export, name)
    raise AttributeError(f"module 'fem' has no attribute {name!r}")


__all__ = [
    "FACES",
    "GAS_CONSTANT",
    "KELVIN",
    "BoxGrid",
    "DamageIntegral",
    "FaceBC",
    "GroupMaxima",
    "HeatBoundary",
    "HeatStepper",
    "KroneckerSolver",
    "LayeredKroneckerSolver",
    "NotApplicable",
    "TimeSeriesWriter",
    "advance_damage",
    "arrhenius_increment",
    "box_mesh",
    "check_mesh",
    "corner_load_matrix",
    "element_coefficient",
    "element_to_node",
    "element_volumes",
    "element_voxel_index",
    "face_facets",
    "face_nodes",
    "fractional_damage",
    "layer_coefficients",
    "load_vector",
    "locate",
    "lumped_mass",
    "march",
    "mass_matrix",
    "probe_matrix",
    "robin_load",
    "robin_matrix",
    "stiffness_matrix",
    "structured_grid",
    "update_damage",
    "voxel_load_matrix",
    "write_vtu",
]
