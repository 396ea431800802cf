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

Broadband (MCmatlab's Example 23; :mod:`mcmatlab_py.monte_carlo.broadband`): with an array of
excitation wavelengths :math:`\\lambda_k` (``MC.NA`` then (nx, ny, nz, n_x), slice k per W
incident in all) and an array of fluorescence wavelengths :math:`\\lambda_j`, each voxel
emits the photons absorbed at every :math:`\\lambda_k` times :math:`QY(\\lambda_k)`, spread
over the :math:`\\lambda_j` by its emission spectrum normalised over them,

.. math:: E_j(\\mathbf{r}) = \\sum_k NA_k(\\mathbf{r})\\, QY(\\lambda_k)\\,
          \\frac{\\lambda_k}{\\lambda_j}\\; \\frac{ES(\\lambda_j)}{\\sum_{j'} ES(\\lambda_{j'})}

(``ES`` not given: equal shares), as MCmatlab's ``runMonteCarlo``. ``FMC.source_distribution``
is then (nx, ny, nz, n_f), ``FMC.emitted_power`` (n_f,), and the fluorescence maps get the
wavelength axis of :mod:`mcmatlab_py.monte_carlo.broadband`, each wavelength run with its own emitters.
With one fluorescence wavelength the spectrum only tells whether a medium emits there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .monte_carlo.broadband import is_broadband
from .monte_carlo.run import run_simulation
from .monte_carlo.simulation import MonteCarloSimulation

__all__ = ["FluorescenceMonteCarloSimulation", "fluorescence_emitters",
           "run_fluorescence_monte_carlo"]


@dataclass
class FluorescenceMonteCarloSimulation(MonteCarloSimulation):
    """Fluorescence Monte Carlo settings and results (MCmatlab's ``model.FMC``).

    The settings and outputs are those of :class:`~mcmatlab_py.monte_carlo.simulation.MonteCarloSimulation`
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

    #: nm, the fluorescence wavelength (MCmatlab's FMC.wavelength); a 1-D array: broadband
    wavelength: float | np.ndarray | None = None
    #: W of fluorescence emitted in the cuboid per W of incident excitation (result); (n_f,),
    #: per fluorescence wavelength, in a broadband run
    emitted_power: float | np.ndarray | None = None

    _owner_label = "FMC"

    def validate(self, G) -> None:
        if self.wavelength is None:
            raise ValueError("FMC.wavelength must be set: the fluorescence wavelength in nm "
                             "(MCmatlab's model.FMC.wavelength)")
        for name, default in (("P", None), ("fr_dep_iterations", 0), ("spectrum_func", None)):
            if getattr(self, name) != default:
                raise ValueError(f"FMC.{name} = {getattr(self, name)!r}: the fluorescence run has "
                                 f"no power or fluence-rate iteration of its own (MCmatlab's "
                                 f"neither; its spectrum is the media's ES); set MC.{name}, "
                                 "the excitation's")
        super().validate(G)


def _check_excitation(G, MC) -> None:
    shape = (G.nx, G.ny, G.nz)
    if MC.NA is None:
        raise ValueError("MC.NA is empty: run the excitation, model.run_monte_carlo(), before "
                         "the fluorescence Monte Carlo")
    if is_broadband(MC.wavelength):
        shape = (*shape, np.size(MC.wavelength))
    if np.shape(MC.NA) != shape:
        raise ValueError(f"MC.NA has shape {np.shape(MC.NA)}, not {shape} ((nx, ny, nz), and "
                         "len(MC.wavelength) in a broadband run): run model.run_monte_carlo() "
                         "again after changing G or MC.wavelength")
    if not MC.deposition_criteria.is_default:
        raise ValueError("MC.deposition_criteria restrict where the excitation is deposited: the "
                         "excitation must be run without them to give the fluorescence emitters")
    if MC.wavelength is None:
        raise ValueError("MC.wavelength is None: the fluorescence power needs the excitation "
                         "wavelength (photon energies, lambda_x / lambda_f)")


def fluorescence_emitters(G, MC, wavelength, M_raw: np.ndarray | None = None, *,
                          state: tuple | None = None) -> np.ndarray:
    """Fluorescence emitted at ``wavelength`` (nm), W/cm^3 per W incident: (nx, ny, nz), or
    (nx, ny, nz, n_f) for an array of n_f fluorescence wavelengths.

    ``MC`` is the run excitation (``NA``, ``wavelength``, one or an array, ``FR``, ``T``,
    ``FD``); each medium with a ``QY`` emits :math:`\\sum_k NA_k \\cdot QY(\\lambda_k) \\cdot
    \\lambda_k / \\lambda_f` (photons emitted per photon absorbed, times their energy ratio),
    spread over an array of fluorescence wavelengths by its ``ES`` normalised over them (see
    the module docstring). ``M_raw``: the media map of ``G`` (computed when not given).
    ``state``: the voxel ``(FR, T, FD)`` seen by ``QY`` and ``ES`` instead of ``MC``'s (a heat
    run's state, the excitation unchanged). A medium whose ``ES`` is 0 at every fluorescence
    wavelength where it absorbed light raises ``ValueError``: all its emission would be put
    where its spectrum says there is none.
    """
    _check_excitation(G, MC)
    M_raw = G.medium_map() if M_raw is None else M_raw
    shape = M_raw.shape
    lam_x = np.atleast_1d(np.asarray(MC.wavelength, dtype=np.float64))
    lam_f = np.atleast_1d(np.asarray(wavelength, dtype=np.float64))
    NA = np.asarray(MC.NA).reshape(*shape, lam_x.size)  # a last axis also for one wavelength
    ratio = lam_x[:, None] / lam_f[None, :]  # (n_x, n_f) photon energy ratios
    out = np.zeros((*shape, lam_f.size), dtype=np.float64)
    for i, medium in enumerate(G.media):
        if medium.QY is None:
            continue
        mask = M_raw == i
        if not mask.any():
            continue
        here = [np.broadcast_to(np.asarray(v, dtype=np.float64), shape)[mask]
                for v in (state if state is not None else (MC.FR, MC.T, MC.FD))]
        # (n_voxels, n_x): absorbed power times QY at each excitation wavelength
        absorbed_qy = np.column_stack([NA[mask, k] * medium.values("QY", lx, *here)
                                       for k, lx in enumerate(lam_x)])
        emitted = absorbed_qy @ ratio  # (n_voxels, n_f): all emitted at each lambda_f
        if medium.ES is None:
            share = np.full(lam_f.size, 1.0 / lam_f.size)
        else:
            es = np.column_stack([medium.values("ES", lf, *here) for lf in lam_f])
            norm = es.sum(axis=1, keepdims=True)
            silent = (norm[:, 0] == 0) & (emitted[:, 0] > 0)
            if silent.any():
                where = (f"FMC.wavelength = {lam_f[0]:g} nm" if lam_f.size == 1 else
                         f"every FMC.wavelength ({lam_f[0]:g}..{lam_f[-1]:g} nm)")
                raise ValueError(
                    f"Medium({medium.name!r}).ES is 0 at {where} where the medium absorbed "
                    "excitation light: it does not emit there; choose fluorescence wavelengths "
                    "inside its emission band")
            share = np.divide(es, norm, out=np.zeros_like(es), where=norm > 0)
        out[mask] = emitted * share
    return out if is_broadband(wavelength) else out[..., 0]


def run_fluorescence_monte_carlo(model, client=None, emitters: np.ndarray | None = None) -> None:
    """Fill ``model.FMC`` from the excitation in ``model.MC`` (see the module docstring).

    ``client``: a ``dask.distributed`` client, as for the excitation. ``emitters``: (nx, ny,
    nz) fluorescence emitted at ``FMC.wavelength``, W/cm^3 per W incident, instead of
    :func:`fluorescence_emitters` of ``model.MC`` (e.g. summed over excitation wavelengths).
    """
    G, MC, FMC = model.G, model.MC, model.FMC
    if not isinstance(FMC, FluorescenceMonteCarloSimulation):
        raise ValueError(f"model.FMC must be a FluorescenceMonteCarloSimulation, got {FMC!r}")
    M_raw = G.medium_map()
    FMC.source_distribution = None  # a result: the last run's emitters
    FMC.validate(G)
    broadband = is_broadband(FMC.wavelength)
    if emitters is None:
        emitters = fluorescence_emitters(G, MC, FMC.wavelength, M_raw)
    else:
        emitters = np.asarray(emitters, dtype=np.float64)
        want = (*M_raw.shape, FMC.wavelength.size) if broadband else M_raw.shape
        if emitters.shape != want or not np.all(np.isfinite(emitters)) or np.any(emitters < 0):
            raise ValueError(f"emitters must be finite, >= 0 and of shape {want} "
                             f"((nx, ny, nz{', len(FMC.wavelength)' if broadband else ''})), got "
                             f"shape {emitters.shape}")
    dV = G.dx * G.dy * G.dz
    per_wavelength = emitters.reshape(-1, emitters.shape[3]).sum(axis=0) * dV if broadband \
        else None
    power = float(emitters.sum() * dV)
    if not power > 0:
        raise ValueError("no fluorescence emitters: no medium with a quantum yield (Medium.QY "
                         "> 0) absorbed excitation light")
    FMC.FR, FMC.T, FMC.FD = MC.FR, MC.T, MC.FD
    FMC.source_distribution = emitters
    run_simulation(G, FMC, client=client, power=power)
    FMC.emitted_power = per_wavelength if broadband else power
