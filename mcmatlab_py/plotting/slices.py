"""Three orthogonal slices of a voxel field, the 2-D stand-in for MCmatlab's NdimSliderPlot.

MCmatlab draws a 3-D field as three slices in a 3-D box with sliders; a saved figure
shows the same three planes side by side: xy at depth z, xz at y, yz at x, placed by
relative ``positions`` (0..1 along each axis, MCmatlab's ``slicePositions``), with z
pointing down as in MCmatlab (``reversedAxes = 3``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["new_figure", "MIDDLE", "orthogonal_slices", "slice_indices", "slices_through_maximum",
           "update_slices"]

#: relative slice positions through the middle of the cuboid
MIDDLE = (0.5, 0.5, 0.5)


def slice_indices(shape, positions) -> tuple[int, int, int]:
    """Voxel indices of the slices at relative ``positions`` (0: first voxel, 1: last)."""
    return tuple(int(round(float(p) * (n - 1))) for p, n in zip(positions, shape, strict=True))


def slices_through_maximum(data: np.ndarray, axes=(0, 1, 2),
                           fallback=MIDDLE) -> tuple[float, float, float]:
    """Relative slice positions through the voxel of the largest positive value of ``data``
    (nx, ny, nz) along ``axes``; along the other axes, and along all of them when no value
    is positive, at ``fallback``.

    The inverse of :func:`slice_indices`: voxel ``i`` of ``n`` is at ``i / (n - 1)``.
    """
    a = np.asarray(data, float)
    if not np.any(a > 0):
        return tuple(float(p) for p in fallback)
    ijk = np.unravel_index(np.argmax(np.where(a > 0, a, -np.inf)), a.shape)
    return tuple(ijk[k] / max(a.shape[k] - 1, 1) if k in axes else float(fallback[k])
                 for k in range(3))


def _at(v, length) -> str:
    """A slice's coordinate for a title: a centre that rounding put 1e-17 off zero is 0."""
    return f"{0.0 if abs(v) < 1e-9 * length else v:.3g}"


def _panels(data: np.ndarray, G, positions) -> list[tuple[np.ndarray, str]]:
    """The (image, title) of the xy, xz and yz panels; ``data`` (nx, ny, nz)."""
    ix, iy, iz = slice_indices(data.shape, positions)
    return [(data[:, :, iz].T, f"xy at z = {_at(G.z[iz], G.Lz)} cm"),
            (data[:, iy, :].T, f"xz at y = {_at(G.y[iy], G.Ly)} cm"),
            (data[ix, :, :].T, f"yz at x = {_at(G.x[ix], G.Lx)} cm")]


def _cuts(shape, G, positions) -> list[tuple[float, float]]:
    """(horizontal, vertical) line of each panel: where the other two slices cut it, cm."""
    ix, iy, iz = slice_indices(shape, positions)
    return [(G.y[iy], G.x[ix]), (G.z[iz], G.x[ix]), (G.z[iz], G.y[iy])]


def orthogonal_slices(fig, data: np.ndarray, G, positions, *, cmap="viridis", norm=None,
                      label: str = "", title: str = "", categories: list[str] | None = None):
    """Draw ``data`` (nx, ny, nz) on three panels of ``fig``; return ``(axes, images)``.

    ``categories``: ``data`` holds integer indices into these names (a medium map): drawn
    with a discrete colour map and a legend instead of a colour bar.
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch
    from matplotlib.ticker import MaxNLocator

    x0, x1, y0, y1 = -G.Lx / 2, G.Lx / 2, -G.Ly / 2, G.Ly / 2
    if categories is not None:
        import matplotlib as mpl

        colors = mpl.colormaps["tab10" if len(categories) <= 10 else "tab20"].colors
        cmap = ListedColormap([colors[i % len(colors)] for i in range(len(categories))])
        norm = BoundaryNorm(np.arange(len(categories) + 1) - 0.5, len(categories))
    widths = [G.Lx, G.Lx, G.Ly]
    axes = fig.subplots(1, 3, gridspec_kw={"width_ratios": widths})
    extents = [[x0, x1, y0, y1], [x0, x1, G.Lz, 0], [y0, y1, G.Lz, 0]]
    labels = [("x [cm]", "y [cm]"), ("x [cm]", "z [cm]"), ("y [cm]", "z [cm]")]
    images = []
    for k, (ax, (img, t), ext, (xl, yl), (h, v)) in enumerate(zip(
            axes, _panels(data, G, positions), extents, labels, _cuts(data.shape, G, positions),
            strict=True)):
        # y up in the xy panel; z down (into the tissue) in the others, as MCmatlab
        images.append(ax.imshow(img, extent=ext, cmap=cmap, norm=norm, aspect="equal",
                                interpolation="nearest", origin="lower" if k == 0 else "upper"))
        ax.set(xlabel=xl, ylabel=yl, title=t)
        # a narrow panel (a deep block's xz and yz) would run its default ticks together:
        # fewer of them, and upright where the panel is under half as wide as deep
        ax.xaxis.set_major_locator(MaxNLocator(nbins=4))
        if abs(ext[1] - ext[0]) < 0.5 * abs(ext[3] - ext[2]):
            ax.tick_params(axis="x", labelrotation=90)
        # where the other slices cut the panel (gid: found again by update_slices)
        ax.axhline(h, color="w", lw=0.6, ls="--", gid="cut")
        ax.axvline(v, color="w", lw=0.6, ls="--", gid="cut")
    if categories is not None:
        present = np.unique(data)
        handles = [Patch(color=cmap(i), label=categories[i]) for i in present]
        fig.legend(handles=handles, loc="outside right upper")
    else:
        fig.colorbar(images[0], ax=list(axes), label=label, shrink=0.8)
    if title:
        fig.suptitle(title)
    return axes, images


def update_slices(axes, images, data: np.ndarray, G, positions) -> None:
    """Show ``data`` (nx, ny, nz) at ``positions`` on the panels that
    :func:`orthogonal_slices` drew (their colour scales are left as they are)."""
    for ax, im, (img, t), (h, v) in zip(axes, images, _panels(data, G, positions),
                                        _cuts(data.shape, G, positions), strict=True):
        im.set_data(img)
        ax.set_title(t)
        hline, vline = [line for line in ax.lines if line.get_gid() == "cut"]
        hline.set_ydata([h, h])
        vline.set_xdata([v, v])


def new_figure(width=12.0, height=4.2, name=""):
    """A constrained-layout figure of ``width`` x ``height`` inches, its window titled ``name``."""
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(width, height), layout="constrained")
    if name and fig.canvas.manager is not None:
        fig.canvas.manager.set_window_title(name)
    return fig
