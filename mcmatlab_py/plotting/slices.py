"""Three orthogonal slices of a voxel field, the 2-D stand-in for MCmatlab's NdimSliderPlot.

MCmatlab draws a 3-D field as three slices in a 3-D box with sliders; a saved figure
shows the same three planes side by side: xy at depth z, xz at y, yz at x, placed by
relative ``positions`` (0..1 along each axis, MCmatlab's ``slicePositions``), with z
pointing down as in MCmatlab (``reversedAxes = 3``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["orthogonal_slices", "slice_indices"]


def slice_indices(shape, positions) -> tuple[int, int, int]:
    """Voxel indices of the slices at relative ``positions`` (0: first voxel, 1: last)."""
    return tuple(int(round(float(p) * (n - 1))) for p, n in zip(positions, shape, strict=True))


def orthogonal_slices(fig, data: np.ndarray, G, positions, *, cmap="viridis", norm=None,
                      label: str = "", title: str = "", categories: list[str] | None = None):
    """Draw ``data`` (nx, ny, nz) on three panels of ``fig``; return ``(axes, images)``.

    ``categories``: ``data`` holds integer indices into these names (a medium map): drawn
    with a discrete colour map and a legend instead of a colour bar.
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch
    from matplotlib.ticker import MaxNLocator

    ix, iy, iz = slice_indices(data.shape, positions)
    x0, x1, y0, y1 = -G.Lx / 2, G.Lx / 2, -G.Ly / 2, G.Ly / 2
    if categories is not None:
        import matplotlib as mpl

        colors = mpl.colormaps["tab10" if len(categories) <= 10 else "tab20"].colors
        cmap = ListedColormap([colors[i % len(colors)] for i in range(len(categories))])
        norm = BoundaryNorm(np.arange(len(categories) + 1) - 0.5, len(categories))
    widths = [G.Lx, G.Lx, G.Ly]
    axes = fig.subplots(1, 3, gridspec_kw={"width_ratios": widths})
    def at(v, length):  # a centre that rounding put 1e-17 off zero is drawn as 0
        return f"{0.0 if abs(v) < 1e-9 * length else v:.3g}"

    panels = [
        (data[:, :, iz].T, [x0, x1, y0, y1], "x [cm]", "y [cm]", f"xy at z = {at(G.z[iz], G.Lz)} cm"),
        (data[:, iy, :].T, [x0, x1, G.Lz, 0], "x [cm]", "z [cm]", f"xz at y = {at(G.y[iy], G.Ly)} cm"),
        (data[ix, :, :].T, [y0, y1, G.Lz, 0], "y [cm]", "z [cm]", f"yz at x = {at(G.x[ix], G.Lx)} cm"),
    ]
    images = []
    for k, (ax, (img, ext, xl, yl, t)) in enumerate(zip(axes, panels, strict=True)):
        # y up in the xy panel; z down (into the tissue) in the others, as MCmatlab
        images.append(ax.imshow(img, extent=ext, cmap=cmap, norm=norm, aspect="equal",
                                interpolation="nearest", origin="lower" if k == 0 else "upper"))
        ax.set(xlabel=xl, ylabel=yl, title=t)
        # a narrow panel (a deep block's xz and yz) would run its default ticks together
        ax.xaxis.set_major_locator(MaxNLocator(nbins=4))
    # where the other slices cut each panel
    axes[0].axhline(G.y[iy], color="w", lw=0.6, ls="--")
    axes[0].axvline(G.x[ix], color="w", lw=0.6, ls="--")
    axes[1].axhline(G.z[iz], color="w", lw=0.6, ls="--")
    axes[1].axvline(G.x[ix], color="w", lw=0.6, ls="--")
    axes[2].axhline(G.z[iz], color="w", lw=0.6, ls="--")
    axes[2].axvline(G.y[iy], color="w", lw=0.6, ls="--")
    if categories is not None:
        present = np.unique(data)
        handles = [Patch(color=cmap(i), label=categories[i]) for i in present]
        fig.legend(handles=handles, loc="outside right upper")
    else:
        fig.colorbar(images[0], ax=list(axes), label=label, shrink=0.8)
    if title:
        fig.suptitle(title)
    return axes, images
