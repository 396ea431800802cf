"""Perturbation ("white") Monte Carlo of a homogeneous block: NA for many ``mua`` per run.

:func:`white_absorbed` runs the kernel of :mod:`mcmatlab_py.emulator._white_kernel` once for one
``mus`` and returns the absorbed power for every ``mua`` of a list; the emulator's
``method="white"`` build (:meth:`mcmatlab_py.emulator.AbsorptionEmulator.build`) makes one
such run per column of its table (``n_mus`` runs instead of ``n_mua * n_mus``).

Where re-weighting stops being accurate
---------------------------------------
Every weight is unbiased, but its noise is not that of a direct run at the same ``mua``:
the paths are drawn without absorption, so a strongly absorbing ``mua_k`` is estimated
from long paths whose weight is almost all gone. The noise of ``k`` grows with
``mua_k`` times the spread of the path lengths that reach a voxel; it is small while
``mua_k`` stays well below the reduced scattering ``mus (1 - g)`` (the diffusive regime,
where the paths are short and alike) and grows where ``mua_k`` approaches or exceeds
it, and in deep voxels at high ``mua``, which only the rare long paths reach. For the
paper's block (``g = 0.9``) the emulator's table spans ``mua / (mus (1 - g))`` from
5e-4 to 20; ``validation/emulator_accuracy.py --method white`` measures the error at
off-grid points, and ``tests/test_white.py`` checks single ``mua`` values, the table's
edges included, against direct Monte Carlo.

Several media (a spec with ``medium_map``, e.g. an epidermis over the dermis): one run per
``mus`` of the estimated medium gives every ``mua`` of that medium with the other media's
optics fixed (their ``mua`` is a fixed continuous loss in their voxels). A change of any
medium's ``mus``, ``g`` or ``n`` changes the paths themselves, which weights do not undo:
those stay in the spec (and its cache key). Refraction between media is not built: with
mismatched interfaces all media need one refractive index (else ``NotBuiltError``; the
``table`` build, one direct run per point, has no such limit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from .._strict import NotBuiltError
from ..monte_carlo.host import FLUSH_PHOTONS, WideSums, kernel_args, optical_arrays
from . import _white_kernel as WK
from .spec import EmulatorSpec
from .table import table_rows

__all__ = ["WhiteResult", "white_absorbed", "white_column", "white_obstacle", "white_supported"]


@dataclass
class WhiteResult:
    """Raw totals of a white Monte Carlo run.

    ``absorbed`` is (K, nx, ny, nz) absorbed weight summed over the packets
    (launched-packet units), one map per ``mua_k``; ``tally`` (N_TALLY, K) the totals of
    the ``T_*`` slots of :mod:`mcmatlab_py.monte_carlo._kernel` in the same units.
    """

    mua: np.ndarray  #: (K,) cm^-1
    absorbed: np.ndarray
    tally: np.ndarray
    n_photons: int

    def fraction(self, slot: int) -> np.ndarray:
        """(K,) a ``T_*`` tally as a fraction of the launched power."""
        return self.tally[slot] / self.n_photons


def white_obstacle(spec) -> tuple[type, str] | None:
    """Why the white build cannot run ``spec`` (an
    :class:`~mcmatlab_py.emulator.EmulatorSpec`): ``(exception type, message)``, or None
    when it can. Refraction between media is not built (``NotBuiltError`` unless they share
    one refractive index or the interfaces are matched), and the roulette needs a decay in
    every fixed medium (``mua > 0``)."""
    if spec.media is None:  # one medium
        return None
    present = np.unique(spec.medium_map)
    n = [spec.n if i == spec.estimated else spec.media[i][3] for i in present]
    if not spec.matched_interfaces and len(set(n)) > 1:
        return NotBuiltError, ("the white build needs one refractive index for all media (or "
                               f"matched interfaces), got n = {n}: use the table build")
    fixed = [int(i) for i in present if i != spec.estimated and not spec.media[i][0] > 0]
    if fixed:
        return ValueError, (f"the white build needs mua > 0 in every fixed medium (the "
                            f"roulette needs a decay), got mua = {spec.media[fixed[0]][0]!r} in "
                            f"medium {fixed[0]}")
    return None


def white_absorbed(spec, mua, mus: float, *, n_photons: int, seed: int,
                   n_threads: int | None = None, symmetrized: bool = False) -> WhiteResult:
    """One white Monte Carlo run of the block of ``spec`` (an
    :class:`~mcmatlab_py.emulator.EmulatorSpec`) with scattering ``mus`` (cm^-1), for every
    absorption in ``mua`` (K,) cm^-1. Deterministic for a seed, whatever ``n_threads``.

    ``symmetrized``: tally each voxel's orbit under the mirror symmetries of block and beam
    (``spec.orbits(voxels=True)``) and return the orbit averages, which equals
    :func:`~mcmatlab_py.emulator.symmetrize` of the voxel map (``voxels=True``); the tally
    is then about 8 times smaller and stays in the caches (about twice as fast on 100 x
    100 x 50 voxels).
    """
    mua = np.ascontiguousarray(np.atleast_1d(mua), dtype=np.float64)
    if mua.ndim != 1 or not np.all(np.isfinite(mua)) or np.any(mua <= 0):
        raise ValueError(f"mua must be finite values > 0, got {mua!r}")
    if not (np.isfinite(mus) and mus > 0):
        raise ValueError(f"mus must be finite and > 0, got {mus!r}")
    m = spec.model(float(mua[0]), float(mus), n_photons=n_photons, seed=seed)
    M = m.G.medium_map()
    m.MC.validate(m.G)
    mua_m, mus_m, g_m, n_m = optical_arrays(m.G.media)
    present = np.unique(M)
    obstacle = white_obstacle(spec)
    if obstacle is not None:
        raise obstacle[0](obstacle[1])
    mua_tab = np.repeat(mua_m[:, None], mua.size, axis=1)
    mua_tab[spec.estimated] = mua
    rate = np.ascontiguousarray(mua_tab[present].min(axis=0))
    args = kernel_args(m.G, m.MC, M, mua_m, mus_m, g_m, n_m, seed, int(n_photons))
    (Mf, _, _, _, _, _, nx, ny, nz, dx, dy, dz, boundary_type, n_out, matched, roulette,
     w_thr, chance, si, sf, stab, svox, *_rest) = args
    if n_out == 0.0 and not matched:
        raise ValueError("the white Monte Carlo needs MC.n_outside, the refractive index "
                         "outside the cuboid: None (MCmatlab's faces) is not built for it")
    # one medium in the grid, every face escaping: the kernel that walks no voxel faces
    uniform = int(present[0]) if (present.size == 1 and boundary_type == 1
                                  and np.isfinite(n_m[present[0]])) else -1
    bs = m.MC.batch_size
    n_threads = min(n_threads or numba.get_num_threads(), numba.config.NUMBA_NUM_THREADS)
    K = mua.size
    if symmetrized:
        _, fold = spec.orbits(voxels=True)
        n_rows = int(fold.max()) + 1
    else:
        fold, n_rows = np.arange(nx * ny * nz), nx * ny * nz
    fold = np.ascontiguousarray(fold, dtype=np.int64)
    acc = np.zeros((n_threads, n_rows, K), dtype=np.int64)
    tally = np.zeros((n_threads, WK.N_TALLY, K), dtype=np.int64)
    kid = mua.view(np.uint64)  # a weight's roulette numbers are keyed by its mua
    kargs = (np.ascontiguousarray(mua_tab), rate, kid, Mf, mus_m, g_m,
             float(n_m[spec.estimated]), nx, ny, nz, dx, dy, dz,
             boundary_type, n_out, matched, roulette, w_thr, chance, si, sf, stab, svox, fold,
             np.uint64(seed), bs, int(n_photons))
    old = numba.get_num_threads()
    numba.set_num_threads(n_threads)
    sums = WideSums()  # int64 fixed point holds 2^27 packets: move the sums before that
    n_batches, step = -(-int(n_photons) // bs), max(1, FLUSH_PHOTONS // bs)
    try:
        for a in range(0, n_batches, step):
            WK.run_white_batches(*kargs, a, min(a + step, n_batches), acc, tally, uniform)
            for name, arr in (("acc", acc), ("tally", tally)):
                sums.add(name, arr.sum(axis=0))
                arr[:] = 0
    finally:
        numba.set_num_threads(old)
    rows = sums.value("acc").T / WK.W_ONE  # (K, n_rows)
    if symmetrized:
        rows = rows / np.bincount(fold, minlength=n_rows)  # the orbit average
    absorbed = rows[:, fold].reshape(K, nx, ny, nz)
    return WhiteResult(mua=mua, absorbed=absorbed, tally=sums.value("tally") / WK.W_ONE,
                       n_photons=int(n_photons))


def white_column(spec, b: int, rows=None) -> tuple[np.ndarray, np.ndarray]:
    """Column ``b`` (one ``mus``) of the emulator table of ``spec`` by one white run:
    log(NA + offset) at the orbit representatives (n_rows, n_unique) and the absorbed
    fraction of every ``mua`` (n_rows,), for the table rows ``rows`` (indices into
    ``spec.mua_grid()``; all ``n_mua`` by default). The photons and the seed are those of
    the direct table's points in that column (``spec.photons_at(mus)``, ``spec.seed``).
    A row's numbers do not depend on which other rows run with it (each weight draws its
    own roulette numbers), so a column built in pieces equals one built at once, bit for
    bit."""
    mus = float(spec.mus_grid()[b])
    mua = spec.mua_grid() if rows is None else spec.mua_grid()[np.asarray(rows, dtype=int)]
    res = white_absorbed(spec, mua, mus, n_photons=spec.photons_at(mus),
                         seed=spec.seed, symmetrized=True)
    dV = spec.Lx * spec.Ly * spec.Lz / (spec.nx * spec.ny * spec.nz)
    out = table_rows(spec, res.absorbed / (res.n_photons * dV), symmetric=True)
    return out, res.absorbed.reshape(res.mua.size, -1).sum(axis=1) / res.n_photons


def white_supported(spec: EmulatorSpec) -> str | None:
    """None when the white build applies to ``spec``, else why not
    (:func:`mcmatlab_py.emulator.white.white_obstacle`: one refractive index for all media or
    matched interfaces, and ``mua > 0`` in every fixed medium)."""
    from .white import white_obstacle

    obstacle = white_obstacle(spec)
    return None if obstacle is None else obstacle[1]
