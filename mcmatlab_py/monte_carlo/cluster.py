"""The Monte Carlo on a ``dask.distributed`` cluster: the photon batches split into
ranges, one task each (:func:`batch_range`), their integer tallies summed: the same numbers
as a run on this machine."""

from __future__ import annotations

import functools
import time

import numba
import numpy as np

from .._strict import NotBuiltError
from ..distributed import run_tasks, split_range
from . import _outputs as KO
from ._tally import N_TALLY, W_ONE
from .host import HostRun, MCResult, WideSums, kernel_args, parent_media, track_length, track_media
from .outputs import OutputSpec, output_spec

__all__ = ["batch_range", "simulate_distributed"]


def batch_range(args: tuple, batches: tuple[int, int], spec: OutputSpec | None = None,
                track: bool = True) -> tuple:
    """Batches ``[start, stop)`` of a run on this machine's threads (a task body): the
    :class:`WideSums` of the absorbed weights ``acc`` (nvox,), the tallies ``tally`` (64,)
    and the optional outputs' tallies ``ext`` (n_ext,), fixed point; the kernel seconds;
    the example paths and their lengths."""
    if spec is None:
        spec = OutputSpec(None, np.zeros(KO.OF_SIZE), np.zeros(1, dtype=np.bool_), 1, 0)
    host = HostRun(args, numba.get_num_threads(), spec, int(args[27]), track)
    t0 = time.perf_counter()
    host.run(batches[0], batches[1])
    return host.totals(), time.perf_counter() - t0, host.out[4], host.out[5]


def simulate_distributed(G, MC, M, mua, mus, g, nref, *, seed, n_photons, client,
                          label) -> MCResult:
    if n_photons is None:
        raise ValueError("MC.simulation_time_requested cannot be used on a cluster: give "
                         "MC.n_photons_requested")
    n_batches = -(-n_photons // MC.batch_size)
    workers = max(1, len(client.scheduler_info().get("workers", {})))
    ranges = split_range(n_batches, 4 * workers)  # a few tasks per worker: load balance
    if getattr(MC, "request_collected_photons", False):
        raise NotBuiltError("MC.request_collected_photons is not built for runs on a cluster")
    args = kernel_args(G, MC, M, mua, mus, g, nref, seed, n_photons)
    spec = output_spec(G, MC, len(mua), parent_media(G, MC, len(mua)))
    t0 = time.perf_counter()
    parts = run_tasks(functools.partial(batch_range, args, spec=spec,
                                        track=MC.calc_normalized_fluence_rate),
                      ranges, client=client,
                      progress=MC.progress, label=label)
    wall = time.perf_counter() - t0
    sums = WideSums()
    for p in parts:
        sums.merge(p[0])
    # each example path was written by the one task that ran its packet
    path_n = np.max([p[3] for p in parts], axis=0)
    paths = parts[0][2].copy()
    for p in parts[1:]:
        rows = p[3] > 0
        paths[rows] = p[2][rows]
    track = track_media(args, spec, MC.calc_normalized_fluence_rate)
    length = track_length(sums, track, (G.dx, G.dy, G.dz), M.shape)
    return MCResult(absorbed=sums.value("acc").reshape(M.shape) / W_ONE,
                    tally=sums.value("tally")[: N_TALLY], n_photons=int(n_photons),
                    kernel_seconds=wall, kernel_cpu_seconds=float(sum(p[1] for p in parts)),
                    spec=spec, ext=sums.value("ext"), paths=paths, path_n=path_n,
                    track=track, track_length=length)
