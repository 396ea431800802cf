"""VTU export of tetrahedral fields and ParaView time series (.pvd).

meshio is imported only when writing.  A time series is a ``.pvd`` collection
listing one ``.vtu`` file per step (written next to it in ``<name>_vtu/``);
ParaView and ``pyvista.read`` open it.
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

__all__ = ["TimeSeriesWriter", "write_vtu"]


def _check_data(data, n: int, what: str) -> dict:
    out = {}
    for name, v in (data or {}).items():
        a = np.asarray(v)
        if a.shape[0] != n:
            raise ValueError(f"{what} {name!r} must have {n} rows, got shape {a.shape}")
        out[str(name)] = a
    return out


def write_vtu(path, mesh, point_data: dict | None = None, cell_data: dict | None = None) -> Path:
    """Write a tetrahedral mesh and fields to a VTU file.

    Parameters
    ----------
    path : str or Path
        Output file (``.vtu``).
    mesh : skfem.MeshTet
    point_data : dict of name -> array (npoints,) or (npoints, k)
        Nodal fields, e.g. ``{"T": T}`` in deg C.
    cell_data : dict of name -> array (nelements,) or (nelements, k)
        Element fields, e.g. ``{"medium": media}``.

    Returns
    -------
    Path
    """
    import meshio

    n, ne = mesh.p.shape[1], mesh.t.shape[1]
    pd = _check_data(point_data, n, "point_data")
    cd = {k: [v] for k, v in _check_data(cell_data, ne, "cell_data").items()}
    m = meshio.Mesh(mesh.p.T, [("tetra", mesh.t.T.astype(np.int64))], point_data=pd,
                    cell_data=cd)
    path = Path(path)
    m.write(path, file_format="vtu")
    return path


class TimeSeriesWriter:
    """Write a field series as ``<name>.pvd`` + one VTU per step.

    Parameters
    ----------
    path : str or Path
        The ``.pvd`` file.
    mesh : skfem.MeshTet
    cell_data : dict, optional
        Element fields written with every step (e.g. media).

    Examples
    --------
    >>> with TimeSeriesWriter("run.pvd", mesh) as w:   # doctest: +SKIP
    ...     for k, T in enumerate(history):
    ...         w.write(k * dt, T=T)
    """

    def __init__(self, path, mesh, cell_data: dict | None = None):
        self.path = Path(path)
        if self.path.suffix != ".pvd":
            raise ValueError(f"path must end in .pvd, got {str(path)!r}")
        self.mesh = mesh
        self.cell_data = cell_data
        self.dir = self.path.with_name(self.path.stem + "_vtu")
        self.dir.mkdir(parents=True, exist_ok=True)
        self.entries: list[tuple[float, str]] = []

    def write(self, time: float, **point_data) -> Path:
        """Write one step at ``time`` (s) with nodal fields as keywords."""
        k = len(self.entries)
        f = self.dir / f"{self.path.stem}_{k:05d}.vtu"
        write_vtu(f, self.mesh, point_data=point_data, cell_data=self.cell_data)
        self.entries.append((float(time), os.path.relpath(f, self.path.parent)))
        self._write_pvd()
        return f

    def _write_pvd(self) -> None:
        lines = ['<?xml version="1.0"?>',
                 '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                 "  <Collection>"]
        for t, f in self.entries:
            lines.append(f'    <DataSet timestep="{t!r}" group="" part="0" file={quoteattr(f)}/>')
        lines += ["  </Collection>", "</VTKFile>", ""]
        self.path.write_text("\n".join(lines))

    def close(self) -> None:
        self._write_pvd()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
