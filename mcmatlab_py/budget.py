"""What a run will need, estimated before anything is allocated.

A run that cannot fit is refused at once with the estimate and the key to change, as
the voxel-count check of ``model.G`` does, instead of being killed by the kernel's
out-of-memory handler hours later (exit 137, no message).
"""

from __future__ import annotations

import os

__all__ = [
    "HEAT_BYTES_PER_NODE",
    "LONG_RUN_S",
    "MAX_STEPS",
    "available_memory",
    "check_filter",
    "check_memory",
    "check_steps",
    "format_bytes",
    "format_seconds",
    "warn_long_run",
]

#: time steps beyond which a run is refused (10^6 heat steps of even a tiny mesh take hours)
MAX_STEPS = 1_000_000
#: s: a run expected to take longer than this says so, with its estimate, before it goes on
LONG_RUN_S = 600.0


def available_memory() -> int:
    """Bytes of physical memory of this machine (or of its cgroup limit, if lower)."""
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(path) as fh:
                text = fh.read().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return int(total)


def format_bytes(n: float) -> str:
    """``n`` bytes in a readable unit (``"4.1 GB"``)."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} PB"  # pragma: no cover


def format_seconds(s: float) -> str:
    """``s`` seconds in a readable unit (``"3.2 days"``)."""
    for unit, length in (("years", 365.25 * 86400), ("days", 86400), ("h", 3600), ("min", 60)):
        if s >= 2 * length or unit == "min" and s >= 60:
            return f"{s / length:.3g} {unit}"
    return f"{s:.3g} s"


def warn_long_run(seconds: float, what: str, measured: str, instead: str) -> None:
    """Warn (once, before a long run goes on) when it is expected to take more than
    :data:`LONG_RUN_S`: ``"{what} will take about 3.2 days more ({measured}): Ctrl-C stops
    it; {instead}"``."""
    if seconds > LONG_RUN_S:
        import warnings

        warnings.warn(f"{what} will take about {format_seconds(seconds)} more ({measured}): "
                      f"Ctrl-C stops it; {instead}", RuntimeWarning, stacklevel=3)


def check_memory(need_bytes: float, what: str, keys: str, fraction: float = 0.8) -> None:
    """Refuse (ValueError) a run whose estimated memory ``need_bytes`` exceeds ``fraction``
    of this machine's memory; the message names ``what`` needs it and the ``keys`` to change."""
    have = available_memory()
    if need_bytes > fraction * have:
        raise ValueError(f"{what} needs about {format_bytes(need_bytes)} of memory, more than "
                         f"this machine can give ({format_bytes(fraction * have)} of "
                         f"{format_bytes(have)}): reduce {keys}")


def check_steps(n_steps: float, what: str, keys: str, limit: int = MAX_STEPS) -> None:
    """Refuse (ValueError) a run of more than ``limit`` time steps, naming the ``keys``."""
    if not n_steps <= limit:
        raise ValueError(f"{what} would take {n_steps:.3g} time steps (limit {limit}): "
                         f"change {keys}")


#: bytes per FEM node of a heat run (operators, factorization or fast-diagonalization
#: data, work vectors), measured: ``tissue-enkf heat`` on 2.1 M nodes peaks at 4.1 GB
HEAT_BYTES_PER_NODE = 2048


def check_filter(n_members: int, n_nodes: int, table_points: int = 0) -> None:
    """Refuse a filter whose ensemble (``n_members`` x ``n_nodes`` temperatures, with the
    analysis' work copies), heat model and emulator table (``table_points`` x nodes)
    cannot fit in memory."""
    ensemble = 12.0 * 8 * n_members * n_nodes  # the ensemble, its forecast, Y, anomalies...
    check_memory(ensemble + HEAT_BYTES_PER_NODE * n_nodes,
                 f"the filter's ensemble ({n_members} members x {n_nodes} nodes)",
                 "filter.n_members or filter.grid")
    if table_points:
        check_memory(2.0 * 8 * table_points * n_nodes,
                     f"the emulator table ({table_points} points x {n_nodes} nodes)",
                     "filter.emulator.n_mua, filter.emulator.n_mus or filter.grid")
