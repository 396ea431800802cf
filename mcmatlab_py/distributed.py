"""Run independent pieces of work on a Dask cluster, or in this process when there is none.

Everything tissue-enkf distributes is a list of independent, deterministic tasks whose
results are gathered in order: emulator table points, ranges of Monte Carlo photon
batches, the members of an exact-mode forecast, the cases of a sensitivity sweep, the
data files of a batch identification. :func:`run_tasks` runs such a list on a
``dask.distributed`` client when one is given and in a plain loop otherwise, so the
single-machine path needs no Dask at all and the two paths give the same numbers (each
task carries its own seed; Monte Carlo sums are integers).

Dask is optional (``pip install "tissue-enkf[dist]"``)::

    from mcmatlab_py.distributed import close, connect
    client = connect()                        # a local cluster: one worker process per core
    client = connect("tcp://10.0.0.5:8786")   # an existing scheduler
    emulator = AbsorptionEmulator.build(spec, client=client)
    close(client)                             # its local cluster's processes end here

Workers run their numba kernels on one thread each (``threads_per_worker=1`` and
:func:`numba_threads`), so that a cluster of n single-threaded workers uses n cores
without oversubscription.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from fem.checks import shorten

from .progress import Progress

__all__ = ["TaskError", "close", "connect", "numba_threads", "run_tasks"]


class TaskError(RuntimeError):
    """A task that failed on every attempt; ``index`` is its position in the list."""

    def __init__(self, index: int, error: BaseException):
        super().__init__(f"task {index} failed: {type(error).__name__}: {error}")
        self.index = index
        self.error = error


def _dask():
    try:
        import dask  # noqa: F401
        from dask import distributed
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError("Dask is not installed: pip install \"tissue-enkf[dist]\" "
                          "(dask[distributed]) to use a cluster") from exc
    return distributed


def connect(scheduler: str | Any | None = None, *, n_workers: int | None = None,
            threads_per_worker: int = 1, timeout: float = 30.0, **cluster_kw):
    """A ``dask.distributed.Client``.

    Parameters
    ----------
    scheduler : str, Client or None
        An address (``"tcp://host:8786"``) of a running scheduler, an existing client
        (returned as is), or None for a new local cluster on this machine.
    n_workers : int, optional
        Worker processes of a local cluster (default: the number of cores).
    threads_per_worker : int
        Threads of each local worker (default 1: the numba kernels then run on one
        thread each and n workers use n cores).
    timeout : float
        s to wait for the scheduler at an address; an address where none answers (nothing
        listening, or another service) raises ValueError naming it.

    Close the client with :func:`close`: it waits until a local cluster's processes end.
    """
    distributed = _dask()
    if scheduler is not None and not isinstance(scheduler, str):
        return scheduler
    if isinstance(scheduler, str):
        if not scheduler.strip():
            raise ValueError("scheduler must be an address like 'tcp://host:8786', got ''")
        try:
            return distributed.Client(scheduler, timeout=timeout)
        except (OSError, TimeoutError, MemoryError, ValueError, TypeError) as err:
            # nothing listening (a time-out), or another service, whose first bytes Dask
            # reads as a frame length (3 EiB asked for an HTTP server's reply)
            why = str(err).splitlines()[0] if str(err) else ""
            raise ValueError(f"no Dask scheduler answered at {shorten(scheduler)} within "
                             f"{timeout:g} s ({type(err).__name__}: {shorten(why)})") from None
    n = int(n_workers) if n_workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise ValueError(f"n_workers must be >= 1, got {n_workers!r}")
    cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=threads_per_worker,
                                       processes=True, dashboard_address=None, **cluster_kw)
    return distributed.Client(cluster)


def close(client, timeout: float = 10.0) -> None:
    """Close ``client`` and the local cluster it runs on (one of :func:`connect`), and wait
    until the cluster's worker processes have ended, killing those still running after
    ``timeout`` s: no process the cluster started outlives the caller. A remote
    cluster (a scheduler at an address) is left running."""
    if client is None:
        return
    cluster = getattr(client, "cluster", None)
    pids = [w.pid for w in getattr(cluster, "workers", {}).values()
            if isinstance(getattr(w, "pid", None), int)]
    try:
        client.close()
    finally:
        if cluster is not None:
            cluster.close()
        _wait_for_end(pids, timeout)


def _wait_for_end(pids: list[int], timeout: float) -> None:
    import time

    import psutil  # a dependency of distributed

    procs = []
    for pid in pids:
        with contextlib.suppress(psutil.Error):
            procs.append(psutil.Process(pid))

    def running(p) -> bool:
        try:
            return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
        except psutil.Error:
            return False

    def wait(seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while any(running(p) for p in procs) and time.monotonic() < deadline:
            time.sleep(0.05)

    wait(timeout)
    for p in procs:
        if running(p):
            with contextlib.suppress(psutil.Error):
                p.kill()
    wait(5.0)  # SIGKILL is delivered asynchronously


@contextlib.contextmanager
def numba_threads(n: int):
    """Run numba's parallel kernels on at most ``n`` threads inside the block (restored after)."""
    import numba

    old = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(old)


def _in_worker(fn, item, threads):
    """Task body on a worker: the function with numba limited to the worker's threads."""
    with numba_threads(threads):
        return fn(item)


def run_tasks(fn: Callable[[Any], Any], items: Iterable[Any], *, client=None, retries: int = 2,
              errors: str = "raise", progress: bool = False, label: str = "tasks",
              worker_threads: int = 1,
              on_result: Callable[[int, Any], None] | None = None) -> list:
    """``[fn(item) for item in items]``, on ``client`` when given, in order.

    Parameters
    ----------
    fn : callable
        A picklable function of one item (module-level, or a ``functools.partial`` of one).
    client : dask.distributed.Client, optional
        None runs the tasks here, one after the other.
    retries : int
        Further attempts of a task that raised (a worker that dies mid-task has its
        task rescheduled by Dask on its own, up to the scheduler's
        ``allowed-failures``).
    errors : {"raise", "return"}
        ``"raise"``: the first task that failed on every attempt raises
        :class:`TaskError`. ``"return"``: its place in the list holds the TaskError and
        the other tasks go on (a batch of datasets where one file is bad).
    worker_threads : int
        numba threads inside each task on a worker.
    on_result : callable, optional
        ``on_result(index, result)`` as soon as a task succeeds (in the order they end on
        a cluster), before the others end: a caller keeps what is done when the rest is
        interrupted.
    """
    if errors not in ("raise", "return"):
        raise ValueError(f"errors must be 'raise' or 'return', got {errors!r}")
    if not isinstance(retries, int) or retries < 0:
        raise ValueError(f"retries must be an int >= 0, got {retries!r}")
    items = list(items)
    bar = Progress(len(items), label, enabled=progress)
    out: list = [None] * len(items)
    if client is None:
        for i, item in enumerate(items):
            for attempt in range(retries + 1):
                try:
                    out[i] = fn(item)
                    break
                except Exception as exc:  # noqa: BLE001 - reported per task
                    if attempt == retries:
                        if errors == "raise":
                            bar.close()
                            raise TaskError(i, exc) from exc
                        out[i] = TaskError(i, exc)
            if on_result is not None and not isinstance(out[i], TaskError):
                on_result(i, out[i])
            bar.update(i + 1)
        bar.close()
        return out

    distributed = _dask()
    futures = client.map(_in_worker, [fn] * len(items), items, [worker_threads] * len(items),
                         retries=retries, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    done = 0
    try:
        for fut in distributed.as_completed(futures):
            i = index[fut.key]
            if fut.status == "error":
                exc = fut.exception()
                if errors == "raise":
                    raise TaskError(i, exc) from exc
                out[i] = TaskError(i, exc)
            else:
                out[i] = fut.result()
                if on_result is not None:
                    on_result(i, out[i])
            done += 1
            bar.update(done)
    finally:
        bar.close()
        for f in futures:
            f.release()
    return out


def split_range(n: int, parts: int) -> Sequence[tuple[int, int]]:
    """``parts`` contiguous ``(start, stop)`` ranges covering ``range(n)`` (none empty)."""
    parts = max(1, min(int(parts), int(n)))
    edges = [round(i * n / parts) for i in range(parts + 1)]
    return [(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]
