"""The parallel driver of the Monte Carlo kernels: workers (one per thread) claim photon
batches from a shared atomic counter and run them with the one-medium kernel
(:mod:`mcmatlab_py.monte_carlo._uniform`) or the general one
(:mod:`mcmatlab_py.monte_carlo._kernel`).

Numba keys the on-disk cache of :func:`run_batches` on this file's text alone, yet the
cached code holds the kernels compiled in: a change to them (or to the helpers they
inline) must change this file too, or a cache compiled before it goes on running.
Kernels of 2026-12: delta tracking within groups of similar media, a packet changing
between its balls only once one is used up (issue 47); deposits of fewer than
``_tally.RANDOM_ROUNDING_BELOW`` units rounded at random, not carried (issue 46).
"""

import numba
import numpy as np

from ._atomic import fetch_add
from ._kernel import transport_batch
from ._uniform import transport_uniform_batch, uniform_path_applies


@numba.njit(cache=True, parallel=True)
def run_batches(
    M, mua, mus, g, nref, uniform_medium, nx, ny, nz, dx, dy, dz,
    boundary_type, n_out, matched, roulette, weight_threshold, chance,
    si, sf, stab, svox, phase_idx, phase_tab, normals, use_normals,
    seed, batch_size, n_total, batch_start, batch_stop, acc, tally,
    oi, of, consider, ext, paths, path_n, track, flu, safe, majorant,
):  # fmt: skip
    """Run batches ``[batch_start, batch_stop)`` on ``acc.shape[0]`` workers in parallel.

    ``track`` (n_media,) bool or None and ``flu`` (n_workers, nvox or 1): the track-length
    tally (:func:`transport_batch`; the Python layer sets ``uniform_medium = -1`` with it).
    ``safe`` (nvox,) float32: the safety distances of the general kernel
    (:func:`mcmatlab_py.monte_carlo.safety.navigation_safety`; negative: a ball of delta
    tracking) and ``majorant`` (n_media,) float64 cm^-1, the largest attenuation of each
    medium's group (:func:`mcmatlab_py.monte_carlo.safety.delta_groups`).

    ``acc`` is (n_workers, nvox), ``tally`` (n_workers, N_TALLY or more) and ``ext``
    (n_workers, n_ext), one row per worker; the workers (one per thread) claim batches one at a time from a
    shared atomic counter, so a thread on a slower core runs fewer batches instead
    of holding up the others. The result of a batch depends only on
    ``(seed, batch)`` and integer sums are exact, so the reduced totals do not
    depend on which worker ran which batch, nor on the number of threads.
    """
    n_workers = acc.shape[0]
    counter = np.zeros(1, dtype=np.int64)
    uniform = False  # the one-medium kernel (mcmatlab_py.monte_carlo._uniform) runs a plain run
    if oi is None:  # the optional outputs need the general kernel (pruned at compile time)
        uniform = uniform_path_applies(uniform_medium, boundary_type, nref, mua, mus, phase_idx)
    for k in numba.prange(n_workers):
        while True:
            b = batch_start + fetch_add(counter, 0, 1)
            if b >= batch_stop:
                break
            if uniform:
                transport_uniform_batch(
                    b, uniform_medium, mua, mus, g, nref, nx, ny, nz, dx, dy, dz, n_out,
                    matched, roulette, weight_threshold, chance, si, sf, stab, svox, seed,
                    batch_size, n_total, acc[k], tally[k],
                )  # fmt: skip
                continue
            transport_batch(
                b, M, safe, majorant, mua, mus, g, nref, nx, ny, nz, dx, dy, dz,
                boundary_type, n_out, matched, roulette, weight_threshold, chance,
                si, sf, stab, svox, phase_idx, phase_tab, normals, use_normals,
                seed, batch_size, n_total, acc[k], tally[k],
                oi, of, consider, ext[k], paths, path_n, track, flu[k],
            )  # fmt: skip
