"""MCmatlab's ``NdimSliderPlot``: slices through a 3-D field with sliders (matplotlib widgets).

:func:`slice_viewer` draws the xy, xz and yz slices of an (nx, ny, nz[, n4[, n5]]) array,
one slider per axis: x, y, z and, where present, the wavelength (a broadband run's last
axis) and the time. z points into the tissue and is drawn downwards, the laser's face
(z = 0) on top, as in MCmatlab's figures. It works with any matplotlib backend; under
Agg the sliders' callbacks still move the slices (``viewer.sliders["z"].set_val(k)``).

:func:`laser_face_on_top` turns a pyvista view the same way, and :func:`view_vtu` opens
one of our VTU exports (:mod:`mcmatlab_py.export`, :mod:`fem`) so.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["SliceViewer", "laser_face_on_top", "slice_viewer", "view_vtu"]


@dataclass
class SliceViewer:
    """The figure, its sliders (by axis name) and the current index along every axis."""

    fig: object
    sliders: dict = field(default_factory=dict)
    index: dict = field(default_factory=dict)
    images: dict = field(default_factory=dict)  #: "xy", "xz", "yz" -> AxesImage
    data: np.ndarray | None = None

    def slice(self, plane: str) -> np.ndarray:
        """The 2-D array now shown in ``plane`` ("xy", "xz" or "yz"), in (rows, columns)."""
        return np.asarray(self.images[plane].get_array())


def _axis_values(n: int, values, name: str) -> np.ndarray:
    if values is None:
        return np.arange(n, dtype=float)
    v = np.asarray(values, dtype=float)
    if v.shape != (n,):
        raise ValueError(f"slice_viewer: {name} must have {n} values (the data's axis), got "
                         f"shape {v.shape}")
    return v


def slice_viewer(data, G=None, *, wavelength=None, time=None, names=None, log: bool = False,
                 cmap: str = "inferno", label: str = "", title: str = "") -> SliceViewer:
    """Slices of ``data`` through sliders, MCmatlab's ``NdimSliderPlot``.

    Parameters
    ----------
    data : array, (nx, ny, nz), (nx, ny, nz, n4) or (nx, ny, nz, n4, n5)
        A voxel field (``model.MC.NFR``, ``model.HS.T_voxels``, a broadband ``NA``).
    G : Geometry, optional
        Gives the voxel centres (cm) of the slices; without it, voxel indices.
    wavelength, time : 1-D arrays, optional
        The values along the 4th (and 5th) axis: nm and s. A 4-D array without either is
        taken as wavelengths.
    names : sequence of str, optional
        The extra axes' slider labels (default "wavelength [nm]", "time [s]").
    log : bool
        Show log10 of the positive values (MCmatlab's log10 checkbox).
    """
    import matplotlib.pyplot as plt
    from matplotlib.widgets import Slider

    arr = np.asarray(data, dtype=float)
    if arr.ndim not in (3, 4, 5):
        raise ValueError(f"slice_viewer: data must be (nx, ny, nz) with up to two more axes, got "
                         f"shape {arr.shape}")
    if log:
        arr = np.log10(np.where(arr > 0, arr, np.nan))
    nx, ny, nz = arr.shape[:3]
    coords = {"x": _axis_values(nx, None if G is None else G.x, "G.x"),
              "y": _axis_values(ny, None if G is None else G.y, "G.y"),
              "z": _axis_values(nz, None if G is None else G.z, "G.z")}
    extra = []
    if arr.ndim >= 4:
        first = "time [s]" if wavelength is None and time is not None and arr.ndim == 4 else \
            "wavelength [nm]"
        vals = time if first.startswith("time") else wavelength
        extra.append((first, _axis_values(arr.shape[3], vals, first.split()[0])))
    if arr.ndim == 5:
        extra.append(("time [s]", _axis_values(arr.shape[4], time, "time")))
    if names is not None:
        extra = [(n, v) for n, (_, v) in zip(names, extra, strict=True)]
    unit = "cm" if G is not None else "index"
    fig = plt.figure(figsize=(11, 4.2 + 0.35 * (3 + len(extra))))
    n_sliders = 3 + len(extra)
    bottom = 0.06 + 0.05 * n_sliders
    axes = {p: fig.add_axes((0.05 + 0.32 * k, bottom + 0.05, 0.26, 0.88 - bottom))
            for k, p in enumerate(("xy", "xz", "yz"))}
    viewer = SliceViewer(fig=fig, data=arr)
    viewer.index = {"x": nx // 2, "y": ny // 2, "z": 0, **{n: 0 for n, _ in extra}}
    finite = arr[np.isfinite(arr)]
    vmin, vmax = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)

    def edges(c):
        d = c[1] - c[0] if c.size > 1 else 1.0
        return c[0] - d / 2, c[-1] + d / 2

    ex, ey, ez = edges(coords["x"]), edges(coords["y"]), edges(coords["z"])
    # imshow's rows run downwards: z (into the tissue) grows down the xz and yz panels
    spec = {"xy": ((ex[0], ex[1], ey[1], ey[0]), "x", "y"),
            "xz": ((ex[0], ex[1], ez[1], ez[0]), "x", "z"),
            "yz": ((ey[0], ey[1], ez[1], ez[0]), "y", "z")}
    for plane, (extent, h, v) in spec.items():
        ax = axes[plane]
        viewer.images[plane] = ax.imshow(_plane(arr, plane, viewer.index, extra), extent=extent,
                                         origin="upper", aspect="auto", cmap=cmap, vmin=vmin,
                                         vmax=vmax, interpolation="nearest")
        ax.set(xlabel=f"{h} [{unit}]", ylabel=f"{v} [{unit}]")
    fig.colorbar(viewer.images["yz"], ax=axes["yz"], label=("log10 " if log else "") + label)
    if title:
        fig.suptitle(title)

    def redraw(_=None):
        for plane in ("xy", "xz", "yz"):
            viewer.images[plane].set_data(_plane(arr, plane, viewer.index, extra))
        axes["xy"].set_title(f"z = {coords['z'][viewer.index['z']]:.4g} {unit}")
        axes["xz"].set_title(f"y = {coords['y'][viewer.index['y']]:.4g} {unit}")
        axes["yz"].set_title(f"x = {coords['x'][viewer.index['x']]:.4g} {unit}")
        fig.canvas.draw_idle()

    sliders = [("x", nx, coords["x"]), ("y", ny, coords["y"]), ("z", nz, coords["z"])]
    sliders += [(n, v.size, v) for n, v in extra]
    for k, (name, n, values) in enumerate(sliders):
        ax = fig.add_axes((0.12, 0.03 + 0.05 * (n_sliders - 1 - k), 0.7, 0.03))
        s = Slider(ax, name, 0, n - 1, valinit=viewer.index[name], valstep=1)

        def moved(val, name=name, values=values, s=s):
            viewer.index[name] = int(round(val))
            s.valtext.set_text(f"{values[viewer.index[name]]:.4g}")
            redraw()

        s.on_changed(moved)
        s.valtext.set_text(f"{values[viewer.index[name]]:.4g}")
        viewer.sliders[name] = s
    redraw()
    return viewer


def _plane(arr, plane: str, index: dict, extra) -> np.ndarray:
    sub = arr
    for name, _ in reversed(extra):  # the last axis first: the others keep their places
        sub = np.take(sub, index[name], axis=sub.ndim - 1)
    if plane == "xy":
        return sub[:, :, index["z"]].T  # rows y, columns x
    if plane == "xz":
        return sub[:, index["y"], :].T  # rows z (down), columns x
    return sub[index["x"], :, :].T  # rows z, columns y


def laser_face_on_top(plotter):
    """Turn a pyvista view so that z points down the screen: the irradiated face (z = 0) on
    top, looking along +y at the xz plane, as MCmatlab draws the cuboid. Returns it."""
    plotter.view_xz()
    plotter.camera.up = (0.0, 0.0, -1.0)
    plotter.reset_camera()
    return plotter


def view_vtu(path, scalars: str | None = None, *, show: bool = True, cmap: str = "inferno"):
    """Open a VTU export (voxels or the heat mesh) in pyvista, the laser's face on top.

    Returns the plotter (``show=False``: not shown, for screenshots and tests).
    """
    try:
        import pyvista as pv
    except ImportError as err:  # pragma: no cover - depends on the installation
        raise ImportError("view_vtu needs pyvista: pip install 'tissue-enkf[viz]'") from err
    mesh = pv.read(str(path))
    plotter = pv.Plotter(off_screen=not show)
    plotter.add_mesh(mesh, scalars=scalars, cmap=cmap, show_edges=False)
    plotter.add_axes()
    laser_face_on_top(plotter)
    if show:
        plotter.show()
    return plotter
