"""The Monte Carlo light transport (MCmatlab's ``model.MC``): settings and results
(:mod:`~mcmatlab_py.monte_carlo.simulation`), the Python layer that runs the numba kernels
(:mod:`~mcmatlab_py.monte_carlo.run`, :mod:`~mcmatlab_py.monte_carlo.host`; on a GPU
:mod:`~mcmatlab_py.monte_carlo.gpu`, on a cluster :mod:`~mcmatlab_py.monte_carlo.cluster`),
broadband runs, optics tables, safety distances and the optional outputs. The kernels
(``_kernel``, ``_batches``, ``_uniform``, ``_steps``, ``_track``, ``_tally``, ``_outputs``,
``_cuda``) take only arrays and scalars."""

from .cluster import batch_range
from .gpu import gpu_available
from .host import (
    FLUSH_PHOTONS,
    THIN,
    HostRun,
    MCResult,
    WideSums,
    kernel_safety,
    optical_arrays,
    track_media,
)
from .run import run_monte_carlo, run_simulation, run_validated, simulate, store_results
from .simulation import EnergyBalanceError, MonteCarloSimulation, check_energy_balance

__all__ = [
    "FLUSH_PHOTONS", "THIN", "EnergyBalanceError", "HostRun", "MCResult", "MonteCarloSimulation",
    "WideSums", "batch_range", "check_energy_balance", "gpu_available", "kernel_safety",
    "optical_arrays", "run_monte_carlo", "run_simulation", "run_validated", "simulate",
    "store_results", "track_media",
]
