"""The parts of a :class:`~enkf.tissue.TissueFilterSetup` besides the parameter model:
the sensors, the model error, the heat model and the restarts from the smoother.

Each part checks its own fields in ``__post_init__`` (a ``ValueError`` that names the
field and the value); what ties parts together (e.g. restarts need constant or drifting
optics) is checked by the setup.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import fem

from ...checks import fraction
from ..parameters import tracked_points
from ..paths import LOGISTIC, check_form

__all__ = ["HeatModel", "ModelError", "Sensors", "SmootherRestarts"]


def _nonneg(obj, *names: str) -> None:
    """Each field of ``names`` finite and >= 0, else a ValueError naming it."""
    for name in names:
        v = getattr(obj, name)
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"{type(obj).__name__}.{name} must be >= 0, got {v!r}")


@dataclass
class Sensors:
    """What is observed and where the temperature is reported (``[sensors]`` of a config).

    Parameters
    ----------
    positions : (p, 3) cm
        Point sensors; may be empty, shape (0, 3), with an ``image``.
    noise_var : float or (p,)
        deg C^2, the sensors' noise variance ``D`` (the paper: 0.01).
    image : enkf.tissue.image.ThermalImage, optional
        A camera's pixels over the top face, observed after the point sensors: the data
        then have ``p + image.n_pixels`` columns (pixels in C order of the frame).
    offset_std : float
        deg C: the prior sd of an unknown calibration offset of each point sensor,
        estimated with the parameters (one per sensor, N(0, sd^2) at the start, constant;
        added to the model's readings). 0 (default): the sensors are calibrated. A real
        sensor that reads 0.3 deg C high otherwise pulls the optics until the model fits
        the offset.
    tracked : (n_tracked, 3) cm
        Points whose temperature is reported (default :func:`tracked_points`).
    """

    positions: np.ndarray = field(default_factory=lambda: np.zeros((1, 3)))
    noise_var: float | np.ndarray = 0.01
    image: object = None
    offset_std: float = 0.0
    tracked: np.ndarray = field(default_factory=tracked_points)

    def __post_init__(self):
        self.positions = np.asarray(self.positions, float).reshape(-1, 3)
        if self.positions.shape[0] == 0 and self.image is None:
            raise ValueError("Sensors.positions is empty and there is no image: nothing "
                             "observed")
        self.tracked = np.atleast_2d(np.asarray(self.tracked, float))
        _nonneg(self, "offset_std")
        if self.offset_std and self.positions.shape[0] == 0:
            raise ValueError(f"Sensors.offset_std = {self.offset_std!r} needs point sensors "
                             "(Sensors.positions is empty)")

    @property
    def n_offsets(self) -> int:
        """Offsets estimated beside the parameters: one per point sensor when
        ``offset_std > 0``, else 0."""
        return self.positions.shape[0] if self.offset_std > 0 else 0


@dataclass
class ModelError:
    """The forecast's error and how the ensemble's spread is kept honest
    (``[filter.model_error]``, ``[filter.adaptive_inflation]``, ``filter.model_noise_std``,
    ``inflation``, ``rtps`` of a config).

    Parameters
    ----------
    noise_std : float
        deg C per step: the white floor, ``C = noise_std^2 I`` (default 0.002: the coarse
        model is close to the truth, and a larger white nodal noise only makes the members
        rough).
    kind : str
        ``"white"`` (default, the paper): the floor alone. ``"structured"``: the floor plus
        a relative error of each step's tendency, correlated over depth and time
        (:class:`~enkf.tissue.model_error.StructuredModelError`, sized from the coarse
        model against independent models): honest bands for constant tissue on data from
        another model (``validation/reports/model_error_coverage.md``); not yet validated
        for drifting optics, where it slowed the parameters' drift in the first runs, so
        it is not the default.
    rel_std : float
        The sd of the relative error of a step's tendency (structured).
    time_scale : float
        s, its correlation time.
    length_xy, length_z : float
        cm, its correlation lengths across and down.
    adaptive_inflation : bool
        Estimate a factor on the forecast's temperature covariance from the innovations
        (:mod:`enkf.adaptive`): the model error's size is then checked against the data.
        Off by default until validated for drifting optics (on in
        ``examples/own_data.toml``).
    adaptive_inflation_bounds : (lo, hi)
        Of the covariance factor.
    adaptive_inflation_time_scale : float
        Analysed steps averaged over.
    inflation : float
        A fixed multiplicative inflation of the anomalies (:class:`enkf.problem.FilterConfig`).
    rtps : float
        Relaxation of the temperatures' analysis spread back towards the forecast's, alpha
        in [0, 1] (Whitaker & Hamill 2012; :func:`enkf.spread.relax_to_prior_spread`):
        0 = none.
    """

    noise_std: float = 0.002
    kind: str = "white"
    rel_std: float = 0.05
    time_scale: float = 3.0
    length_xy: float = 0.1
    length_z: float = 0.05
    adaptive_inflation: bool = False
    adaptive_inflation_bounds: tuple[float, float] = (1.0, 25.0)
    adaptive_inflation_time_scale: float = 30.0
    inflation: float = 1.0
    rtps: float = 0.0

    def __post_init__(self):
        if self.kind not in ("structured", "white"):
            raise ValueError(f"ModelError.kind must be 'structured' or 'white', got "
                             f"{self.kind!r}")
        fraction(self.rtps, "ModelError.rtps")
        _nonneg(self, "noise_std", "rel_std", "time_scale", "length_xy", "length_z")


@dataclass
class HeatModel:
    """How the forecast steps the heat equation (``[HS] theta``, ``[HS] dt``,
    ``filter.heat_mass`` of a config).

    Parameters
    ----------
    theta : float
        Time scheme of the forecast's heat steps: 0.5 (default) Crank-Nicolson, 1
        backward Euler. At the readings' 0.1 s, backward Euler lags the rise and the fall
        of the temperature by up to 0.6% of the peak (0.11 deg C at the paper's surface,
        0.43 in its drifting case), an error the optics then take up: on data from
        independent model A the camera's mus came out 4.1% off with backward Euler, 1.5%
        with Crank-Nicolson (``validation/reports/coarse_model_error.md``, "The time
        scheme"; ``docs/enkf.md``). Crank-Nicolson has the same cost per step.
    max_dt : float, optional
        s, the longest heat step of the forecast (``[HS] dt`` in a config): an interval
        between readings longer than this is split into equal sub-steps. None: one step
        per interval.
    operator : str
        ``"kronecker"`` (default): the tensor-product operator of :class:`fem.HeatStepper`,
        equal to P1 away from the box edges, with no per-member cost when VHC and TC are
        estimated; ``"p1"``: the exact P1 matrices (an edge correction per new pair of
        member scales).
    mass : str
        1-D mass of the tensor-product operator: ``"averaged"`` (default) cancels the
        leading discretization error of the lumped mass; at the paper's true parameters
        the 20 x 20 x 10 surface temperature is then within 0.1% of the fine truth
        instead of 1.1% cold (``validation/reports/coarse_model_error.md``). ``"lumped"``
        is the P1 lumped mass.
    boundary : fem.HeatBoundary
        The block's thermal boundary conditions.
    """

    theta: float = 0.5
    max_dt: float | None = None
    operator: str = "kronecker"
    mass: str = "averaged"
    boundary: fem.HeatBoundary = field(default_factory=fem.HeatBoundary)

    def __post_init__(self):
        if isinstance(self.theta, bool) or not (isinstance(self.theta, (int, float))
                                                 and 0.5 <= float(self.theta) <= 1.0):
            raise ValueError(f"HeatModel.theta must be in [0.5, 1] (0.5: Crank-Nicolson, 1: "
                             f"backward Euler), got {self.theta!r}")
        if self.max_dt is not None and not (np.isfinite(self.max_dt) and self.max_dt > 0):
            raise ValueError(f"HeatModel.max_dt must be > 0 (s) or None, got {self.max_dt!r}")


@dataclass
class SmootherRestarts:
    """Restarts of the filter from the ES-MDA smoother (``filter.smoother_restart*`` of a
    config; ``docs/enkf.md``, "Restarts").

    After the first reading at or after each of ``times``, or at or after the end of
    each laser pulse (``"laser_off"``), the parameter ensemble is replaced by the
    smoother's over every reading so far (from the prior;
    :func:`enkf.tissue.restart.restart_ensemble`) and the members' temperatures are re-run
    to that time with their new optics; then the filter goes on. The sequential updates
    lose information on a curved mua-mus ridge; the restart brings it back. Needs
    ``parameters.kind = "random_walk"``, with ``random_walk_std = 0`` unless ``knots >=
    2``, and no sensor offsets (checked by the setup).

    Parameters
    ----------
    times : tuple of float or "laser_off"
        s, the restart times; () (default): none.
    iterations : int
        ES-MDA updates of each restart.
    delay : float
        s, with ``"laser_off"``: restart after the first reading at or after this long
        past the end of each pulse. Drifting optics (``knots >= 2``) need some cooling
        readings to tell their final values: 2.5 s after a 5 s pulse in
        ``docs/enkf.md``, "Restarts".
    knots : int, "logistic" or a tuple of them
        1 (default): constant optics (``smooth_constant``). 2 or more: optics drifting while
        heated, piecewise linear in heated time through that many values
        (``smooth_drifting``); the restart takes their value at its reading, and the
        filter's walk goes on from there. ``"logistic"``: a logistic's segment between a
        value before the drift and one after it (:mod:`enkf.tissue.paths`). Several
        forms, e.g. (2, 3): the restarted
        ensemble is an equal mixture of the smoothers of those forms of the drift, each
        giving a block of members (``docs/enkf.md``, "Which form of the drift").
    discrepancy : float
        The restarts' model discrepancy (relative sd of the rise; ``smooth_constant``'s
        ``discrepancy``): 0 for identical twins.
    discrepancy_time : float
        s, its correlation time.
    gaussian : bool
        True (default): the restarted members are a log-normal draw with the smoother's
        ensemble's log mean and covariance (:func:`enkf.tissue.restart.gaussian_ensemble`):
        the ETKF's updates keep an ensemble's shape, and the smoother's skew made the
        quantile bands miss (75-80% on the layered twins, 90-95% with it). False: its
        members as they are.
    """

    times: tuple | str = ()
    iterations: int = 8
    delay: float = 0.0
    knots: int | tuple = 1
    discrepancy: float = 0.0
    discrepancy_time: float = 2.0
    gaussian: bool = True

    def __post_init__(self):
        r = self.times
        if isinstance(r, str):
            if r != "laser_off":
                raise ValueError(f"SmootherRestarts.times must be times (s) or 'laser_off', "
                                 f"got {r!r}")
        else:
            try:
                t = np.asarray(r, float).reshape(-1)
            except (TypeError, ValueError):
                raise ValueError(f"SmootherRestarts.times must be times (s) or 'laser_off', "
                                 f"got {r!r}") from None
            if not (np.all(np.isfinite(t)) and np.all(t > 0) and np.all(np.diff(t) > 0)):
                raise ValueError(f"SmootherRestarts.times must be increasing times > 0 (s), "
                                 f"got {r!r}")
            self.times = tuple(float(v) for v in t)
            if not t.size:
                return
        n = self.iterations
        if not (isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 1):
            raise ValueError(f"SmootherRestarts.iterations must be an integer >= 1, got {n!r}")
        forms = self.knots
        forms = tuple(forms) if isinstance(forms, (list, tuple)) else (forms,)
        if not forms:
            raise ValueError("SmootherRestarts.knots must be an integer >= 1, 'logistic' or a "
                             "list of them, got []")
        forms = tuple(check_form(k, "SmootherRestarts.knots", lo=1) for k in forms)
        if len(forms) > 1 and (1 in forms or len(set(forms)) < len(forms)):
            raise ValueError(f"SmootherRestarts.knots = {list(forms)}: a mixture of drift "
                             "forms needs different forms, each >= 2 knots or 'logistic'")
        self.knots = forms[0] if len(forms) == 1 else forms
        if not isinstance(self.gaussian, (bool, np.bool_)):
            raise ValueError(f"SmootherRestarts.gaussian must be True or False, got "
                             f"{self.gaussian!r}")
        if self.delay and not isinstance(r, str):
            raise ValueError(f"SmootherRestarts.delay = {self.delay!r} is for times = "
                             "'laser_off'")
        for name in ("discrepancy", "discrepancy_time", "delay"):
            v = getattr(self, name)
            if not (np.isfinite(v) and (v > 0 if name.endswith("time") else v >= 0)):
                raise ValueError(f"SmootherRestarts.{name} must be "
                                 f"{'> 0 (s)' if name.endswith('time') else '>= 0'}, got {v!r}")

    @property
    def knot_forms(self) -> tuple:
        """The restarts' counts of knots, one per form of the drift (:attr:`knots`)."""
        k = self.knots
        return tuple(k) if isinstance(k, tuple) else (k,)

    @property
    def drifts(self) -> bool:
        """Whether the restarts let the optics drift (knots >= 2 or a logistic)."""
        return any(k == LOGISTIC or k > 1 for k in self.knot_forms)
