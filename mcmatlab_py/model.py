"""The MCmatlab-style model: ``model.G`` (geometry), ``model.MC`` (Monte Carlo),
``model.FMC`` (fluorescence Monte Carlo), ``model.HS`` (heat).

Users set attributes, then call ``model = model.run_monte_carlo()`` as in MCmatlab.
:class:`Model` is the facade on top: it holds the four settings classes and calls the
runners (:mod:`mcmatlab_py.monte_carlo`, :mod:`mcmatlab_py.fluorescence`,
:mod:`mcmatlab_py.frt`, :mod:`mcmatlab_py.heat`); nothing below imports it.
"""

from __future__ import annotations

from . import fluorescence as _fluorescence
from . import frt as _frt
from ._strict import StrictAttributes
from .fluorescence import FluorescenceMonteCarloSimulation
from .geometry.cuboid import Geometry
from .heat import run as _heat_run
from .heat.budget import check_heat
from .heat.simulation import HeatSimulation
from .light.source import SOURCE_TYPES, LightSource  # noqa: F401  (re-exported)
from .monte_carlo import run as _mc_run
from .monte_carlo.simulation import (  # noqa: F401  (re-exported: the model's classes)
    MAX_PHOTONS,
    MAX_SEED,
    EnergyBalanceError,
    MonteCarloSimulation,
    check_energy_balance,
)

__all__ = ["MAX_PHOTONS", "MAX_SEED", "EnergyBalanceError", "Geometry", "LightSource", "Model",
           "MonteCarloSimulation", "check_energy_balance"]


class Model(StrictAttributes):
    """An MCmatlab model: ``G`` geometry, ``MC`` Monte Carlo, ``HS`` heat simulation.

    Examples
    --------
    >>> from mcmatlab_py import Model, Medium
    >>> model = Model()
    >>> model.G.nx, model.G.ny, model.G.nz = 20, 20, 10
    >>> model.G.Lx, model.G.Ly, model.G.Lz = 0.5, 0.5, 0.25
    >>> model.G.media = [Medium("standard tissue", mua=1.0, mus=100.0, g=0.9, n=1.3)]
    >>> model.MC.n_photons_requested = 10_000
    >>> model.MC.seed = 1
    >>> model.MC.light_source.source_type = "tophat"
    >>> model.MC.light_source.radius = 0.1
    >>> model = model.run_monte_carlo()
    >>> model.MC.NA.shape
    (20, 20, 10)
    """

    _owner_label = "model"
    _extra_attributes = ("G", "MC", "FMC", "HS")

    def __init__(self):
        self.G = Geometry()
        self.MC = MonteCarloSimulation()
        self.FMC = FluorescenceMonteCarloSimulation()
        self.HS = HeatSimulation()

    def reset(self, what: str | None = None) -> Model:
        """MCmatlab's ``model = reset(model, what)``: ``what`` ("G", "MC", "FMC" or "HS") back
        to its defaults, settings and results; without ``what``, all four (a new model).
        Returns ``self``. (``model.HS.reset()`` forgets only the heat results, keeping the
        settings, to start a heat run afresh.)"""
        fresh = {"G": Geometry, "MC": MonteCarloSimulation,
                 "FMC": FluorescenceMonteCarloSimulation, "HS": HeatSimulation}
        if what is not None and what not in fresh:
            raise ValueError(f"model.reset takes 'G', 'MC', 'FMC', 'HS' or None (all), got "
                             f"{what!r}")
        for name in fresh if what is None else (what,):
            setattr(self, name, fresh[name]())
        return self

    def run_monte_carlo(self, kind: str = "excitation", *, client=None) -> Model:
        """Run the Monte Carlo light transport; fills ``self.MC`` and returns ``self``.

        ``kind``: ``"excitation"`` (``self.MC``) or ``"fluorescence"`` (``self.FMC``, from the
        excitation's absorption in media with ``QY``: MCmatlab's
        ``runMonteCarlo(model, 'fluorescence')``, :meth:`run_fluorescence_monte_carlo`).
        ``client``: a ``dask.distributed`` client (:func:`mcmatlab_py.distributed.connect`)
        to spread the photon batches over a cluster; the same seed gives the same ``NA``.
        With ``MC.fr_dep_iterations`` = n > 0 the excitation is run n times, each seeing the
        fluence rate ``MC.P * NFR`` of the one before (MCmatlab's ``FRdepIterations``,
        :func:`mcmatlab_py.frt.fluence_rate_iterations`).
        """
        if kind == "fluorescence":
            return self.run_fluorescence_monte_carlo(client=client)
        if kind != "excitation":
            raise ValueError(f"model.run_monte_carlo takes 'excitation' or 'fluorescence', "
                             f"got {kind!r}")
        n = self.MC.checked_fr_dep_iterations()
        if n:
            _frt.fluence_rate_iterations(self, self.MC.P, n, client=client)
        else:
            _mc_run.run_monte_carlo(self, client=client)
            check_energy_balance(self.MC)
        return self

    def run_fluorescence_monte_carlo(self, *, client=None, emitters=None) -> Model:
        """Run the fluorescence Monte Carlo (:mod:`mcmatlab_py.fluorescence`) after the
        excitation; fills ``self.FMC`` and returns ``self``. ``emitters``: the (nx, ny, nz)
        fluorescence emitted, W/cm^3 per W incident, instead of that of ``self.MC``."""
        _fluorescence.run_fluorescence_monte_carlo(self, client=client, emitters=emitters)
        check_energy_balance(self.FMC)
        return self

    def simulate_heat_distribution(self) -> Model:
        """Run the heat simulation driven by ``MC.NA``; fills ``self.HS`` and returns ``self``.

        A run that cannot fit or finish is refused first, naming the field and its value
        (:func:`mcmatlab_py.heat.check_heat`: more than 10^6 time steps from ``HS.dt``
        and the durations, a mesh of ``HS.mesh_divisions`` larger than the memory)."""
        self.HS.validate(self.G)
        check_heat(self.G, self.HS)
        _heat_run.simulate_heat_distribution(self)
        return self

    def plot(self, what: str | None = None, path=None, *, interactive: bool = False) -> dict:
        """MCmatlab's ``plot(model, what)`` for ``what`` in "G", "MC", "FMC", "HS": returns
        ``{name: Figure}``, saved as ``<stem>_<name>.png`` next to ``path`` when given
        (:func:`mcmatlab_py.plotting.plot_model`). Without ``what`` (MCmatlab's
        ``plot(model)``): every stage that has outputs, named ``"<stage>_<name>"``."""
        from .plotting import plot_model  # an edge package: imported when used

        return plot_model(self, what, path, interactive=interactive)
