"""Voxel outputs for ParaView and pyvista: a VTU of hexahedral voxels (an edge module)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["voxel_hexahedra", "write_voxel_vtu"]


def voxel_hexahedra(G) -> tuple[np.ndarray, np.ndarray]:
    """Points ((nx+1)(ny+1)(nz+1), 3) and VTK-ordered hexahedra (nx*ny*nz, 8) of the grid.

    Cells are in C order of (nx, ny, nz), so ``field.ravel()`` gives the cell data.
    """
    xs = np.linspace(-G.Lx / 2, G.Lx / 2, G.nx + 1)
    ys = np.linspace(-G.Ly / 2, G.Ly / 2, G.ny + 1)
    zs = np.linspace(0.0, G.Lz, G.nz + 1)
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    points = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    ny1, nz1 = G.ny + 1, G.nz + 1
    i, j, k = np.meshgrid(np.arange(G.nx), np.arange(G.ny), np.arange(G.nz), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()

    def node(a, b, c):
        return (a * ny1 + b) * nz1 + c

    cells = np.column_stack([
        node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
        node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1), node(i, j + 1, k + 1),
    ])
    return points, cells


def write_voxel_vtu(path: str | Path, G, fields: dict[str, np.ndarray]) -> None:
    """Write (nx, ny, nz) voxel fields as cell data of a hexahedral VTU."""
    import meshio

    points, cells = voxel_hexahedra(G)
    cell_data = {}
    for name, arr in fields.items():
        arr = np.asarray(arr)
        if arr.shape != (G.nx, G.ny, G.nz):
            raise ValueError(f"field {name!r} has shape {arr.shape}, expected {(G.nx, G.ny, G.nz)}")
        cell_data[name] = [np.ascontiguousarray(arr, dtype=np.float64).ravel()]
    meshio.write(str(path), meshio.Mesh(points, [("hexahedron", cells)], cell_data=cell_data),
                 binary=True)
