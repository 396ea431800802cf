"""TOML -> identification run (an edge subpackage): :func:`load_identify` reads a config
into an :class:`IdentifyConfig`, whose :meth:`~IdentifyConfig.setup` builds the
:class:`~enkf.tissue.TissueFilterSetup`.

Modules: :mod:`~enkf.app.config.reader` (the tables and their keys; the file format in
its docstring), :mod:`~enkf.app.config.spec` (:class:`IdentifyConfig`, :class:`DataSpec`),
:mod:`~enkf.app.config.numbers` (each key's limit), :mod:`~enkf.app.config.params`
(estimated parameters, priors, bounds, coagulation, drift bank: the setup's
:class:`~enkf.tissue.ParameterModel`), :mod:`~enkf.app.config.settings` (smoother,
restarts, model error), :mod:`~enkf.app.config.media` (estimated media, node grids),
:mod:`~enkf.app.config.camera` (``[sensors.camera]``), :mod:`~enkf.app.config.advice`
(``[advice]``).
"""

from mcmatlab_py.config import ConfigError

from .reader import FILTER_KEYS, check_identify_keys, identify_config_from_dict, load_identify, run_table
from .spec import DataSpec, IdentifyConfig

__all__ = ["FILTER_KEYS", "ConfigError", "DataSpec", "IdentifyConfig", "check_identify_keys",
           "identify_config_from_dict", "load_identify", "run_table"]
