"""Ensemble Kalman filtering for joint state and parameter estimation.

The package root is the generic filter: pure array math on ``(N, n)`` ensembles, with
no knowledge of tissue, photons or meshes (it imports nothing from ``mcmatlab_py`` or
``fem``):

- :mod:`enkf.analysis`: analysis updates (perturbed-observation EnKF, ETKF, localized
  EnKF).
- :mod:`enkf.spread`: the ensemble's spread around an analysis (inflation, relaxation to
  prior spread, rotation).
- :mod:`enkf.transforms`: parameter transforms (identity, log, logit).
- :mod:`enkf.problem`: what is filtered and how (:class:`FilterConfig`,
  :class:`FilterProblem`, the prior, :class:`FilterResult`).
- :mod:`enkf.health`: the health check that stops a run gone wrong.
- :mod:`enkf.loop`: the augmented-state filter loop (:func:`run_filter`).
- :mod:`enkf.smoother`: the ensemble smoother with multiple data assimilation
  (:func:`es_mda`) for constant parameters over a whole window.
- :mod:`enkf.importance`: adaptive multiple importance sampling (:func:`amis`), the
  posterior itself from an ensemble's first guess, for few parameters.
- :mod:`enkf.modes`: the posterior's modes from many starts (:func:`find_modes`,
  batched Levenberg-Marquardt in a box), which seed the importance sampler.
- :mod:`enkf.toy_models`: toy models to verify the filter (linear-Gaussian with its
  exact Kalman filter, Lorenz-96).
- :mod:`enkf.checks`: input checks shared by these modules.

Subpackages, imported by name only (``import enkf`` loads none of them):

- :mod:`enkf.tissue`: the application, identifying tissue optics from a thermal sensor
  (``from enkf.tissue import identify``).
- :mod:`enkf.paper`: the paper's experiments (Arnold & Fichera).
- :mod:`enkf.app`: the command-line tool ``tissue-enkf`` (parser, commands, TOML
  config, data readers, run directories, reports, the validation suite).

Dependencies point one way: ``enkf.app -> enkf.paper -> enkf.tissue -> enkf``,
``enkf.tissue -> mcmatlab_py -> fem``.

Glossary (as in DAPPER and Arnold & Fichera): ``N`` ensemble size; ``E`` ensemble
``(N, n)``, members in rows; ``A`` anomalies ``E - mean``; ``Y`` ensemble in
observation space ``(N, p)``; ``y`` data ``(p,)``; ``R`` (paper: D) observation
error covariance; ``K`` Kalman gain; ``theta`` parameters in physical units;
``u`` the transformed parameters the filter works on; ``C`` model-noise
variances; ``E_rw`` random-walk covariance. See docs/enkf.md.
"""

from importlib.metadata import PackageNotFoundError, version

from .adaptive import (
    AdaptiveInflation,
    InflationEstimator,
    innovation_loglik,
    innovation_persistence,
    normalized_innovation,
)
from .analysis import enkf_perturbed_obs, etkf
from .health import HealthCheck
from .importance import ImportanceSample, amis
from .loop import run_filter
from .modes import Modes, find_modes
from .problem import (
    DEFAULT_METHOD,
    FilterConfig,
    FilterDivergence,
    FilterProblem,
    FilterResult,
    StepReport,
    uniform_prior,
)
from .smoother import es_mda
from .spread import inflate, random_rotation, relax_to_prior_spread
from .transforms import IdentityTransform, LogitTransform, LogTransform

try:
    __version__ = version("tissue-enkf")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0+unknown"

__all__ = [
    "AdaptiveInflation",
    "ImportanceSample",
    "amis",
    "es_mda",
    "find_modes",
    "Modes",
    "DEFAULT_METHOD",
    "FilterConfig",
    "FilterDivergence",
    "FilterProblem",
    "FilterResult",
    "HealthCheck",
    "InflationEstimator",
    "IdentityTransform",
    "LogTransform",
    "LogitTransform",
    "StepReport",
    "__version__",
    "enkf_perturbed_obs",
    "etkf",
    "inflate",
    "innovation_loglik",
    "innovation_persistence",
    "normalized_innovation",
    "random_rotation",
    "relax_to_prior_spread",
    "run_filter",
    "uniform_prior",
]
