"""Python layer of the Monte Carlo: validate once, build arrays, run the kernel in rounds
(here, on a GPU: :mod:`~mcmatlab_py.monte_carlo.gpu`, or on a cluster:
:mod:`~mcmatlab_py.monte_carlo.cluster`), one wavelength after the other for a broadband
``MC``, and write the results into ``model.MC``."""

from __future__ import annotations

import math
import time

import numba
import numpy as np

from .._strict import NotBuiltError
from ..budget import warn_long_run
from ..geometry.media_bins import optical_media_properties
from ..progress import Progress
from ._tally import (
    N_TALLY,
    T_ABSORBED_EXCLUDED,
    T_BOTTOM,
    T_KILLED,
    T_LAUNCHED,
    T_MISSED,
    T_OUTSIDE_ABSORBED,
    T_ROULETTE,
    T_SIDES,
    T_SPECULAR,
    T_TOP,
    W_ONE,
)
from .broadband import (
    WavelengthStack,
    check_supported,
    is_broadband,
    monochromatic,
    photon_split,
    spectrum,
    stacked_properties,
    wavelength_seeds,
)
from .cluster import simulate_distributed
from .gpu import simulate_gpu
from .host import HostRun, MCResult, kernel_args, parent_media, track_length
from .outputs import output_spec, store_outputs
from .simulation import MAX_PHOTONS, check_energy_balance

__all__ = [
    "run_broadband",
    "run_monte_carlo",
    "run_simulation",
    "run_validated",
    "simulate",
    "store_results",
]


def simulate(G, MC, M: np.ndarray, mua, mus, g, nref, *, seed: int, n_photons: int | None,
             time_limit_s: float | None = None, label: str = "Monte Carlo",
             client=None) -> MCResult:
    """Run the kernel on a validated geometry; the medium map and properties are given.

    Exactly one of ``n_photons`` and ``time_limit_s`` is used (``n_photons`` wins). With a
    ``dask.distributed`` ``client`` the photon batches are split into ranges, one task
    each, and the integer tallies summed: the same numbers as here.
    """
    if getattr(MC, "use_gpu", False):
        if client is not None:
            raise NotBuiltError("MC.use_gpu with a dask client (a cluster of GPUs) is not built")
        return simulate_gpu(G, MC, M, mua, mus, g, nref, seed=seed, n_photons=n_photons,
                             time_limit_s=time_limit_s, label=label)
    if client is not None:
        return simulate_distributed(G, MC, M, mua, mus, g, nref, seed=seed,
                                     n_photons=n_photons, client=client, label=label)
    n_threads = min(MC.n_threads or numba.get_num_threads(), numba.config.NUMBA_NUM_THREADS)
    n_slots = n_threads  # one worker per thread, each with its own tally rows
    bs = MC.batch_size
    spec = output_spec(G, MC, len(mua), parent_media(G, MC, len(mua)))
    collect_target = n_photons if getattr(MC, "request_collected_photons", False) else None
    if collect_target is not None:
        n_photons = None  # run until enough packets are collected
        time_limit_s = 60.0 * MC.simulation_time_requested if MC.simulation_time_requested \
            else None
    n_total = n_photons if n_photons is not None else MAX_PHOTONS
    n_batches = -(-n_total // bs) if n_photons is not None else None
    args = kernel_args(G, MC, M, mua, mus, g, nref, seed, n_total)

    old_threads = numba.get_num_threads()
    numba.set_num_threads(n_threads)
    try:
        # compiles (or loads) outside the timing
        host = HostRun(args, n_slots, spec, bs, MC.calc_normalized_fluence_rate)
        if collect_target is not None:
            done, kernel_s, kernel_cpu = _run_until_collected(host, collect_target,
                                                              time_limit_s)
            n_photons = done * bs
            n_batches = done
        total = n_batches if n_batches is not None else time_limit_s
        bar = Progress(total, label, enabled=MC.progress and collect_target is None)
        done = 0 if collect_target is None else n_batches
        if collect_target is None:
            kernel_s = 0.0
            kernel_cpu = 0.0
        per_round = 8 * n_slots
        while done < (n_batches if n_batches is not None else np.inf):
            stop = done + per_round if n_batches is None else min(done + per_round, n_batches)
            t0 = time.perf_counter()
            c0 = time.process_time()
            host.run(done, stop)
            dt = time.perf_counter() - t0
            kernel_cpu += time.process_time() - c0
            kernel_s += dt
            n_round = stop - done
            done = stop
            bar.update(done if n_batches is not None else kernel_s,
                       f"{done * bs / max(kernel_s, 1e-9):.3g} photons/s")
            if n_batches is not None and done >= n_batches:
                break
            if n_batches is None and kernel_s >= time_limit_s:
                break
            # aim at rounds of about half a second, to keep the bar and the clock responsive
            rate = n_round / max(dt, 1e-6)  # batches per second
            if n_batches is not None and done == n_round:  # the estimate, once, up front
                warn_long_run((n_batches - done) / rate,
                              f"MC.n_photons_requested = {n_total:.3g}",
                              f"{rate * bs:.3g} photons/s on the first {done * bs:.3g}",
                              "request fewer photons, or set MC.simulation_time_requested")
            per_round = int(min(max(n_slots, 0.5 * rate), 50 * per_round))
            per_round = max(n_slots, per_round - per_round % n_slots)
            if n_batches is None:
                remaining = time_limit_s - kernel_s
                per_round = max(n_slots, min(per_round, int(rate * remaining) + n_slots))
        bar.close()
    finally:
        numba.set_num_threads(old_threads)
    n_done = n_photons if n_photons is not None else done * bs
    sums = host.totals()
    return MCResult(absorbed=sums.value("acc").reshape(M.shape) / W_ONE,
                    tally=sums.value("tally")[: N_TALLY], n_photons=int(n_done),
                    kernel_seconds=kernel_s, kernel_cpu_seconds=kernel_cpu, spec=spec,
                    ext=sums.value("ext"), paths=host.out[4], path_n=host.out[5],
                    track=host.track,
                    track_length=track_length(sums, host.track, (G.dx, G.dy, G.dz), M.shape))


def _run_until_collected(host: HostRun, target: int, time_limit_s):
    """MCmatlab's requestCollectedPhotons: run batches until ``target`` packets are collected.

    The size of each round depends only on the counts collected so far, never on the
    clock or the thread count, so a seed still gives the same result on any machine
    (unless ``time_limit_s`` stops the run first). Returns (batches, seconds, CPU seconds).
    """
    done, per_round = 0, 16
    kernel_s = kernel_cpu = 0.0
    while True:
        t0, c0 = time.perf_counter(), time.process_time()
        host.run(done, done + per_round)
        kernel_s += time.perf_counter() - t0
        kernel_cpu += time.process_time() - c0
        done += per_round
        got = host.collected()
        if got >= target or (time_limit_s is not None and kernel_s >= time_limit_s):
            return done, kernel_s, kernel_cpu
        # aim 10% past the target at the rate seen so far; at most 4x the batches done
        rate = got / done
        need = (target - got) / rate * 1.1 if got else 4 * done
        per_round = int(min(max(math.ceil(need), 1), 4 * done))
        if done * host.bs > 10**12:
            raise RuntimeError(f"MC.request_collected_photons: {got} of {target} packets "
                               f"collected after {done * host.bs} launched; check the collector")


def run_monte_carlo(model, client=None) -> None:
    """Validate ``model.G`` and ``model.MC``, run the Monte Carlo, and fill ``model.MC``."""
    run_simulation(model.G, model.MC, client=client)


def run_simulation(G, MC, *, client=None, power: float = 1.0) -> None:
    """Validate ``G`` and ``MC`` (a :class:`~mcmatlab_py.monte_carlo.simulation.MonteCarloSimulation` or its
    fluorescence subclass), run the Monte Carlo, and fill ``MC``.

    ``power``: W launched per W the outputs are normalised to. The maps (``NA``, ``NFR``,
    ``NI_*``, far field, collector image, MCML bins) are multiplied by it; the fractions
    (``absorbed_fraction``, ``escaped``, ...) stay fractions of the launched power. The
    fluorescence run gives the fluorescence emitted per W of incident excitation, so its maps
    are per W incident as MCmatlab's. An array ``MC.wavelength`` runs each wavelength in
    turn (:mod:`mcmatlab_py.monte_carlo.broadband`).
    """
    M_raw = G.medium_map()  # validates G
    MC.validate(G)
    if is_broadband(MC.wavelength):
        run_broadband(G, MC, M_raw, client=client, power=power)
        return
    MC.spectrum = MC.n_photons_per_wavelength = None  # a broadband run's, if MC held one
    run_validated(G, MC, M_raw, client=client, power=power)


def run_validated(G, MC, M_raw: np.ndarray, *, client=None, power: float = 1.0) -> None:
    """:func:`run_simulation` of one wavelength after ``G`` and ``MC`` were validated."""
    # media at MC.wavelength; media depending on FR, T, FD split into sub-media (new M)
    props = optical_media_properties(G.media, M_raw, MC.wavelength, MC.FR, MC.T, MC.FD)
    M, mua, mus, g, nref = props.M, props.mua, props.mus, props.g, props.n
    seed = MC.seed if MC.seed is not None else int(np.random.SeedSequence().entropy % 2**63)
    n_photons = MC.n_photons_requested
    time_limit = None
    if n_photons is None:
        minutes = MC.simulation_time_requested if MC.simulation_time_requested else 0.1
        time_limit = 60.0 * minutes
    MC.media_properties = props  # before the run: the kernel maps sub-media to media with it
    res = simulate(G, MC, M, mua, mus, g, nref, seed=seed, n_photons=n_photons,
                   time_limit_s=time_limit, client=client)
    store_results(MC, res, M, mua, G.dx * G.dy * G.dz)
    if power != 1.0:
        MC.NA = MC.NA * power
        MC.NFR = MC.NFR * power
    if res.spec is not None and res.spec.active:
        store_outputs(G, MC, res.spec, res.ext, res.paths, res.path_n,
                      res.tally[T_LAUNCHED] / W_ONE / power)
    MC.seed_used = seed
    MC.M = M


def run_broadband(G, MC, M_raw: np.ndarray, *, client=None, power: float = 1.0) -> None:
    """Run a validated broadband ``MC`` (``wavelength`` an array), one wavelength after the
    other, and fill it (see the module docstring). ``power``: W launched in all per W the
    outputs are normalised to, as for :func:`mcmatlab_py.monte_carlo.run_simulation`."""
    check_supported(G, MC)
    wl = MC.wavelength
    n = wl.size
    shares = spectrum(MC)
    powered = np.flatnonzero(shares > 0)
    o = MC._owner_label
    seed = MC.seed if MC.seed is not None else int(np.random.SeedSequence().entropy % 2**63)
    seeds = wavelength_seeds(seed, n)
    if MC.n_photons_requested is not None:
        if MC.n_photons_requested < powered.size:
            raise ValueError(f"{o}.n_photons_requested = {MC.n_photons_requested} is fewer than "
                             f"the {powered.size} wavelengths with light: each needs a photon")
        counts, minutes = photon_split(MC.n_photons_requested, powered.size), None
    else:
        counts = [None] * powered.size
        minutes = (MC.simulation_time_requested or 0.1) / powered.size
    S = MC.source_distribution
    MC.spectrum = shares
    MC.media_properties = stacked_properties(G, M_raw, wl)
    stack = WavelengthStack(n)
    bar = Progress(powered.size, f"{'Fluorescence ' if o == 'FMC' else ''}Monte Carlo, "
                   f"{n} wavelengths", enabled=MC.progress)
    for i, k in enumerate(powered):
        source = np.ascontiguousarray(S[..., k]) if S is not None and S.ndim == 4 else S
        sub = monochromatic(MC, wl[k], counts[i], minutes, seeds[k], source)
        run_validated(G, sub, M_raw, client=client, power=power * shares[k])
        check_energy_balance(sub)
        stack.add(k, sub)
        bar.update(i + 1)
    bar.close()
    stack.store(MC)
    MC.seed_used = seed


def store_results(MC, res: MCResult, M: np.ndarray, mua: np.ndarray, dV: float) -> None:
    """Normalise the raw totals of ``res`` into the MCmatlab outputs of ``MC``."""
    launched = res.tally[T_LAUNCHED] / W_ONE  # = n_photons

    def frac(i):
        return float(res.tally[i] / W_ONE / launched)

    MC.NA = res.absorbed / (launched * dV)
    mua_map = mua[M]
    with np.errstate(divide="ignore", invalid="ignore"):
        MC.NFR = np.where(mua_map > 0, MC.NA / mua_map, 0.0)
    if res.track is not None:  # thin media: the fluence rate from the track length
        MC.NFR = np.where(res.track[M], res.track_length / (launched * dV), MC.NFR)
    # with deposition criteria NA holds only what met them; the balance counts all
    MC.absorbed_fraction = float((res.absorbed.sum() + frac(T_ABSORBED_EXCLUDED) * launched)
                                 / launched)
    MC.specular_reflectance = frac(T_SPECULAR)
    MC.escaped = {"top": frac(T_TOP), "bottom": frac(T_BOTTOM), "sides": frac(T_SIDES)}
    MC.absorbed_outside_fraction = frac(T_OUTSIDE_ABSORBED)
    MC.killed_fraction = frac(T_KILLED)
    MC.missed_fraction = frac(T_MISSED)
    MC.roulette_gain_fraction = frac(T_ROULETTE)
    MC.n_photons = res.n_photons
    MC.simulation_time = res.kernel_seconds
    MC.photons_per_second = res.n_photons / max(res.kernel_seconds, 1e-12)
    # cores actually used by the kernel: below n_threads when the machine is busy
    MC.cores_used = res.kernel_cpu_seconds / max(res.kernel_seconds, 1e-12)
