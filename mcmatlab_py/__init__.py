"""mcmatlab_py: a Python port of the MCmatlab workflow (Marti et al. 2018).

Describe a voxel cuboid of tissue (``model.G``), run Monte Carlo light transport
(``model.MC``), then the heat simulation (``model.HS``)::

    from mcmatlab_py import Model, Medium
    model = Model()
    ...
    model = model.run_monte_carlo()

Glossary
--------
mua, mus
    absorption and scattering coefficients, cm^-1
g
    Henyey-Greenstein anisotropy factor (mean cosine of scattering)
n
    refractive index
VHC
    volumetric heat capacity, J cm^-3 K^-1
TC
    thermal conductivity, W cm^-1 K^-1
NA
    normalized absorption, absorbed power per volume per W incident, W cm^-3 W^-1
NFR
    normalized fluence rate, W cm^-2 W^-1
E, A
    Arrhenius activation energy (J/mol) and frequency factor (1/s)
wavelength
    nm (``MC.wavelength``), selects media given as functions of wavelength; an array
    of them runs a broadband simulation (:mod:`mcmatlab_py.monte_carlo.broadband`)
spectrum
    power share of each wavelength of a broadband run (``MC.spectrum_func``
    normalised)
FR, T, FD
    fluence rate (W cm^-2), temperature (deg C), fractional damage (0..1)
n_bins
    sub-media a FR-, T- or FD-dependent medium is split into
theta, phi
    polar angle and azimuth of a light source's axis, rad (theta = 0: along +z)
psi
    rotation of an X/Y beam about its axis, rad
FPID, AID
    focal-plane and angular intensity distributions of a beam (MCmatlab's
    abbreviations; ``focal_plane_intensity_distribution``,
    ``angular_intensity_distribution``)
NI_xpos .. NI_zneg
    normalized irradiance leaving each cuboid face, W cm^-2 W^-1
LC
    light collector (``MC.light_collector``): a lens (focal length f) or a fiber
    (f = inf)
DC
    deposition criteria (``MC.deposition_criteria``)
Rd_r, Tt_r, Rd_a, Tt_a
    MCML's radial (cm^-2) and exit-angle (sr^-1) reflectance, transmittance
FMC
    fluorescence Monte Carlo (``model.FMC``), run after the excitation ``model.MC``
QY
    fluorescence quantum yield, photons emitted per photon absorbed (``Medium.QY``)
ES
    emission spectrum of a fluorescent medium, not normalised (``Medium.ES``)
"""

from ._strict import NotBuiltError
from .fluorescence import FluorescenceMonteCarloSimulation
from .geometry.media import Medium
from .geometry.spectra import calc_mua, calc_mus
from .geometry.stl import find_inside_voxels
from .light.source import IntensityDistribution
from .model import Geometry, LightSource, Model, MonteCarloSimulation

__all__ = ["FluorescenceMonteCarloSimulation", "Geometry", "IntensityDistribution",
           "LightSource", "Medium", "Model", "MonteCarloSimulation", "NotBuiltError", "calc_mua",
           "calc_mus", "find_inside_voxels"]
