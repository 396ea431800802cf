"""The Monte Carlo's settings and results (MCmatlab's ``model.MC``) and the energy-balance
check every run ends with.

Names follow MCmatlab in snake_case (``nPhotonsRequested`` -> ``n_photons_requested``).
Everything is validated when a simulation starts, and a bad value raises a
``ValueError`` that names the field and the value. The runners
(:mod:`mcmatlab_py.monte_carlo.run`, :mod:`mcmatlab_py.fluorescence`,
:mod:`mcmatlab_py.heat`) import these classes; the :class:`~mcmatlab_py.Model` facade
imports the runners.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .._strict import StrictAttributes
from ..geometry.cuboid import Geometry, check_int
from ..geometry.media import check_positive
from ..geometry.media_bins import state_field
from ..light.collector import DepositionCriteria, LightCollector
from ..light.source import LightSource, check_source_distribution
from .broadband import check_wavelengths, is_broadband

__all__ = ["BOUNDARY_TYPES", "MAX_PHOTONS", "MAX_SEED", "EnergyBalanceError",
           "MonteCarloSimulation", "check_energy_balance"]

#: every launched packet is accounted for in fixed point: the balance is 1 to rounding
ENERGY_TOLERANCE = 1e-9
#: seeds are non-negative 64-bit integers (numpy's generators and the kernels' streams)
MAX_SEED = 2**63 - 1
#: packets a run may request: the kernels count them in int64, and a run limited by time
#: counts up to this many (about 2.3e18: years on any machine)
MAX_PHOTONS = np.iinfo(np.int64).max // 4
#: the first of n fluence-rate iterations has 2^-(n-1) of the photons: more is pointless
MAX_FR_DEP_ITERATIONS = 64
BOUNDARY_TYPES = {
    0: "no escaping boundaries",
    1: "all cuboid boundaries escape",
    2: "top boundary escapes",
    3: "top and bottom escape, sides cyclic",
}


class EnergyBalanceError(ValueError):
    """A Monte Carlo run whose energy balance is not 1: its results are not to be used."""


@dataclass
class MonteCarloSimulation(StrictAttributes):
    """Monte Carlo settings and results (MCmatlab's ``model.MC``).

    Results (filled by :meth:`Model.run_monte_carlo`):

    * ``NA``: (nx, ny, nz) absorbed power per volume per W incident, W/cm^3/W.
    * ``NFR``: (nx, ny, nz) normalized fluence rate ``NA / mua``, W/cm^2/W (0 where mua = 0).
    * ``absorbed_fraction``: absorbed inside the cuboid, fraction of the incident power.
    * ``specular_reflectance``: reflected at entry (0 with matched interfaces).
    * ``escaped``: ``{"top", "bottom", "sides"}``, fractions of the incident power.
    * ``absorbed_outside_fraction``, ``killed_fraction``, ``missed_fraction`` (packets
      that never entered: off the top face, emitted outside the cuboid or inside a
      perfect reflector), ``roulette_gain_fraction`` (net weight created by Russian
      roulette; zero in expectation): with these, every launched packet is accounted
      for exactly (``energy_balance`` is 1 up to rounding).
    * ``n_photons``, ``photons_per_second``, ``simulation_time`` (s, kernel only),
      ``cores_used`` (kernel CPU time over wall time: below ``n_threads`` when other
      programs took the cores).

    Optional outputs (:mod:`mcmatlab_py.monte_carlo.outputs`; the plain run computes none of them):

    * ``NI_xpos``, ``NI_xneg``, ``NI_ypos``, ``NI_yneg``, ``NI_zpos``, ``NI_zneg`` (with
      ``calc_normalized_irradiance``): the power leaving through each face pixel per area
      per W incident, W/cm^2/W; shapes (ny, nz), (nx, nz), (nx, ny). ``NI_zneg`` is the
      top face. Faces that cannot escape (``boundary_type``) stay zero.
    * ``far_field`` (res, res) over (theta, phi), the escaping power per bin, W/W (as
      MCmatlab), with bin centres ``far_field_theta`` (0..pi, from +z) and
      ``far_field_phi`` (-pi..pi); directions are those after refraction into ``n_outside``.
    * ``light_collector.image`` (with ``use_light_collector``) and ``n_photons_collected``.
    * ``Rd_r``, ``Tt_r`` (cm^-2) and ``Rd_a``, ``Tt_a`` (sr^-1): MCML's radial and
      exit-angle reflectance and transmittance about the source's focus (with
      ``n_radial_bins``), at ``radial_r`` (cm) and ``exit_angle`` (rad); the last bins
      also hold what lies beyond, as in MCML.
    * ``example_paths`` (4, k): x, y, z (cm) and weight of the first ``n_example_paths``
      packets, each path preceded by a NaN column (MCmatlab's layout).

    Broadband runs (``wavelength`` a 1-D array of n, :mod:`mcmatlab_py.monte_carlo.broadband`): every map
    gets a last axis of n wavelengths, ``NA`` and ``NFR`` (nx, ny, nz, n), ``NI_*`` (.., ..,
    n), ``far_field`` (res, res, n), ``light_collector.image`` with a last axis of n, each
    slice per W incident in all (slice k is ``spectrum[k]`` times a monochromatic run's
    map, so the sum over the last axis is the broadband total, as MCmatlab's); the
    fractions, ``escaped``'s values and ``energy_balance`` are (n,), each a fraction of its
    own wavelength's power (NaN for a wavelength of zero power, not run);
    ``n_photons_per_wavelength`` (n,) and ``spectrum`` (n,) are set.
    """

    n_photons_requested: int | None = None
    simulation_time_requested: float | None = None  #: minutes, used if no photon count
    seed: int | None = None  #: None draws a fresh seed (stored in ``seed_used``)
    matched_interfaces: bool = True
    boundary_type: int = 1
    #: refractive index of the surrounding medium: with ``matched_interfaces = False`` a packet
    #: entering or leaving the cuboid meets Fresnel's reflection and refraction against it.
    #: None: MCmatlab's faces, which neither reflect nor refract (the medium at a face goes on
    #: beyond it): beams enter the top face unrefracted, packets leave every escaping face,
    #: and only those leaving from a medium of n = 1 reach ``far_field`` and the light
    #: collector (MCmatlab's "escaped"); ``NI_*`` counts them all
    n_outside: float | None = 1.0
    russian_roulette: bool = True
    weight_threshold: float = 0.01  #: roulette below this weight (MCmatlab's THRESHOLD)
    roulette_chance: float = 0.1  #: survival probability in roulette (MCmatlab's CHANCE)
    n_threads: int | None = None  #: None: all numba threads
    batch_size: int = 1000  #: photons per random stream (part of what a seed means)
    #: run on an NVIDIA GPU (MCmatlab's useGPU; the ``gpu`` extra): the plain outputs only,
    #: statistically the same as the CPU's, not bit-identical
    use_gpu: bool = False
    gpu_device: int = 0  #: index of the CUDA device used with ``use_gpu`` (MCmatlab's GPUdevice)
    progress: bool = True  #: progress bar on stderr for runs longer than a few seconds
    light_source: LightSource = field(default_factory=LightSource)
    #: nm; selects the value of media given as functions of wavelength (MCmatlab's default
    #: 800 nm); a 1-D array runs each wavelength in turn (broadband, MCmatlab's Example 23):
    #: the maps get a last axis of ``len(wavelength)`` (:mod:`mcmatlab_py.monte_carlo.broadband`)
    wavelength: float | np.ndarray | None = 800.0
    #: broadband runs: the spectral power ``S(wavelength)`` (one number >= 0; not normalised:
    #: the shares ``S / sum(S)`` become ``spectrum``); None: equal power at every wavelength
    spectrum_func: Callable | None = None
    #: W, incident (pulse peak) power, for media that depend on the fluence rate: the runs of
    #: ``fr_dep_iterations`` see ``FR = P * NFR``; for a plane wave, the power on the top face
    P: float | None = None
    #: MCmatlab's FRdepIterations: with n > 0, ``model.run_monte_carlo()`` runs n times with
    #: ``FR = P * NFR`` of the run before, the photon count (or time) doubling up to the
    #: requested one (:func:`mcmatlab_py.frt.fluence_rate_iterations`); needs ``P``
    fr_dep_iterations: int = 0
    # the voxel state seen by media that depend on it: a number or an (nx, ny, nz) array.
    # MCmatlab takes them from MC.P * MC.NFR, HS.T and 1 - exp(-HS.Omega); here they are given
    # (FR: the first run's, MCmatlab's FRinitial; the iterations and the heat run set them).
    FR: float | np.ndarray = 0.0  #: W/cm^2, fluence rate
    T: float | np.ndarray = 37.0  #: deg C, temperature
    FD: float | np.ndarray = 0.0  #: fractional damage, 0..1
    #: (nx, ny, nz) >= 0: emit isotropically from the voxels with these weights instead of
    #: ``light_source`` (MCmatlab's sourceDistribution, example 26); NA is then per W emitted
    source_distribution: np.ndarray | None = None
    #: cm, length scale of the smoothing of interface normals (MCmatlab's default 0.1) used
    #: for Fresnel reflection and refraction when ``matched_interfaces`` is False; 0: Sobel
    #: normals unsmoothed; None: the voxel faces (this port's extra: exact for planar layers)
    smoothing_length_scale: float | None = 0.1
    use_light_collector: bool = False
    light_collector: LightCollector = field(default_factory=LightCollector)
    #: n_photons_requested counts collected packets, not launched ones
    request_collected_photons: bool = False
    deposition_criteria: DepositionCriteria = field(default_factory=DepositionCriteria)
    far_field_res: int = 0  #: 0: no far field
    n_example_paths: int = 0
    calc_normalized_irradiance: bool = False  #: the NI_* maps (MCmatlab computes them always)
    #: NFR in thin media from the track length (MCmatlab's calcNormalizedFluenceRate, default
    #: True); False skips that tally, which runs a block of air up to 15x faster: NFR is then
    #: NA / mua everywhere (zero where no packet interacts)
    calc_normalized_fluence_rate: bool = True
    n_radial_bins: int = 0  #: MCML's nr; 0: no radial and angular tallies
    radial_bin_size: float = 0.01  #: cm, MCML's dr
    n_angle_bins: int = 30  #: MCML's na, over exit angles 0..pi/2

    # results
    NA: np.ndarray | None = None
    NFR: np.ndarray | None = None
    absorbed_fraction: float | None = None
    specular_reflectance: float | None = None
    escaped: dict | None = None
    absorbed_outside_fraction: float | None = None
    killed_fraction: float | None = None
    missed_fraction: float | None = None
    roulette_gain_fraction: float | None = None
    n_photons: int | None = None
    #: broadband runs: (n,) the power share of each wavelength (sums to 1; MCmatlab's spectrum)
    spectrum: np.ndarray | None = None
    #: broadband runs: (n,) packets launched at each wavelength (``n_photons`` is their sum)
    n_photons_per_wavelength: np.ndarray | None = None
    photons_per_second: float | None = None
    simulation_time: float | None = None
    cores_used: float | None = None
    seed_used: int | None = None
    #: (nx, ny, nz) int32 sub-medium index the kernel ran on (``G``'s map unless media were split)
    M: np.ndarray | None = None
    #: the sub-media's mua, mus, g, n (:class:`mcmatlab_py.geometry.media_bins.OpticalMediaProperties`)
    media_properties: object = None
    NI_xpos: np.ndarray | None = None
    NI_xneg: np.ndarray | None = None
    NI_ypos: np.ndarray | None = None
    NI_yneg: np.ndarray | None = None
    NI_zpos: np.ndarray | None = None
    NI_zneg: np.ndarray | None = None
    far_field: np.ndarray | None = None
    far_field_theta: np.ndarray | None = None
    far_field_phi: np.ndarray | None = None
    n_photons_collected: int | None = None
    Rd_r: np.ndarray | None = None
    Tt_r: np.ndarray | None = None
    Rd_a: np.ndarray | None = None
    Tt_a: np.ndarray | None = None
    radial_r: np.ndarray | None = None
    exit_angle: np.ndarray | None = None
    example_paths: np.ndarray | None = None

    _owner_label = "MC"
    _renamed = {"LS": "light_source", "normalizedAbsorption": "NA",
                "normalizedFluenceRate": "NFR", "silentMode": "progress (= not silentMode)",
                "calcNFR": "calc_normalized_fluence_rate",
                "useAllCPUs": "n_threads", "LC": "light_collector",
                "FRinitial": "FR (the fluence rate the first run sees)",
                **{f"normalizedIrradiance_{s}": f"NI_{s}"
                   for s in ("xpos", "xneg", "ypos", "yneg", "zpos", "zneg")}}
    _not_built = (
        "interfaceNormals", "CDFs",
    )

    @property
    def energy_balance(self) -> float | np.ndarray:
        """(absorbed + escaped + specular + outside + killed + missed - roulette gain), ~1;
        (n,) for a broadband run, one per wavelength (NaN for one of zero power, not run)."""
        return (self.absorbed_fraction + sum(self.escaped.values()) + self.specular_reflectance
                + self.absorbed_outside_fraction + self.killed_fraction + self.missed_fraction
                - self.roulette_gain_fraction)

    def validate(self, G: Geometry) -> None:
        o = self._owner_label  # "MC", or "FMC" for the fluorescence run
        if self.n_photons_requested is not None:
            self.n_photons_requested = check_int(o, "n_photons_requested",
                                                  self.n_photons_requested, maximum=MAX_PHOTONS)
        if self.simulation_time_requested is not None:
            self.simulation_time_requested = check_positive(
                o, "simulation_time_requested", self.simulation_time_requested)
        if self.boundary_type not in BOUNDARY_TYPES:
            raise ValueError(
                f"{o}.boundary_type must be one of {sorted(BOUNDARY_TYPES)}, "
                f"got {self.boundary_type!r}")
        if self.n_outside is not None:
            n_out = check_positive(o, "n_outside", self.n_outside)
            if n_out < 1:
                raise ValueError(f"{o}.n_outside must be >= 1 or None (MCmatlab's faces), got "
                                 f"{self.n_outside!r}")
            self.n_outside = n_out
        self.weight_threshold = check_positive(o, "weight_threshold", self.weight_threshold)
        c = check_positive(o, "roulette_chance", self.roulette_chance)
        if c >= 1:
            raise ValueError(f"{o}.roulette_chance must be in (0, 1), got {self.roulette_chance!r}")
        self.batch_size = check_int(o, "batch_size", self.batch_size)
        if self.n_threads is not None:
            self.n_threads = check_int(o, "n_threads", self.n_threads)
        if self.seed is not None:
            self.seed = check_int(o, "seed", self.seed, minimum=0, maximum=MAX_SEED)
        if not isinstance(self.use_gpu, bool | np.bool_):
            raise ValueError(f"{o}.use_gpu must be True or False, got {self.use_gpu!r}")
        if not isinstance(self.calc_normalized_fluence_rate, bool | np.bool_):
            raise ValueError(f"{o}.calc_normalized_fluence_rate must be True or False, got "
                             f"{self.calc_normalized_fluence_rate!r}")
        self.gpu_device = check_int(o, "gpu_device", self.gpu_device, minimum=0)
        if not isinstance(self.light_source, LightSource):
            raise ValueError(f"{o}.light_source must be a LightSource, got {self.light_source!r}")
        self.light_source.validate(G)
        self.source_distribution = check_source_distribution(
            self.source_distribution, (G.nx, G.ny, G.nz), np.size(self.wavelength)
            if is_broadband(self.wavelength) else None, owner=o)
        if self.smoothing_length_scale is not None:
            self.smoothing_length_scale = check_positive(o, "smoothing_length_scale",
                                                         self.smoothing_length_scale,
                                                         allow_zero=True)
        if self.wavelength is not None:
            self.wavelength = check_wavelengths(o, self.wavelength)
        if self.spectrum_func is not None and not callable(self.spectrum_func):
            raise ValueError(f"{o}.spectrum_func must be a function of the wavelength (nm) or "
                             f"None, got {self.spectrum_func!r}")
        self._validate_outputs(G)
        self.checked_fr_dep_iterations()
        shape = (G.nx, G.ny, G.nz)
        self.FR = state_field(f"{o}.FR", self.FR, shape, lower=0.0)
        self.T = state_field(f"{o}.T", self.T, shape)
        self.FD = state_field(f"{o}.FD", self.FD, shape, lower=0.0, upper=1.0)

    def checked_fr_dep_iterations(self) -> int:
        """``fr_dep_iterations`` validated (with ``P``, which the iterations need)."""
        o = self._owner_label
        if self.P is not None:
            self.P = check_positive(o, "P", self.P)
        n = self.fr_dep_iterations = check_int(o, "fr_dep_iterations", self.fr_dep_iterations,
                                                minimum=0, maximum=MAX_FR_DEP_ITERATIONS)
        if n and self.P is None:
            # MCmatlab 3 stopped here too; MCmatlab 4 silently takes 1 W
            raise ValueError(f"{o}.fr_dep_iterations = {n} but {o}.P is None: the iterations give "
                             f"the media the fluence rate FR = P * NFR, so give {o}.P, the "
                             "incident power in W")
        return n

    def _validate_outputs(self, G: Geometry) -> None:
        o = self._owner_label
        for name in ("far_field_res", "n_example_paths", "n_radial_bins"):
            setattr(self, name, check_int(o, name, getattr(self, name), minimum=0))
        if self.n_radial_bins:
            self.n_angle_bins = check_int(o, "n_angle_bins", self.n_angle_bins)
            self.radial_bin_size = check_positive(o, "radial_bin_size", self.radial_bin_size)
        if self.boundary_type == 0:
            for name in ("far_field_res", "use_light_collector", "calc_normalized_irradiance",
                         "n_radial_bins"):
                if getattr(self, name):
                    raise ValueError(f"{o}.{name} is set but {o}.boundary_type = 0 lets no light "
                                     "escape: change one of them")
        if not isinstance(self.light_collector, LightCollector):
            raise ValueError(f"{o}.light_collector must be a LightCollector, got "
                             f"{self.light_collector!r}")
        if not isinstance(self.deposition_criteria, DepositionCriteria):
            raise ValueError(f"{o}.deposition_criteria must be a DepositionCriteria, got "
                             f"{self.deposition_criteria!r}")
        if self.use_light_collector:
            self.light_collector.validate(G)
        if self.request_collected_photons and not self.use_light_collector:
            raise ValueError(f"{o}.request_collected_photons is True but {o}.use_light_collector "
                             "is False")
        if self.request_collected_photons and self.n_photons_requested is None:
            raise ValueError(f"{o}.request_collected_photons needs {o}.n_photons_requested (the "
                             "number of packets to collect)")
        self.deposition_criteria.validate(self.use_light_collector)


def check_energy_balance(sim: MonteCarloSimulation) -> None:
    """Raise :class:`EnergyBalanceError` unless the run's energy balance is 1 to rounding
    (at every wavelength of a broadband run that ran)."""
    balance = np.atleast_1d(np.asarray(sim.energy_balance, dtype=np.float64))
    absorbed = np.atleast_1d(np.asarray(sim.absorbed_fraction, dtype=np.float64))
    bad = ~np.isnan(balance) & ~(np.abs(balance - 1.0) <= ENERGY_TOLERANCE)
    if np.isnan(balance).all() or bad.any():
        k = int(np.flatnonzero(bad)[0]) if bad.any() else 0
        at = f" at {sim._owner_label}.wavelength[{k}]" if is_broadband(sim.wavelength) else ""
        raise EnergyBalanceError(
            f"the Monte Carlo lost track of its energy{at}: absorbed + escaped + the rest = "
            f"{float(balance[k])!r} of the launched power, not 1 (absorbed fraction "
            f"{float(absorbed[k])!r}); the inputs are beyond what the kernel resolves: check "
            "the media's mua and mus and the geometry")
