"""What every command shares: exit statuses, threads, the Dask client."""

from __future__ import annotations

from fem.checks import shorten  # re-exported: the one helper of all packages
from mcmatlab_py.model import MAX_SEED  # re-exported: the seeds' limit of the kernels

from .config import run_table

__all__ = ["EXIT_BAD_INPUT", "EXIT_CHECK_FAILED", "EXIT_UNEXPECTED", "MAX_SEED", "apply_threads",
           "close_client", "dask_client", "shorten"]

EXIT_BAD_INPUT = 2
EXIT_CHECK_FAILED = 1  #: validate: a check failed (its report is still written)
EXIT_UNEXPECTED = 1  #: an error that is not the input's fault (a bug: reported in one line)


def dask_client(args, config: dict | None = None):
    """The Dask client of --scheduler / --workers (or the config's [run] table), or None."""
    scheduler, workers = getattr(args, "scheduler", None), getattr(args, "workers", None)
    if scheduler is None and workers is None and config is not None:
        scheduler, workers = run_table(config)
    if scheduler is None and workers is None:
        return None
    if scheduler is not None and workers is not None:
        raise ValueError("give --scheduler or --workers, not both")
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    from mcmatlab_py.distributed import connect

    return connect(scheduler, n_workers=workers)


def close_client(client) -> None:
    """Close the client; a local cluster's worker processes end before this returns."""
    if client is not None:
        from mcmatlab_py.distributed import close

        close(client)


def apply_threads(threads):
    if threads is not None:
        import numba

        from fem.checks import check_number

        threads = check_number("--threads", threads, integer=True, lo=1, hi=1_000_000)
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
