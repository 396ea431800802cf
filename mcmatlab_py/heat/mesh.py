"""The mesh of a heat run: the tetrahedra over the voxel cuboid, the voxel <-> node
operators, the media per element and the damage parameters per node."""

from __future__ import annotations

import numpy as np

__all__ = ["Setup", "damage_parameters", "voxels_to_nodes"]


def voxels_to_nodes(L, values) -> np.ndarray:
    """(npoints,) node values from a voxel field (a number or (nx, ny, nz)).

    The weighted mean of the voxels under each node's hat function, ``(L v) / (L 1)``
    with ``L = fem.voxel_load_matrix``: with uniform heat capacity it keeps the heat
    content of the voxel field, and a constant stays exactly constant.
    """
    v = np.asarray(values, dtype=float)
    if v.ndim == 0:
        return np.full(L.shape[0], float(v))
    return (L @ v.ravel()) / (L @ np.ones(L.shape[1]))


class Setup:
    """Mesh, operators and per-element media of one run."""

    def __init__(self, G, HS, M):
        import fem

        self.grid = fem.BoxGrid(G.nx, G.ny, G.nz, G.Lx, G.Ly, G.Lz)
        if HS.mesh_divisions is None:
            self.mesh_grid = self.grid
        else:
            self.mesh_grid = fem.BoxGrid(*HS.mesh_divisions, G.Lx, G.Ly, G.Lz)
        self.mesh = self.mesh_grid.mesh()
        self.L = fem.voxel_load_matrix(self.mesh, self.grid)  # (npoints, nvox) cm^3
        # media per element: the voxel that holds the element's centroid
        # six elements per voxel: the narrowest integers that hold the indices (48 of the
        # ~900 bytes per node of a large heat run, measured with bench_heat_memory.py)
        ev = fem.element_voxel_index(self.mesh, self.grid)
        self.elem_voxel = ev.astype(np.int32) if self.grid.nvoxels < 2**31 else ev
        del ev
        medium_type = np.int16 if int(M.max(initial=0)) < 2**15 else np.int64
        self.elem_medium = M.ravel().astype(medium_type)[self.elem_voxel]
        self._to_voxels = None
        self.medium_nodes = [np.unique(self.mesh.t[:, self.elem_medium == i])
                             for i in range(len(G.media))]

    def to_voxels(self, nodal) -> np.ndarray:
        """(nx, ny, nz): a nodal field evaluated at the voxel centres (P1 interpolation)."""
        import fem

        if self._to_voxels is None:
            X, Y, Z = np.meshgrid(self.grid.x, self.grid.y, self.grid.z, indexing="ij")
            self._to_voxels = fem.probe_matrix(self.mesh, np.vstack([X.ravel(), Y.ravel(),
                                                                     Z.ravel()]))
        return (self._to_voxels @ nodal).reshape(self.grid.shape)


def damage_parameters(mesh, elem_medium, media):
    """Per-node Arrhenius E (J/mol) and A (1/s), from the media of the elements around it.

    A node between media takes the most damageable of them (the largest ``A``, then ``E``),
    as ``fem.element_to_node(..., how="max")``, so that a node touching damageable tissue
    can be damaged; E and A come from that one medium, never a mix of two.
    """
    import fem

    if all(m.E is None or m.A is None for m in media):
        return None, None
    E = np.array([m.E if m.E is not None else 0.0 for m in media])
    A = np.array([m.A if m.A is not None else 0.0 for m in media])
    order = np.lexsort((E, A))  # media from the least to the most damageable
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    node_medium = order[fem.element_to_node(mesh, rank[elem_medium], "max").astype(int)]
    return E[node_medium], A[node_medium]
