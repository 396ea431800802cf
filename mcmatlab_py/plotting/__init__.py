"""Figures like MCmatlab's ``plot(model, 'G' | 'MC' | 'FMC' | 'HS')`` (an edge package: matplotlib
is imported only here, pyvista only for the interactive slicer).

``model.plot(what, path=None, interactive=False)`` returns ``{name: Figure}``; without
``what`` (MCmatlab's ``plot(model)``), the figures of every stage that has outputs: ``G``
always, ``MC``, ``FMC`` and ``HS`` when they have run, named ``"<stage>_<name>"``
(``"MC_NA"``):

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

__all__ = ["STAGES", "plot_model", "plot_na_slices", "stages_with_outputs"]


#: MCmatlab's stages, in the order ``plot(model)`` draws them
STAGES = ("G", "MC", "FMC", "HS")


def stages_with_outputs(model) -> list[str]:
    """The stages that ``plot(model)`` draws: the geometry, and each simulation that has run."""
    ran = {"G": True, "MC": model.MC.NA is not None, "FMC": model.FMC.NA is not None,
           "HS": model.HS.T_voxels is not None}
    return [s for s in STAGES if ran[s]]


def plot_model(model, what: str | None = None, path: str | Path | None = None, *,
               interactive: bool = False) -> dict:
    """MCmatlab's ``plot(model, what)``: the figures of ``what`` in ``{"G", "MC", "FMC", "HS"}``.

    Parameters
    ----------
    what : {"G", "MC", "FMC", "HS"}, optional
        None (MCmatlab's ``plot(model)``): every stage with outputs
        (:func:`stages_with_outputs`), the figures named ``"<stage>_<name>"``.
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
    if what is None:
        stages = stages_with_outputs(model)
        figs = {f"{stage}_{name}": fig for stage in stages
                for name, fig in makers[stage](model).items()}
    elif what in makers:
        stages, figs = [what], makers[what](model)
    else:
        raise ValueError(f"model.plot takes 'G', 'MC', 'FMC', 'HS' or None (every stage that "
                         f"has outputs), got {what!r}")
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        stem = path.stem if path.suffix else path.name
        for name, fig in figs.items():
            fig.savefig(path.with_name(f"{stem}_{name}.png"), dpi=110)
    if interactive:
        from .slicer import interactive_slicer

        for stage in stages:
            interactive_slicer(model, stage)
    return figs
