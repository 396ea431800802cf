"""``filter.medium`` and the emulator's node grids of a second medium and of the beam's
radius: which media of ``[G]`` are estimated."""

from __future__ import annotations

from fem.checks import shorten
from mcmatlab_py.config import ConfigError

from .numbers import num, pair
from .params import prior_of

__all__ = ["BEAM_NODES_ROOM", "MEDIA_NODES_ROOM", "beam_nodes", "estimated_media",
           "estimated_medium", "media_nodes"]


def estimated_media(value, G) -> tuple[int, int | None]:
    """``filter.medium``: one medium (name or index), or a list of two whose optics are
    both estimated (the second's as mua2, mus2): ``(first, second or None)``."""
    if not isinstance(value, list):
        return estimated_medium(value, G), None
    if len(value) == 1:
        return estimated_medium(value[0], G), None
    if len(value) != 2:
        raise ConfigError(f"filter.medium must be one medium or a list of two (whose optics are "
                          f"estimated), got {shorten(repr(value))}")
    first, second = (estimated_medium(v, G) for v in value)
    if first == second:
        raise ConfigError(f"filter.medium = {shorten(repr(value))} names one medium twice")
    return first, second


#: the default node range of a second medium's optics: its prior, widened by this factor
#: each way (members that an analysis moves beyond the prior would be clamped to the edge
#: and stop responding to the data: with the nodes on the prior's edges a camera's bands
#: missed truths near those edges)
MEDIA_NODES_ROOM = 1.5


def media_nodes(emu: dict, setup_kw: dict, m) -> dict:
    """``filter.emulator.mua2_range``, ``mus2_range`` (default: the second medium's prior
    widened by :data:`MEDIA_NODES_ROOM` each way) and ``media_nodes`` (per axis, default
    4: over that range 3 nodes added 0.5-1% to the loads' error, 4 nothing measurable,
    ``validation/layered_both.py --emulator``): the node grid of its optics."""
    out = {"n_nodes": 4}
    if "media_nodes" in emu:
        out["n_nodes"] = num("filter.emulator.media_nodes", emu["media_nodes"], integer=True,
                              lo=2)
    for name in ("mua2", "mus2"):
        prior, source = prior_of(name, setup_kw, m, m.where2)
        rng = (prior[0] / MEDIA_NODES_ROOM, prior[1] * MEDIA_NODES_ROOM)
        if f"{name}_range" in emu:
            rng = pair(f"filter.emulator.{name}_range", emu[f"{name}_range"], positive=True)
            if not (rng[0] <= prior[0] and prior[1] <= rng[1]):
                raise ConfigError(f"filter.emulator.{name}_range = {list(rng)} must cover the "
                                  f"prior of {name}, [{prior[0]:g}, {prior[1]:g}] cm^-1 ({source})")
        out[f"{name}_range"] = tuple(rng)
    return out


#: the default node range of an estimated beam radius: its prior widened by this factor each
#: way (as :data:`MEDIA_NODES_ROOM`, so that members an analysis moves past the prior still
#: respond to the data)
BEAM_NODES_ROOM = 1.1


def beam_nodes(emu: dict, setup_kw: dict, m, model) -> dict:
    """``filter.emulator.radius_range`` (default: the radius's prior widened by
    :data:`BEAM_NODES_ROOM` each way) and ``radius_nodes`` (default 4: against tables built
    directly at radii between the nodes the filter's loads were 0.93% off at worst, 2.6%
    with 3 nodes, 0.66% with 5, with a table's own Monte Carlo noise 0.53%;
    ``validation/reports/beam_radius.md``): the node grid of the beam's radius."""
    src = model.MC.light_source
    if src.source_type not in ("tophat", "gaussian"):
        raise ConfigError(f"filter.estimate holds beam_radius, but MC.light_source.source_type "
                          f"= {src.source_type!r} has no radius: use \"tophat\" or \"gaussian\"")
    out = {"n_nodes": 4}
    if "radius_nodes" in emu:
        out["n_nodes"] = num("filter.emulator.radius_nodes", emu["radius_nodes"], integer=True,
                              lo=2)
    prior, source = prior_of("beam_radius", setup_kw, m)
    rng = (prior[0] / BEAM_NODES_ROOM, prior[1] * BEAM_NODES_ROOM)
    if "radius_range" in emu:
        rng = pair("filter.emulator.radius_range", emu["radius_range"], positive=True)
        if not (rng[0] <= prior[0] and prior[1] <= rng[1]):
            raise ConfigError(f"filter.emulator.radius_range = {list(rng)} must cover the prior "
                              f"of beam_radius, [{prior[0]:g}, {prior[1]:g}] cm ({source})")
    out["radius_range"] = tuple(rng)
    return out


def estimated_medium(value, G) -> int:
    """``filter.medium``: the index in ``G.media`` of the medium whose parameters are
    estimated (a name or an index; default the only medium). The heat model has one VHC
    and TC for the whole block, so every medium must have the same."""
    names = [m.name for m in G.media]
    if value is None:
        if len(names) > 1:
            raise ConfigError(f"G.media holds {len(names)} media {names}: set filter.medium to "
                              "the name (or index) of the one whose parameters are estimated")
        i = 0
    elif isinstance(value, str):
        if names.count(value) != 1:
            why = "is repeated in" if value in names else "is not a medium of"
            raise ConfigError(f"filter.medium = {shorten(repr(value))} {why} G.media {names}")
        i = names.index(value)
    elif isinstance(value, int) and not isinstance(value, bool):
        if not 0 <= value < len(names):
            raise ConfigError(f"filter.medium = {value} is not an index of G.media "
                              f"(0..{len(names) - 1}: {names})")
        i = value
    else:
        raise ConfigError(f"filter.medium must be a medium's name or index, got "
                          f"{shorten(repr(value))}")
    for k in ("VHC", "TC"):
        if getattr(G.media[i], k) is None:
            raise ConfigError(f"G.media[{i}].{k} is missing (needed by the heat model)")
    if len(names) > 1:
        try:
            M = G.medium_map()
        except ValueError as err:
            raise ConfigError(str(err)) from None
        if not (M == i).any():
            raise ConfigError(f"filter.medium = {names[i]!r} (G.media[{i}]) fills no voxel of "
                              "the geometry (G.geom_func): nothing to estimate")
        ref = G.media[i]
        for j, other in enumerate(G.media):
            for k in ("VHC", "TC"):
                a, b = getattr(other, k), getattr(ref, k)
                if callable(a) or callable(b) or a != b:
                    raise ConfigError(
                        f"G.media[{j}].{k} = {shorten(repr(a))} differs from the estimated "
                        f"medium's {shorten(repr(b))}: the filter's heat model has one {k} for "
                        "the whole block (give every medium the same VHC and TC)")
    return i
