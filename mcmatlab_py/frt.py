"""Media that depend on fluence rate, temperature and damage, coupled by iteration.

MCmatlab evaluates such media on the voxels and splits them into ``n_bins`` sub-media
(:mod:`mcmatlab_py.geometry.media_bins`). Two loops couple them to the simulations:

* the fluence-rate loop of the Monte Carlo (MCmatlab's ``MC.FRdepIterations``: set
  ``MC.P`` and ``MC.fr_dep_iterations`` and ``model.run_monte_carlo()`` calls
  :func:`fluence_rate_iterations`): run, set ``FR = P * NFR``, run again, with the photon
  count doubling up to the requested one (Example 12);
* the heat simulation (``HS.media_prop_recalc_period``, :class:`MediaCoupling`): every
  so many updates the voxel temperatures and damage ``1 - exp(-Omega)`` are put into
  the media; when a medium's optical sub-media change the Monte Carlo is re-run (with
  ``FR = P * NFR``, iterated as ``MC.fr_dep_iterations`` says), and after it the
  fluorescence Monte Carlo if the model has one (also when only ``QY`` or ``ES``
  depend on the state); the thermal sub-media give new VHC and TC per element
  (Examples 13-15, Test 1), as MCmatlab's ``heatSimParamsRecalc``.
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from .fluorescence import fluorescence_emitters
from .geometry.media import FLUORESCENCE_FIELDS, OPTICAL_FIELDS, THERMAL_FIELDS, check_positive
from .geometry.media_bins import optical_media_properties, thermal_media_properties
from .monte_carlo.broadband import total
from .monte_carlo.run import run_monte_carlo
from .monte_carlo.simulation import check_energy_balance

__all__ = ["MediaCoupling", "fluence_rate_iterations", "same_sub_media"]


def same_sub_media(a, b) -> bool:
    """True if two sets of sub-media (optical or thermal) assign the same values to every voxel."""
    if a is None or b is None or not np.array_equal(a.M, b.M):
        return False
    names = ("mua", "mus", "g", "n") if hasattr(a, "mua") else ("VHC", "TC")
    return all(np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True) for f in names)


def fluence_rate_iterations(model, power: float, n_iterations: int, *, client=None) -> None:
    """MCmatlab's fluence-rate iteration of the Monte Carlo (``MC.FRdepIterations``).

    ``n_iterations`` runs; run ``i`` has ``n_photons_requested / 2**(n_iterations - 1 - i)``
    photons (or that fraction of ``simulation_time_requested``), and between runs
    ``MC.FR = power * MC.NFR``, so that media given as ``f(wavelength, FR, T, FD)`` see
    the fluence rate (W/cm^2) of ``power`` W. The first run sees ``MC.FR`` as given.
    Fills ``model.MC`` as :meth:`Model.run_monte_carlo` does (which calls this with
    ``MC.P`` and ``MC.fr_dep_iterations``); ``client`` as there.
    """
    MC = model.MC
    power = check_positive("fluence_rate_iterations", "power", power, allow_zero=True)
    n_iterations = int(n_iterations)
    if n_iterations < 1:
        raise ValueError(f"n_iterations must be >= 1, got {n_iterations!r}")
    n0, t0 = MC.n_photons_requested, MC.simulation_time_requested
    try:
        for i in range(n_iterations):
            scale = 0.5 ** (n_iterations - 1 - i)
            if n0 is not None:
                MC.n_photons_requested = max(1, int(round(n0 * scale)))
            elif t0 is not None:
                MC.simulation_time_requested = t0 * scale
            run_monte_carlo(model, client=client)
            check_energy_balance(MC)
            if i < n_iterations - 1:
                MC.FR = power * total(MC.NFR)
    finally:
        MC.n_photons_requested, MC.simulation_time_requested = n0, t0


class MediaCoupling:
    """The media of a heat run as the voxel state changes (see the module doc).

    Attributes
    ----------
    thermal : ThermalMediaProperties
        The current thermal sub-media.
    vhc_e, tc_e : (nelements,)
        J cm^-3 K^-1 and W cm^-1 K^-1 per element (the sub-medium of the element's voxel).
    version : int
        Increases whenever ``vhc_e`` or ``tc_e`` change (the steppers are rebuilt).
    thermal_dependent, optical_dependent, fluorescence_dependent : bool
        Whether any medium's thermal (VHC, TC), optical (mua, mus, g) or fluorescence (QY,
        ES) properties depend on the state.
    """

    def __init__(self, model, M: np.ndarray, setup):
        self.model, self.M, self.setup = model, M, setup
        media = model.G.media
        self.thermal_dependent = any(m.depends_on_state(f) for m in media for f in THERMAL_FIELDS)
        self.optical_dependent = any(m.depends_on_state(f) for m in media for f in OPTICAL_FIELDS)
        self.fluorescence_dependent = any(m.depends_on_state(f) for m in media
                                          for f in FLUORESCENCE_FIELDS)
        self.thermal = None
        self.version = 0
        self.vhc_e = self.tc_e = None

    def update_thermal(self, T_vox, Omega_vox) -> bool:
        """Re-evaluate the thermal sub-media at voxel temperatures (deg C) and damage integrals;
        True if they changed (then ``vhc_e``, ``tc_e`` and ``version`` are new)."""
        if self.thermal is not None and not self.thermal_dependent:
            return False
        T = 37.0 if T_vox is None else T_vox
        FD = 0.0 if Omega_vox is None else -np.expm1(-np.asarray(Omega_vox))
        new = thermal_media_properties(self.model.G.media, self.M, T, FD)
        if same_sub_media(new, self.thermal):
            return False
        self.thermal = new
        sub = new.M.ravel()[self.setup.elem_voxel]
        self.vhc_e, self.tc_e = new.VHC[sub], new.TC[sub]
        self.version += 1
        return True

    def update_optics(self, T_vox, Omega_vox, power: float) -> bool:
        """Re-run the Monte Carlo if the optical sub-media at this temperature and damage
        differ from those it last ran on (MCmatlab's ``heatSimParamsRecalc``); True if it ran.

        The new run sees ``MC.T``, ``MC.FD`` of the voxels and ``MC.FR = power * NFR``, and
        with ``MC.fr_dep_iterations`` = n > 0 is iterated n times at ``power`` W as
        :meth:`Model.run_monte_carlo` iterates (MCmatlab re-runs its ``runMonteCarlo``).
        """
        if not self.optical_dependent:
            return False
        model = self.model
        G, MC = model.G, model.MC
        FD = -np.expm1(-np.asarray(Omega_vox))
        new = optical_media_properties(G.media, self.M, MC.wavelength, MC.FR, T_vox, FD)
        if same_sub_media(new, MC.media_properties):
            return False
        MC.T, MC.FD = T_vox, FD
        if MC.NFR is not None:
            MC.FR = power * total(MC.NFR)
        with _quiet(MC):
            fluence_rate_iterations(model, power, max(1, MC.checked_fr_dep_iterations()))
        return True

    def update_fluorescence(self, T_vox, Omega_vox, excitation_ran: bool) -> bool:
        """Re-run the fluorescence Monte Carlo, if the model has run one, when its emitters
        change: after a new excitation (``excitation_ran``), or when ``QY`` or ``ES`` depend
        on the voxel temperature and damage and give new emitters. True if it ran.

        MCmatlab re-runs its fluorescence after every excitation re-run; a run given its
        own ``emitters`` (:meth:`Model.run_fluorescence_monte_carlo`) gets those of
        ``model.MC`` here.
        """
        model = self.model
        MC, FMC = model.MC, model.FMC
        if FMC.simulation_time is None or not (excitation_ran or self.fluorescence_dependent):
            return False
        FD = -np.expm1(-np.asarray(Omega_vox))
        emitters = fluorescence_emitters(model.G, MC, FMC.wavelength, self.M,
                                         state=(MC.FR, T_vox, FD))
        if not excitation_ran and np.array_equal(emitters, FMC.source_distribution):
            return False
        with _quiet(FMC):
            model.run_fluorescence_monte_carlo(emitters=emitters)
        return True


@contextmanager
def _quiet(sim):
    """No progress bar for the runs inside a heat simulation (it has its own)."""
    progress, sim.progress = sim.progress, False
    try:
        yield
    finally:
        sim.progress = progress
