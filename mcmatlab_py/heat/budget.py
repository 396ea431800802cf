"""What a heat run will need, estimated before anything is allocated
(:mod:`mcmatlab_py.budget` for the limits and the memory of this machine)."""

from __future__ import annotations

from fem.checks import shorten

from ..budget import HEAT_BYTES_PER_NODE, check_memory, check_steps
from .mesh import heat_mesh_divisions
from .simulation import auto_dt

__all__ = ["check_heat"]


def check_heat(G, HS) -> None:
    """Refuse a heat simulation of ``(model.G, model.HS)`` that cannot fit or finish: more
    than :data:`mcmatlab_py.budget.MAX_STEPS` steps (``HS.dt``, the durations) or more memory than the machine
    has (``HS.mesh_divisions``, the voxel grid)."""
    div = heat_mesh_divisions(G, HS, warn=False) or (G.nx, G.ny, G.nz)
    # steps chosen by accuracy (mcmatlab_py.heat.run's condition): their number follows the
    # temperatures, not the stability bound, and is not known ahead
    adaptive = (HS.dt is None and getattr(HS, "step_control", "stability") == "accuracy"
                and HS.mua_t is None and HS.mus_t is None and HS.VHC_t is None
                and HS.TC_t is None)
    dt = HS.dt
    if dt is None and not adaptive:  # the stability bound, from the media given as numbers
        const = [m for m in G.media if isinstance(m.VHC, float) and isinstance(m.TC, float)]
        if const:
            dt = auto_dt([L / n for L, n in zip((G.Lx, G.Ly, G.Lz), div, strict=True)],
                         [m.VHC for m in const], [m.TC for m in const], HS.theta,
                         HS.large_time_steps)
    if dt is not None:
        duration = HS.total_duration + HS.duration_end
        step = f"HS.dt = {dt:g} s" if HS.dt is not None else f"the automatic step {dt:g} s"
        check_steps(duration / dt, f"HS (n_pulses * (duration_on + duration_off) + "
                                   f"duration_end = {duration:g} s in steps of {step})",
                    "HS.dt, HS.duration_on, HS.duration_off, HS.duration_end or HS.n_pulses")
    n_nodes = 1.0
    for d in div:
        n_nodes *= float(d) + 1
    keys = (f"HS.mesh_divisions = {shorten(list(div))}" if HS.mesh_divisions is not None else
            f"G.nx, G.ny, G.nz = {shorten(list(div))} (or set a coarser HS.mesh_divisions)")
    check_memory(n_nodes * HEAT_BYTES_PER_NODE, f"the heat mesh of {n_nodes:.3g} nodes", keys)
