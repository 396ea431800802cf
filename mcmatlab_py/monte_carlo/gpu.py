"""The plain Monte Carlo on a CUDA GPU (MCmatlab's ``MC.useGPU``): the Python layer of
the kernel :mod:`mcmatlab_py.monte_carlo._cuda`."""

from __future__ import annotations

import time

import numba
import numpy as np

from .._strict import NotBuiltError
from ..progress import Progress
from ._tally import N_TALLY, W_ONE
from .host import FLUSH_PHOTONS, MCResult, WideSums, kernel_args, parent_media, track_length, track_media
from .outputs import output_spec
from .simulation import MAX_PHOTONS

__all__ = ["gpu_available", "simulate_gpu"]


def gpu_available() -> bool:
    """Whether ``MC.use_gpu = True`` can run here: the ``numba-cuda`` package (the ``gpu``
    extra) and a CUDA GPU, or numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1`` set before
    ``numba.cuda`` is first imported)."""
    try:
        from numba import cuda
    except ImportError:
        return False
    return bool(cuda.is_available())


def simulate_gpu(G, MC, M, mua, mus, g, nref, *, seed, n_photons, time_limit_s,
                  label) -> MCResult:
    """The plain run on a CUDA GPU (:mod:`mcmatlab_py.monte_carlo._cuda`): the same totals as
    :func:`simulate`, statistically (each CUDA thread runs its own random stream)."""
    spec = output_spec(G, MC, len(mua), parent_media(G, MC, len(mua)))
    if spec.active:
        raise NotBuiltError(
            "MC.use_gpu runs the plain Monte Carlo only (NA, NFR, the escaped and absorbed "
            "fractions): the optional outputs (normalized irradiance, far field, light "
            "collector, radial bins, deposition criteria, example paths) are not built for the "
            "GPU; set MC.use_gpu = False for them")
    if MC.n_outside is None and not MC.matched_interfaces:
        raise NotBuiltError(
            "MC.use_gpu with MC.n_outside = None (MCmatlab's faces) is not built for the GPU: "
            "set MC.n_outside to a refractive index, or MC.use_gpu = False")
    if not gpu_available():
        raise RuntimeError(
            "MC.use_gpu = True needs numba-cuda (pip install 'tissue-enkf[gpu]') and an NVIDIA "
            "GPU with its driver; none was found (numba.cuda.is_available() is False). "
            "Set MC.use_gpu = False to run on the CPU")
    from numba import cuda

    from . import _cuda as KC

    if not numba.config.ENABLE_CUDASIM:
        cuda.select_device(int(MC.gpu_device))
    n_total = n_photons if n_photons is not None else MAX_PHOTONS
    args = list(kernel_args(G, MC, M, mua, mus, g, nref, seed, n_total))
    if args[22] is None:  # phase_idx: the CUDA kernel takes an array (-1: Henyey-Greenstein)
        args[22] = np.full(len(mua), -1, dtype=np.int32)
    per = KC.PHOTONS_PER_THREAD
    args[27] = per
    track = track_media(args, spec, MC.calc_normalized_fluence_rate)
    if track is not None:
        args[5] = -1  # uniform_medium: the track-length tally cuts paths at voxel faces
    args = [cuda.to_device(a) if isinstance(a, np.ndarray) else a for a in args]
    nvox = M.size
    acc = cuda.to_device(np.zeros(nvox, dtype=np.int64))
    tally = cuda.to_device(np.zeros(N_TALLY, dtype=np.int64))
    flu = cuda.to_device(np.zeros(nvox if track is not None else 1, dtype=np.int64))
    tracked = cuda.to_device(track if track is not None else np.zeros(len(mua), dtype=np.bool_))
    n_streams = -(-n_total // per) if n_photons is not None else None
    tpb = KC.THREADS_PER_BLOCK
    # compile outside the timed rounds (no streams: every thread returns at once); a
    # time-limited run would otherwise spend its minutes on the JIT (about 15 s on an H200)
    try:
        KC.transport_streams[1, tpb](*args, 0, 0, acc, tally, tracked, flu)
    except AttributeError as e:  # numba-cuda 0.30 compiles against numpy's np.row_stack
        if "row_stack" not in str(e):
            raise
        raise RuntimeError(
            f"MC.use_gpu: numba-cuda cannot compile the kernel with numpy {np.__version__} "
            f"({e}; numpy 2.5 removed np.row_stack): install numpy < 2.5 "
            "(pip install 'tissue-enkf[gpu]' pins it) or a numba-cuda that supports it") from e
    cuda.synchronize()
    bar = Progress(n_streams if n_streams is not None else time_limit_s, label,
                   enabled=MC.progress)
    sums, pending = WideSums(), 0
    named = [("acc", acc), ("tally", tally)] + ([("flu", flu)] if track is not None else [])
    zeros = {name: np.zeros(arr.shape, dtype=np.int64) for name, arr in named}

    def flush():  # move the int64 sums into the wide ones before they can overflow
        for name, arr in named:
            sums.add(name, arr.copy_to_host())
            arr.copy_to_device(zeros[name])

    max_streams = max(tpb, FLUSH_PHOTONS // per)
    done, per_round = 0, 64 * tpb
    kernel_s = kernel_cpu = 0.0
    while True:
        per_round = min(per_round, max_streams)
        todo = per_round if n_streams is None else min(per_round, n_streams - done)
        t0, c0 = time.perf_counter(), time.process_time()
        KC.transport_streams[-(-todo // tpb), tpb](*args, done, todo, acc, tally, tracked, flu)
        cuda.synchronize()
        dt = time.perf_counter() - t0
        kernel_s += dt
        kernel_cpu += time.process_time() - c0
        done += todo
        pending += todo * per
        if pending >= FLUSH_PHOTONS:
            flush()
            pending = 0
        bar.update(done if n_streams is not None else kernel_s,
                   f"{min(done * per, n_total) / max(kernel_s, 1e-9):.3g} photons/s")
        if (n_streams is not None and done >= n_streams) or (
                n_streams is None and kernel_s >= time_limit_s):
            break
        # rounds of about half a second
        per_round = int(min(max(tpb, 0.5 * todo / max(dt, 1e-6)), 16 * per_round))
        if n_streams is None:
            per_round = min(per_round, int((time_limit_s - kernel_s) * todo / max(dt, 1e-6)) + tpb)
    bar.close()
    flush()
    n_done = n_photons if n_photons is not None else done * per
    length = track_length(sums, track, (G.dx, G.dy, G.dz), M.shape)
    return MCResult(absorbed=sums.value("acc").reshape(M.shape) / W_ONE,
                    tally=sums.value("tally"), n_photons=int(n_done), kernel_seconds=kernel_s,
                    kernel_cpu_seconds=kernel_cpu, spec=spec, track=track, track_length=length)
