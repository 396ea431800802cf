"""The tissue filter's setup (:class:`TissueFilterSetup`) and its parts.

:class:`TissueFilterSetup` holds the problem itself (grid, absorption, laser, initial
temperature, the ensemble's size, method and seed) and five parts, each a small dataclass
that checks its own fields: :class:`ParameterModel` (which parameters, priors, walks,
trend, coagulation, the drift bank), :class:`Sensors` (point sensors, camera, offsets,
tracked points), :class:`ModelError` (the model error, inflation, RTPS),
:class:`HeatModel` (time scheme, heat operator, boundaries) and :class:`SmootherRestarts`.
:meth:`TissueFilterSetup.build` and :meth:`TissueFilterSetup.with_` take the settings by
flat names (:data:`FLAT_NAMES`), as a config's keys.
"""

from .drift_bank import DriftBank
from .parameter_model import ParameterModel
from .parts import HeatModel, ModelError, Sensors, SmootherRestarts
from .problem import FLAT_NAMES, RESTART_PROBES, TissueFilterSetup

__all__ = ["FLAT_NAMES", "RESTART_PROBES", "DriftBank", "HeatModel", "ModelError",
           "ParameterModel", "Sensors", "SmootherRestarts", "TissueFilterSetup"]
