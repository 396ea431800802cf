"""The mesh of a heat run: the tetrahedra over the voxel cuboid, the voxel <-> node
operators, the media per element and the damage parameters per node."""

from __future__ import annotations

import numpy as np

__all__ = ["Setup", "damage_parameters", "heat_mesh_divisions", "voxels_to_nodes"]

#: the most nodes of the finer heat mesh chosen for optics that follow T or FD
#: (about 1.4 GB at the ~657 bytes per node of a heat run)
FINE_MESH_MAX_NODES = 2**21


def _optics_follow_heat(media) -> bool:
    """True if an optical property of a medium changes with T or FD (not only with FR)."""
    for m in media:
        for f in ("mua", "mus", "g"):
            if not m.depends_on_state(f):
                continue
            fn = getattr(m, f)
            try:
                wl = 600.0
                probes = [float(np.asarray(fn(wl, 0.0, T, FD)).ravel()[0])
                          for T, FD in ((20.0, 0.0), (90.0, 0.0), (20.0, 1.0))]
            except Exception:  # noqa: BLE001 - a function we cannot probe: assume it does
                return True
            if len(set(probes)) > 1:
                return True
    return False


def heat_mesh_divisions(G, HS, *, warn: bool = True) -> tuple | None:
    """The heat mesh's divisions: ``HS.mesh_divisions``, else the voxels (None), or twice
    the voxels where optics follow the temperature or the damage.

    Such optics are re-evaluated from the temperature at the voxel centres. With nodes on
    the voxel corners only, the P1 field next to a strongly absorbing voxel over-reads
    its neighbour's centre (MCmatlab's Example 15 on 24^3 voxels: the egg white beside the
    absorber 22.8 deg C above its start, the exact sine-series solution 13.5; the damaged
    volume 18 times too large), and the error is carried into every later Monte Carlo
    re-run. A mesh twice as fine puts nodes on the voxel centres (14.0 deg C there;
    ``validation/reports/mcmatlab_agreement.md``, ex14 and ex15). It is chosen when it
    has at most :data:`FINE_MESH_MAX_NODES` nodes; above, a warning names the setting.
    """
    if HS.mesh_divisions is not None:
        return tuple(HS.mesh_divisions)
    if not _optics_follow_heat(G.media):
        return None
    fine = (2 * G.nx, 2 * G.ny, 2 * G.nz)
    nodes = (fine[0] + 1) * (fine[1] + 1) * (fine[2] + 1)
    if nodes <= FINE_MESH_MAX_NODES or not warn:
        return fine if nodes <= FINE_MESH_MAX_NODES else None
    import warnings

    warnings.warn(
        f"the optics follow the temperature or the damage, read at the voxel centres: a heat "
        f"mesh on the voxel corners ({G.nx} x {G.ny} x {G.nz} divisions) over-reads them "
        f"next to a strong absorber, and twice as fine ({nodes:,} nodes) is more than "
        f"{FINE_MESH_MAX_NODES:,}; set HS.mesh_divisions (e.g. {fine}) to choose",
        stacklevel=4)
    return None


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


def _media_nodes(t: np.ndarray, elem_medium: np.ndarray, n_media: int,
                 npoints: int) -> list[np.ndarray]:
    """The sorted nodes of each medium's elements (``t`` (4, n), ``elem_medium`` (n,)), all
    media in one pass over the elements."""
    seen = np.zeros((n_media, npoints), dtype=bool)
    for a in range(t.shape[0]):
        seen[elem_medium, t[a]] = True
    return [np.flatnonzero(seen[i]).astype(t.dtype, copy=False) for i in range(n_media)]


class Setup:
    """Mesh, operators and per-element media of one run."""

    def __init__(self, G, HS, M):
        import fem

        self.grid = fem.BoxGrid(G.nx, G.ny, G.nz, G.Lx, G.Ly, G.Lz)
        divisions = heat_mesh_divisions(G, HS)
        if divisions is None:
            self.mesh_grid = self.grid
        else:
            self.mesh_grid = fem.BoxGrid(*divisions, G.Lx, G.Ly, G.Lz)
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
        self.medium_nodes = _media_nodes(self.mesh.t, self.elem_medium, len(G.media),
                                         self.mesh.p.shape[1])

    def to_voxels(self, nodal) -> np.ndarray:
        """(nx, ny, nz): a nodal field evaluated at the voxel centres (P1 interpolation)."""
        import fem

        if self._to_voxels is None:
            X, Y, Z = np.meshgrid(self.grid.x, self.grid.y, self.grid.z, indexing="ij")
            P = fem.probe_matrix(self.mesh, np.vstack([X.ravel(), Y.ravel(), Z.ravel()]))
            # a voxel's centre lies on an edge of its elements: two of the four weights
            # are 0 (dropped, the same sums at half the cost; the damage reads it every step)
            P.eliminate_zeros()
            self._to_voxels = P
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
