"""Fluorescence Monte Carlo (MCmatlab's ``model.FMC`` and ``runMonteCarlo(model, 'fluorescence')``).

The excitation run (``model.MC``) leaves ``MC.NA``, the absorbed power per volume. In
media with a quantum yield ``Medium.QY`` a part of it comes back as fluorescence, emitted
isotropically at the fluorescence wavelength ``FMC.wavelength``; a second Monte Carlo,
with the same kernel, settings and outputs as the first, carries it through the tissue.

Energy: ``QY`` counts photons (emitted per absorbed, MCmatlab's definition), so the
emitted power is the absorbed power times ``QY`` times the ratio of the photon energies,

.. math:: E(\\mathbf{r}) = NA(\\mathbf{r})\\, QY(\\lambda_x)\\, \\frac{\\lambda_x}{\\lambda_f}
          \\quad [\\mathrm{W/cm^3/W\\ incident}]

(:math:`\\lambda_x` = ``MC.wavelength``, :math:`\\lambda_f` = ``FMC.wavelength``; MCmatlab's
``runMonteCarlo`` does the same). ``E`` is ``FMC.source_distribution``; its volume integral
``FMC.emitted_power``. The maps of the fluorescence run (``FMC.NA``, ``NFR``, ``NI_*``, far
field, collector image) are per W of *incident excitation*, as MCmatlab's; its fractions
(``absorbed_fraction``, ``escaped``, ...) are fractions of the emitted fluorescence.

One fluorescence wavelength per run: the emission spectrum ``Medium.ES`` only tells
whether a medium emits at ``FMC.wavelength``. MCmatlab's broadband runs (arrays of
wavelengths, its Example 23) are not built; ``examples/mcmatlab/ex23_broadband_monte_carlo.py``
sums monochromatic runs instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._strict import NotBuiltError
from .model import MonteCarloSimulation

__all__ = ["FluorescenceMonteCarloSimulation", "fluorescence_emitters",
           "run_fluorescence_monte_carlo"]


@dataclass
class FluorescenceMonteCarloSimulation(MonteCarloSimulation):
    """Fluorescence Monte Carlo settings and results (MCmatlab's ``model.FMC``).

    The settings and outputs are those of :class:`~mcmatlab_py.model.MonteCarloSimulation`
    (``n_photons_requested``, ``simulation_time_requested``, ``boundary_type``,
    ``matched_interfaces``, ``use_light_collector``, ``light_collector``, ``far_field_res``,
    ``calc_normalized_irradiance``, ``n_example_paths``, ...), with these differences:

    * ``wavelength`` (nm) is the fluorescence wavelength and must be set (no default).
    * the emitters are the fluorescent voxels: ``light_source`` is not used (only its focus,
      as the centre of the MCML radial bins), and ``source_distribution`` is a result, the
      emitted fluorescence, W/cm^3 per W of incident excitation.
    * ``FR``, ``T`` and ``FD`` are copied from ``model.MC`` at the run (one voxel state).
    * ``P`` and ``fr_dep_iterations`` are not its settings (MCmatlab's FMC has neither): the
      fluence-rate iteration is the excitation's, ``model.MC``.
    * ``emitted_power``: the fluorescence emitted in the cuboid, W per W incident.
    * the maps are per W of incident excitation, the fractions are of ``emitted_power``
      (see :mod:`mcmatlab_py.fluorescence`).
    """

    #: nm, the fluorescence wavelength (MCmatlab's FMC.wavelength); one number
    wavelength: float | None = None
    #: W of fluorescence emitted in the cuboid per W of incident excitation (result)
    emitted_power: float | None = None

    _owner_label = "FMC"

    def validate(self, G) -> None:
        if self.wavelength is None:
            raise ValueError("FMC.wavelength must be set: the fluorescence wavelength in nm "
                             "(MCmatlab's model.FMC.wavelength)")
        if np.ndim(self.wavelength) > 0:
            raise NotBuiltError(
                "MCmatlab's broadband FMC.wavelength (an array of wavelengths) is not built yet: "
                "run one fluorescence wavelength at a time and weight the runs by the emission "
                "spectrum (examples/mcmatlab/ex23_broadband_monte_carlo.py)")
        for name, default in (("P", None), ("fr_dep_iterations", 0)):
            if getattr(self, name) != default:
                raise ValueError(f"FMC.{name} = {getattr(self, name)!r}: the fluorescence run has "
                                 f"no power or fluence-rate iteration of its own (MCmatlab's "
                                 f"neither); set MC.{name}, the excitation's")
        super().validate(G)


def _check_excitation(G, MC) -> None:
    shape = (G.nx, G.ny, G.nz)
    if MC.NA is None:
        raise ValueError("MC.NA is empty: run the excitation, model.run_monte_carlo(), before "
                         "the fluorescence Monte Carlo")
    if np.shape(MC.NA) != shape:
        raise ValueError(f"MC.NA has shape {np.shape(MC.NA)}, not the geometry's {shape}: run "
                         "model.run_monte_carlo() again after changing G")
    if not MC.deposition_criteria.is_default:
        raise ValueError("MC.deposition_criteria restrict where the excitation is deposited: the "
                         "excitation must be run without them to give the fluorescence emitters")
    if MC.wavelength is None:
        raise ValueError("MC.wavelength is None: the fluorescence power needs the excitation "
                         "wavelength (photon energies, lambda_x / lambda_f)")


def fluorescence_emitters(G, MC, wavelength: float, M_raw: np.ndarray | None = None, *,
                          state: tuple | None = None) -> np.ndarray:
    """(nx, ny, nz) fluorescence emitted at ``wavelength`` (nm), W/cm^3 per W incident.

    ``MC`` is the run excitation (``NA``, ``wavelength``, ``FR``, ``T``, ``FD``); each medium
    with a ``QY`` emits :math:`NA \\cdot QY(\\lambda_x) \\cdot \\lambda_x / \\lambda_f`
    (photons emitted per photon absorbed, times their energy ratio). ``M_raw``: the media
    map of ``G`` (computed when not given). ``state``: the voxel ``(FR, T, FD)`` seen by
    ``QY`` and ``ES`` instead of ``MC``'s (a heat run's state, the excitation unchanged).
    A medium whose ``ES`` is 0 at ``wavelength`` where it absorbed light raises
    ``ValueError``: with one fluorescence wavelength all its emission would be put where
    its spectrum says there is none.
    """
    _check_excitation(G, MC)
    M_raw = G.medium_map() if M_raw is None else M_raw
    shape = M_raw.shape
    lam_x, lam_f = float(MC.wavelength), float(wavelength)
    out = np.zeros(shape, dtype=np.float64)
    for i, medium in enumerate(G.media):
        if medium.QY is None:
            continue
        mask = M_raw == i
        if not mask.any():
            continue
        here = [np.broadcast_to(np.asarray(v, dtype=np.float64), shape)[mask]
                for v in (state if state is not None else (MC.FR, MC.T, MC.FD))]
        qy = medium.values("QY", lam_x, *here)
        emitted = MC.NA[mask] * qy * (lam_x / lam_f)
        if medium.ES is not None:
            es = medium.values("ES", lam_f, *here)
            if np.any((es == 0) & (emitted > 0)):
                raise ValueError(
                    f"Medium({medium.name!r}).ES is 0 at FMC.wavelength = {lam_f:g} nm where the "
                    "medium absorbed excitation light: it does not emit there; choose a "
                    "fluorescence wavelength inside its emission band")
        out[mask] = emitted
    return out


def run_fluorescence_monte_carlo(model, client=None, emitters: np.ndarray | None = None) -> None:
    """Fill ``model.FMC`` from the excitation in ``model.MC`` (see the module docstring).

    ``client``: a ``dask.distributed`` client, as for the excitation. ``emitters``: (nx, ny,
    nz) fluorescence emitted at ``FMC.wavelength``, W/cm^3 per W incident, instead of
    :func:`fluorescence_emitters` of ``model.MC`` (e.g. summed over excitation wavelengths).
    """
    from .monte_carlo import run_simulation

    G, MC, FMC = model.G, model.MC, model.FMC
    if not isinstance(FMC, FluorescenceMonteCarloSimulation):
        raise ValueError(f"model.FMC must be a FluorescenceMonteCarloSimulation, got {FMC!r}")
    M_raw = G.medium_map()
    FMC.validate(G)
    if emitters is None:
        emitters = fluorescence_emitters(G, MC, FMC.wavelength, M_raw)
    else:
        from .light_source import check_source_distribution

        emitters = check_source_distribution(emitters, M_raw.shape)
    power = float(emitters.sum() * G.dx * G.dy * G.dz)
    if not power > 0:
        raise ValueError("no fluorescence emitters: no medium with a quantum yield (Medium.QY "
                         "> 0) absorbed excitation light")
    FMC.FR, FMC.T, FMC.FD = MC.FR, MC.T, MC.FD
    FMC.source_distribution = emitters
    run_simulation(G, FMC, client=client, power=power)
    FMC.emitted_power = power
