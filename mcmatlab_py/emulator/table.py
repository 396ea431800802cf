"""The table points of an emulator: one direct Monte Carlo run per (mua, mus) point
(:func:`table_point`), stored as log(NA + offset) at the representatives of the block's
mirror symmetries, on the voxels or projected onto the heat mesh's nodes."""

from __future__ import annotations

import numpy as np

from ..monte_carlo.host import optical_arrays
from ..monte_carlo.run import simulate
from .spec import EmulatorSpec

__all__ = ["load_operator", "symmetrize", "table_point", "table_row", "table_rows"]

_OPERATORS: dict = {}


def load_operator(spec: EmulatorSpec):
    """The voxel -> P1 node operator of a nodal-load spec (built once per process)."""
    import fem
    from fem.threads import release_free_memory

    key = (spec.nx, spec.ny, spec.nz, spec.Lx, spec.Ly, spec.Lz, tuple(spec.mesh_divisions))
    if key not in _OPERATORS:
        grid = fem.BoxGrid(spec.nx, spec.ny, spec.nz, spec.Lx, spec.Ly, spec.Lz)
        mesh = fem.BoxGrid(*spec.mesh_divisions, spec.Lx, spec.Ly, spec.Lz).mesh()
        _OPERATORS.clear()  # one at a time: the matrices of fine grids are large
        _OPERATORS[key] = fem.voxel_load_matrix(mesh, grid)
        del mesh
        release_free_memory()  # its temporaries: ~270 MB kept otherwise
    return _OPERATORS[key]


def table_point(spec: EmulatorSpec, point: tuple[int, int]) -> tuple[np.ndarray, float]:
    """One table point ``(i_mua, i_mus)``: log(NA + offset) at the orbit representatives
    (n_unique,) and the absorbed fraction. Deterministic (seed ``spec.seed``): the same
    numbers wherever and on however many threads it runs."""
    a, b = point
    mua, mus = spec.mua_grid()[a], spec.mus_grid()[b]
    m = spec.model(mua, mus, n_photons=spec.photons_at(mus))
    M = m.G.medium_map()
    m.MC.validate(m.G)
    res = simulate(m.G, m.MC, M, *optical_arrays(m.G.media, m.MC.wavelength), seed=spec.seed,
                   n_photons=m.MC.n_photons_requested)
    dV = m.G.dx * m.G.dy * m.G.dz
    return table_row(spec, res.absorbed / (res.n_photons * dV)), float(res.absorbed.sum()
                                                                     / res.n_photons)


def table_row(spec: EmulatorSpec, na: np.ndarray) -> np.ndarray:
    """The stored form of one table point's NA (nx, ny, nz) in W/cm^3/W: projected onto
    the mesh nodes when ``spec.mesh_divisions`` is set, symmetrised, log(. + offset) at
    the orbit representatives (n_unique,)."""
    return table_rows(spec, na[None])[0]


def table_rows(spec: EmulatorSpec, na: np.ndarray, symmetric: bool = False) -> np.ndarray:
    """:func:`table_row` of a stack of maps (K, nx, ny, nz) -> (K, n_unique), with one sparse
    product for the projection; ``symmetric``: the maps are already symmetrised on the
    voxels (as the white run's orbit tallies are)."""
    if spec.mesh_divisions is not None:
        if not symmetric:
            na = np.stack([symmetrize(m, spec, voxels=True) for m in na])
        flat = na.reshape(na.shape[0], -1)
        na = (load_operator(spec) @ flat.T).T.reshape((-1, *spec.field_shape))  # W/node/W
    reps, _ = spec.orbits()
    return np.stack([np.log(symmetrize(m, spec).ravel()[reps] + spec.offset) for m in na])


def symmetrize(na: np.ndarray, spec: EmulatorSpec, voxels: bool = False) -> np.ndarray:
    """Average a field over the mirror symmetries of the block and beam.

    A beam centred on the block is symmetric under x -> -x and y -> -y, and a square
    block under x <-> y as well: averaging over these images is an exact variance
    reduction (up to 8 times fewer photons for the same noise). The field is on the
    spec's voxels, or (``voxels=False`` with ``mesh_divisions``) on its mesh nodes, where
    the average also evens out the O(h^2) asymmetry of the Kuhn triangulation's quadrature
    (not with several media: :meth:`EmulatorSpec.symmetric_axes`).
    """
    sx, sy, swap = spec.symmetric_axes(voxels and spec.media is not None)
    if voxels:
        swap = swap and spec.nx == spec.ny
    if sx:
        na = 0.5 * (na + na[::-1])
    if sy:
        na = 0.5 * (na + na[:, ::-1])
    if swap:
        na = 0.5 * (na + na.transpose(1, 0, 2))
    return na
