"""The tissue parameters the filter can estimate: names, units, default ranges, probe depths.

One table each; every module asks here instead of knowing that column 0 is mua.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "COAGULATION_NAMES",
    "ABSORPTION_INPUTS",
    "BEAM_NAMES",
    "ESTIMATES",
    "PARAMETER_LABELS",
    "PARAMETER_NAMES",
    "OPTICS_NAMES",
    "PARAMETER_UNITS",
    "PRIOR_FACTORS",
    "SECOND_MEDIUM_NAMES",
    "TRACKED_DEPTHS",
    "column",
    "default_bounds",
    "default_prior",
    "parameter_names",
    "tracked_points",
]

#: every parameter the filter can estimate, in the order of the state's parameter block
PARAMETER_NAMES = ("mua", "mus", "VHC", "TC")
#: the coagulated optics the damage-driven model estimates beside the native ``mua``, ``mus``
#: (``parameter_model = "coagulation"``, :mod:`enkf.tissue.coagulation`)
COAGULATION_NAMES = ("mua_coag", "mus_coag")
#: the optics of a second estimated medium of a layered block (e.g. the epidermis over the
#: dermis whose optics are ``mua``, ``mus``; :class:`mcmatlab_py.emulator.media.TwoMediaEmulator`)
SECOND_MEDIUM_NAMES = ("mua2", "mus2")
#: the beam's radius as an uncertain input the ensemble carries beside the optics
#: (:class:`mcmatlab_py.emulator.media.BeamRadiusEmulator`; issue #18)
BEAM_NAMES = ("beam_radius",)
#: the optical parameters an absorption model takes, in its call's order
OPTICS_NAMES = PARAMETER_NAMES[:2] + SECOND_MEDIUM_NAMES
#: every input an absorption model may take, in its call's order
ABSORPTION_INPUTS = OPTICS_NAMES + BEAM_NAMES
#: units of each parameter (MCmatlab's and the paper's)
PARAMETER_UNITS = {"mua": "cm^-1", "mus": "cm^-1", "VHC": "J cm^-3 K^-1", "TC": "W cm^-1 K^-1",
                   "mua_coag": "cm^-1", "mus_coag": "cm^-1", "mua2": "cm^-1", "mus2": "cm^-1",
                   "beam_radius": "cm"}
#: the same units for matplotlib labels
PARAMETER_LABELS = {"mua": "cm$^{-1}$", "mus": "cm$^{-1}$", "VHC": "J cm$^{-3}$ K$^{-1}$",
                    "TC": "W cm$^{-1}$ K$^{-1}$", "mua_coag": "cm$^{-1}$",
                    "mus_coag": "cm$^{-1}$", "mua2": "cm$^{-1}$", "mus2": "cm$^{-1}$",
                    "beam_radius": "cm"}
#: the parameter sets that can be estimated: the optics, or the optics and thermal properties;
#: with a second estimated medium, its optics after the first's; or the optics with the
#: beam's radius carried as an uncertain input
ESTIMATES = (PARAMETER_NAMES[:2], PARAMETER_NAMES, PARAMETER_NAMES[:2] + SECOND_MEDIUM_NAMES,
             PARAMETER_NAMES[:2] + SECOND_MEDIUM_NAMES + PARAMETER_NAMES[2:],
             PARAMETER_NAMES[:2] + BEAM_NAMES)
#: the default prior of an input known to some percent, as factors of its nominal value
#: (in place of ``prior_range``): a beam radius measured to +-10%
PRIOR_FACTORS = {"beam_radius": (0.9, 1.1)}
#: cm, depths below the sensor whose temperature the paper reports (and the tool by default)
TRACKED_DEPTHS = (0.0, 0.1, 0.2)


def parameter_names(estimate, parameter_model: str = "random_walk") -> tuple:
    """The filtered parameters, in the order of the state's parameter block: ``estimate``,
    with the coagulated optics after ``mua``, ``mus`` when ``parameter_model`` is
    ``"coagulation"`` (``mua``, ``mus`` are then the native values)."""
    estimate = tuple(estimate)
    if parameter_model != "coagulation":
        return estimate
    return estimate[:2] + COAGULATION_NAMES + estimate[2:]


def column(names, name: str) -> int:
    """Index of parameter ``name`` in ``names`` (an ``estimate`` tuple); ValueError if absent."""
    names = tuple(names)
    if name not in names:
        raise ValueError(f"parameter {name!r} is not estimated (estimate = {names})")
    return names.index(name)


def tracked_points(depths=TRACKED_DEPTHS, x: float = 0.0, y: float = 0.0,
                   Lz: float | None = None) -> np.ndarray:
    """(n, 3) cm: points below ``(x, y)`` at ``depths``, those deeper than ``Lz`` dropped."""
    return np.array([[x, y, float(z)] for z in depths if Lz is None or z <= Lz], float)


def default_bounds(nominal, prior_lo, prior_hi) -> np.ndarray:
    """(n_par, 2) default health-check range of each parameter's mean: 1/20 to 20 times
    the nominal value, widened to a tenth of the prior's low end and ten times its high end."""
    nominal, prior_lo, prior_hi = (np.asarray(a, float) for a in (nominal, prior_lo, prior_hi))
    return np.column_stack([np.minimum(nominal / 20, prior_lo / 10),
                            np.maximum(nominal * 20, prior_hi * 10)])


def default_prior(name: str, nominal: float, prior_range) -> tuple[float, float]:
    """(lo, hi) of ``name``'s uniform prior when none is given: :data:`PRIOR_FACTORS` times
    ``nominal`` for the inputs known to some percent, else ``prior_range`` times it."""
    lo_f, hi_f = PRIOR_FACTORS.get(name, prior_range)
    return lo_f * nominal, hi_f * nominal
