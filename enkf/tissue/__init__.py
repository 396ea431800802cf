r"""Tissue identification: the augmented EnKF of Arnold & Fichera driven by the laser-tissue model.

State of member :math:`n`: the temperature at every node of the filter's coarse
mesh (by default 20 x 20 x 10 voxels, 4,851 nodes) and
:math:`\theta = (\mu_a, \mu_s)` or :math:`(\mu_a, \mu_s, c_v, k)`, held as
logarithms so they stay positive. The forecast of one sensor interval is one
implicit heat step (:class:`fem.HeatStepper`) with the member's own absorbed
power map ``P(t) * NA(mua_n, mus_n)`` (from the absorption emulator, or direct
Monte Carlo in exact mode) and its own heat capacity and conductivity (per-member
scales, no refactorization). The observation is the temperature at the sensor
point(s), interpolated with the P1 basis.

Defaults and their reasons (see also docs/enkf.md):

* ``N = 50``; priors uniform between 0.5 and 2 times the nominal values; initial
  temperature known; ``D`` the sensor noise variance: as the paper.
* ``model_noise_std = 0.002`` deg C per step (``C = 0.002^2 I``): the coarse model
  is close to the truth, and a larger white nodal noise only makes the members
  rough and lets them disagree with data through noise rather than physics.
* random walk on log parameters (``E``), per 0.1 s step: ``0.002`` when the
  parameters are believed constant; when they may drift, ``0.03`` for log mua and
  ``0.06`` for log mus (the paper's ramps are 0.028 and 0.032 per step in log
  units; mus, weakly identified, needs the wider walk to be followed at all).

Modules: :mod:`~enkf.tissue.parameters` (names, units, ranges, tracked depths: one table
each), :mod:`~enkf.tissue.absorption` (the :class:`Absorption` protocol of the emulator
and the exact mode), :mod:`~enkf.tissue.setup` (:class:`TissueFilterSetup` and its parts:
:class:`ParameterModel`, :class:`Sensors`, :class:`ModelError`, :class:`HeatModel`,
:class:`SmootherRestarts`, and the drift bank's settings :class:`DriftBank`),
:mod:`~enkf.tissue.forward` (the forecast and the observation operator),
:mod:`~enkf.tissue.coagulation` (optics that follow each member's own damage),
:mod:`~enkf.tissue.pieces` (the filter's pieces built from a setup: :func:`assemble`),
:mod:`~enkf.tissue.estimates` (:class:`TissueEstimates`),
:mod:`~enkf.tissue.identify` (:func:`identify`), :mod:`~enkf.tissue.restart` (restarts from
the smoother), :mod:`~enkf.tissue.drift` (the drift bank's run), :mod:`~enkf.tissue.smooth`
(constant optics from a whole window: :func:`smooth_constant`), :mod:`~enkf.tissue.online` (one reading
at a time), :mod:`~enkf.tissue.image` (a thermal camera), :mod:`~enkf.tissue.risk`
(damage-risk maps) and :mod:`~enkf.tissue.outputs` (files every run writes).
"""

from .absorption import Absorption, FunctionAbsorption, as_absorption
from .coagulation import Coagulation, CoagulationForwardModel, coagulated_fraction, effective_optics
from .estimates import TissueEstimates
from .forward import TissueForwardModel, observation_operator
from .identify import identify
from .image import ThermalImage
from .model_error import StructuredModelError
from .online import OnlineEstimate, OnlineIdentifier
from .parameters import (
    BEAM_NAMES,
    COAGULATION_NAMES,
    ESTIMATES,
    PARAMETER_LABELS,
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    SECOND_MEDIUM_NAMES,
    TRACKED_DEPTHS,
    column,
    default_bounds,
    parameter_names,
    tracked_points,
)
from .pieces import FilterPieces, assemble
from .risk import RiskTracker
from .setup import (
    DriftBank,
    HeatModel,
    ModelError,
    ParameterModel,
    Sensors,
    SmootherRestarts,
    TissueFilterSetup,
)
from .smooth import SmootherEstimates, heated_time, smooth_constant, smooth_drifting

__all__ = [
    "Absorption",
    "BEAM_NAMES",
    "SmootherEstimates",
    "COAGULATION_NAMES",
    "Coagulation",
    "CoagulationForwardModel",
    "DriftBank",
    "ESTIMATES",
    "FilterPieces",
    "FunctionAbsorption",
    "HeatModel",
    "ModelError",
    "OnlineEstimate",
    "OnlineIdentifier",
    "PARAMETER_LABELS",
    "PARAMETER_NAMES",
    "ParameterModel",
    "PARAMETER_UNITS",
    "RiskTracker",
    "SECOND_MEDIUM_NAMES",
    "Sensors",
    "SmootherRestarts",
    "StructuredModelError",
    "TRACKED_DEPTHS",
    "ThermalImage",
    "TissueEstimates",
    "TissueFilterSetup",
    "TissueForwardModel",
    "as_absorption",
    "assemble",
    "coagulated_fraction",
    "column",
    "default_bounds",
    "effective_optics",
    "identify",
    "observation_operator",
    "parameter_names",
    "smooth_constant",
    "smooth_drifting",
    "heated_time",
    "tracked_points",
]
