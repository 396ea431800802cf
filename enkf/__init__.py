"""Ensemble Kalman filtering: a generic filter (pure array math) and the
tissue-identification application that drives it with the laser-tissue model.

Generic part (no knowledge of tissue, photons or meshes):

- :mod:`enkf.analysis`: analysis updates on arrays (perturbed-observation EnKF,
  ETKF, inflation).
- :mod:`enkf.transforms`: parameter transforms (identity, log, logit).
- :mod:`enkf.driver`: the augmented-state filter loop (:func:`run_filter`).
- :mod:`enkf.models`: toy models for verification (linear-Gaussian with its exact
  Kalman filter, Lorenz-96).

Glossary (as in DAPPER and Arnold & Fichera): ``N`` ensemble size; ``E`` ensemble
``(N, n)``, members in rows; ``A`` anomalies ``E - mean``; ``Y`` ensemble in
observation space ``(N, p)``; ``y`` data ``(p,)``; ``R`` (paper: D) observation
error covariance; ``K`` Kalman gain; ``theta`` parameters in physical units;
``u`` the transformed parameters the filter works on; ``C`` model-noise
variances; ``E_rw`` random-walk covariance. See docs/enkf.md.
"""

from .analysis import enkf_perturbed_obs, etkf, inflate, random_rotation
from .driver import (
    FilterConfig,
    FilterDivergence,
    FilterProblem,
    FilterResult,
    HealthCheck,
    StepReport,
    run_filter,
    uniform_prior,
)
from .transforms import IdentityTransform, LogitTransform, LogTransform

__all__ = [
    "FilterConfig",
    "FilterDivergence",
    "FilterProblem",
    "FilterResult",
    "HealthCheck",
    "IdentityTransform",
    "LogTransform",
    "LogitTransform",
    "StepReport",
    "enkf_perturbed_obs",
    "etkf",
    "inflate",
    "random_rotation",
    "run_filter",
    "uniform_prior",
]
