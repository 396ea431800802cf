"""Figures like MCmatlab's ``plot(model, 'G' | 'MC' | 'FMC' | 'HS')`` (an edge package: matplotlib
is imported only here, pyvista only for the interactive slicer).

``model.plot(what, path=None, interactive=False)`` returns ``{name: Figure}``:

* ``"G"``: ``geometry`` (the media on three orthogonal slices) and ``media_properties``.
* ``"MC"``: ``media_properties``, ``NA`` and ``NFR`` (log colour scales).
* ``"FMC"``: ``emitters``, ``NA`` and ``NFR`` of the fluorescence, and ``light_collector``,
  ``far_field``, ``NI``, ``example_paths`` when the fluorescence run has them.
* ``"HS"``: ``sensor_positions`` and ``sensor_temperatures`` (with sensors),
  ``temperature`` (final, on the voxels), and with Arrhenius media ``damage``
  (the media with the voxels where Omega > 1) and ``fractional_damage``.

Modules: :mod:`.slices` (the orthogonal slice panels every figure uses),
:mod:`.figures` (the figures), :mod:`.movie` (the heat run's live slices and MP4 movie),
:mod:`.slicer` (pyvista's interactive 3-D slicer).
"""

from __future__ import annotations

from pathlib import Path

from ._na import plot_na_slices

__all__ = ["plot_model", "plot_na_slices"]


def plot_model(model, what: str, path: str | Path | None = None, *,
               interactive: bool = False) -> dict:
    """MCmatlab's ``plot(model, what)``: the figures of ``what`` in ``{"G", "MC", "FMC", "HS"}``.

    Parameters
    ----------
    what : {"G", "MC", "FMC", "HS"}
    path : str or Path, optional
        Save each figure as a PNG: ``<stem>_<name>.png`` next to ``path``.
    interactive : bool
        Also open pyvista's 3-D slicer of the main field (needs pyvista and a display).

    Returns
    -------
    dict
        ``{name: matplotlib.figure.Figure}``.
    """
    from . import figures

    makers = {"G": figures.geometry_figures, "MC": figures.monte_carlo_figures,
              "FMC": figures.fluorescence_figures, "HS": figures.heat_figures}
    if what not in makers:
        raise ValueError(f"model.plot takes 'G', 'MC', 'FMC' or 'HS', got {what!r}")
    figs = makers[what](model)
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        stem = path.stem if path.suffix else path.name
        for name, fig in figs.items():
            fig.savefig(path.with_name(f"{stem}_{name}.png"), dpi=110)
    if interactive:
        from .slicer import interactive_slicer

        interactive_slicer(model, what)
    return figs
