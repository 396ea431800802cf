"""Figures like MCmatlab's (an edge module: matplotlib is imported only here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..monte_carlo.broadband import total

__all__ = ["plot_na_slices"]


def plot_na_slices(model, path: str | Path, *, field: str = "NA") -> None:
    """Save a PNG of a voxel field: the xz slice through the beam axis and the xy surface slice."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    G, MC = model.G, model.MC
    data = total(getattr(MC, field))  # broadband: summed over the wavelengths
    src = MC.light_source
    iy = int(np.clip(np.searchsorted(G.y, src.y_focus), 0, G.ny - 1))
    positive = data[data > 0]
    norm = LogNorm(vmin=max(positive.max() * 1e-4, positive.min()), vmax=positive.max()) \
        if positive.size else None
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    ext_xz = [-G.Lx / 2, G.Lx / 2, G.Lz, 0]
    im = axes[0].imshow(np.where(data[:, iy, :] > 0, data[:, iy, :], np.nan).T, extent=ext_xz,
                        aspect="auto", norm=norm, cmap="inferno")
    axes[0].set(xlabel="x [cm]", ylabel="z [cm]", title=f"{field}, xz slice at y = {G.y[iy]:.3g} cm")
    ext_xy = [-G.Lx / 2, G.Lx / 2, -G.Ly / 2, G.Ly / 2]
    axes[1].imshow(np.where(data[:, :, 0] > 0, data[:, :, 0], np.nan).T, extent=ext_xy,
                   origin="lower", aspect="equal", norm=norm, cmap="inferno")
    axes[1].set(xlabel="x [cm]", ylabel="y [cm]", title=f"{field}, xy slice at the surface")
    unit = "W/cm$^3$/W" if field == "NA" else "W/cm$^2$/W"
    fig.colorbar(im, ax=axes, label=f"{field} [{unit}]")
    fig.savefig(path, dpi=110)
    plt.close(fig)
