"""pyvista's interactive 3-D slicer of a model's main field (optional: needs pyvista)."""

from __future__ import annotations

import numpy as np

from ..monte_carlo.broadband import total

__all__ = ["interactive_slicer", "voxel_image"]


def voxel_image(G, **fields):
    """A ``pyvista.ImageData`` of the voxels with ``fields`` (each (nx, ny, nz)) as cell data."""
    import pyvista as pv

    img = pv.ImageData(dimensions=(G.nx + 1, G.ny + 1, G.nz + 1),
                       spacing=(G.dx, G.dy, G.dz), origin=(-G.Lx / 2, -G.Ly / 2, 0.0))
    for name, values in fields.items():
        img.cell_data[name] = np.asarray(values).ravel(order="F")
    return img


def interactive_slicer(model, what: str, show: bool = True):
    """Open three draggable orthogonal slices of ``what``'s field (G: media, MC and FMC: log10
    NFR, HS: temperature); returns the plotter (not shown when ``show`` is False)."""
    try:
        import pyvista as pv
    except ImportError as err:  # pragma: no cover - depends on the installation
        raise ImportError("the interactive slicer needs pyvista: pip install "
                          "'tissue-enkf[viz]'") from err
    G = model.G
    if what == "G":
        name, data = "medium", G.medium_map()
    elif what in ("MC", "FMC"):
        nfr = total(getattr(model, what).NFR)  # broadband: summed over the wavelengths
        name, data = "log10 NFR", np.log10(np.where(nfr > 0, nfr, np.nan))
    else:
        name, data = "T [deg C]", model.HS.T_voxels
    plotter = pv.Plotter(off_screen=not show)
    plotter.add_mesh_slice_orthogonal(voxel_image(G, **{name: data}), scalars=name,
                                      cmap="inferno" if what != "G" else "tab10")
    plotter.camera_position = "xz"
    plotter.camera.up = (0, 0, -1)  # z points into the tissue, drawn downwards
    if show:
        plotter.show()
    return plotter
