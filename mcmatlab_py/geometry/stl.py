"""Geometry from a closed triangle mesh (an STL file), as MCmatlab's ``findInsideVoxels``.

MCmatlab's example 18 calls ``findInsideVoxels(X, Y, Z, 'sample.stl', A, v)`` inside
its geometry function: the mesh points are mapped by ``A p + v`` (scale to cm,
rotate, mirror, translate) and the voxels whose centres lie inside the mesh are
marked. Here the voxelisation is VTK's ``vtkPolyDataToImageStencil`` through
pyvista (the ``viz`` extra)::

    def geom_func(X, Y, Z, params):
        M = np.zeros(X.shape, dtype=int)                      # air
        M[find_inside_voxels(X, Y, Z, "sample.stl", A=0.1 * np.eye(3), v=(0, 0, 1.5))] = 1
        return M
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..files import open_regular

__all__ = ["find_inside_voxels"]


def _axis(name: str, C: np.ndarray, axis: int) -> np.ndarray:
    """The 1-D coordinates of a meshgrid (``indexing="ij"``) array along ``axis``, checked."""
    index = [0, 0, 0]
    index[axis] = slice(None)
    c = np.asarray(C[tuple(index)], dtype=np.float64)
    shape = [1, 1, 1]
    shape[axis] = -1
    if not np.array_equal(np.broadcast_to(c.reshape(shape), C.shape), C):
        raise ValueError(f"{name} must be a meshgrid of voxel centres (indexing='ij') as passed "
                         "to G.geom_func")
    if c.size > 1:
        step = np.diff(c)
        if not (np.all(step > 0) and np.allclose(step, step[0], rtol=1e-9, atol=0)):
            raise ValueError(f"{name} must hold equally spaced, increasing voxel centres")
    return c


def find_inside_voxels(X: np.ndarray, Y: np.ndarray, Z: np.ndarray, mesh,
                       A: np.ndarray | None = None, v=None) -> np.ndarray:
    """Which voxel centres lie inside a closed surface mesh.

    Parameters
    ----------
    X, Y, Z : (nx, ny, nz) arrays
        Voxel-centre coordinates, cm, as passed to ``G.geom_func``.
    mesh : str, Path or pyvista.PolyData
        An STL file (or any surface file pyvista reads), or a mesh; it must be closed
        (watertight).
    A : (3, 3) array, optional
        Matrix applied to the mesh points (units to cm, rotation, mirroring); identity
        if not given.
    v : (3,) array, optional
        Translation, cm, applied after ``A``: points become ``A p + v``.

    Returns
    -------
    (nx, ny, nz) bool array
        True where the voxel centre is inside the transformed mesh.
    """
    try:
        import pyvista as pv
    except ImportError as err:  # pragma: no cover - pyvista is in the viz extra
        raise ImportError("find_inside_voxels needs pyvista: pip install 'tissue-enkf[viz]'") \
            from err
    X, Y, Z = (np.asarray(C) for C in (X, Y, Z))
    if not (X.ndim == 3 and X.shape == Y.shape == Z.shape):
        raise ValueError(f"X, Y, Z must be (nx, ny, nz) arrays of one shape, got "
                         f"{X.shape}, {Y.shape}, {Z.shape}")
    axes = [_axis(n, C, i) for i, (n, C) in enumerate(zip("XYZ", (X, Y, Z), strict=True))]
    A = np.eye(3) if A is None else np.asarray(A, dtype=np.float64)
    if A.shape != (3, 3) or not np.all(np.isfinite(A)):
        raise ValueError(f"A must be a finite 3 x 3 matrix, got {A!r}")
    v = np.zeros(3) if v is None else np.asarray(v, dtype=np.float64).ravel()
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"v must be a finite translation (x, y, z), got {v!r}")

    if isinstance(mesh, (str, Path)):
        path = Path(mesh)
        with open_regular(path, "mesh file"):  # a pipe, FIFO or device: refused, not read
            pass
        surface = pv.read(path)
    elif isinstance(mesh, pv.DataSet):
        surface = mesh
    else:
        raise ValueError(f"mesh must be a file name or a pyvista mesh, got {mesh!r}")
    if not isinstance(surface, pv.PolyData):
        surface = surface.extract_surface()
    surface = surface.triangulate().clean()
    if surface.n_cells == 0:
        raise ValueError(f"mesh {mesh!r} has no faces")
    if surface.n_open_edges:
        raise ValueError(f"mesh {mesh!r} is not closed ({surface.n_open_edges} open edges): "
                         "inside and outside are undefined")
    surface = surface.copy()
    surface.points = np.asarray(surface.points, dtype=np.float64) @ A.T + v

    spacing = [c[1] - c[0] if c.size > 1 else 1.0 for c in axes]
    ref = pv.ImageData(dimensions=X.shape, spacing=spacing, origin=[c[0] for c in axes])
    mask = surface.voxelize_binary_mask(reference_volume=ref)
    # VTK orders image points with x fastest
    return np.asarray(mask.point_data["mask"]).reshape(X.shape, order="F").astype(bool)
