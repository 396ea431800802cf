r"""Optics that follow the damage: coagulation inside the filter's forecast (issue #21).

A random walk on the optics (the paper) can only react: the filter learns that mus has
risen after the temperatures have told it, so it lags while the tissue changes and the
first readings of the cooling pull it hard. During laser heating the optics change for
a known reason: the tissue coagulates, at the rate of the Arrhenius damage integral of
its own temperature history. This module puts that cause into every member.

Each member :math:`n` carries its damage integral :math:`\Omega_n` at every node of the
filter's mesh, advanced from its own temperatures over each forecast step with
:func:`fem.advance_damage` (trapezoid rule, the project's one Arrhenius kernel, as
:class:`~enkf.tissue.risk.RiskTracker`),

.. math::

    \Omega_n \mathrel{+}= \tfrac{\Delta t}{2}\big(k(T_n^{j}) + k(T_n^{j+1})\big),
    \qquad k(T) = A\,e^{-E/(R\,(T + 273.15))},

and its light-weighted coagulated fraction

.. math::

    F_n = \frac{\sum_i w_{ni}\,\big(1 - e^{-\Omega_{ni}}\big)}{\sum_i w_{ni}},
    \qquad w_{ni} = q_{ni}^{\,p},\quad q_{ni} = \text{the nodal load of member } n
    \text{'s native optics (W per W)},

moves its optics from the native to the coagulated values:

.. math::

    \mu_a^\mathrm{eff} = \mu_a + F_n\,(\mu_a^\mathrm{coag} - \mu_a),\qquad
    \mu_s^\mathrm{eff} = \mu_s + F_n\,(\mu_s^\mathrm{coag} - \mu_s).

The weights are where the member's native optics put the laser's power: the volume whose
optics decide the absorbed-power map and the temperatures the sensor sees (the fluence
would weigh the deep, cool and never coagulated tissue more). The exponent ``p``
(``weight_exponent``, default 2) says how strongly the hottest, most strongly absorbing
nodes count. One fraction for the whole block is a mean field: real tissue coagulates
first in a thin layer under the beam, where its higher scattering keeps more light near
the surface, so the surface heats more than uniform optics at the mean fraction would
make it. With ``p = 1`` the filter's coarse model at the true optics was 8.7 deg C
colder at the end of the 5 s pulse than the fine-grid truth whose voxels coagulate on
their own (84.0 against 92.7 deg C); with ``p = 2`` 0.2 deg C (92.5), and 2.1 deg C
warmer 1 s into the cooling (78.6 against 76.5); ``p = 3`` and ``4`` overshoot (96.4,
98.0). The choice compares forward runs at the true optics on the single pulse
(``enkf.paper.coagulation``), not filter results; the pulse train was not used. The loads of each step
are the emulator's at :math:`(\mu_a^\mathrm{eff}, \mu_s^\mathrm{eff})`, with
:math:`F` of the start of the step (the parameters of time :math:`t_j`, as the loop's
forecast). The estimated parameters are the native and the coagulated values
(``mua``, ``mus``, ``mua_coag``, ``mus_coag``, log-transformed like the others); a
small random walk on them stays available for what the model does not explain.

**Omega stays out of the analysis.** It is each member's own history along its
analysed trajectory, as :class:`~enkf.tissue.risk.RiskTracker` integrates it: the
analysis moves the member's temperature and parameters, and the damage then grows from
the moved temperature. Updating :math:`\Omega` linearly would give negative damage and
regress a quantity that is zero almost everywhere on one surface reading; and the
analysis keeps member identities (the ETKF transform is close to the identity for the
small moves of one reading), so each member's past stays meaningful. The price: a
member's damage is not corrected when its past temperatures are found wrong; the
temperatures, which drive the future damage, are.

**The mean field's error.** A fraction of the block coagulated is not a coagulated layer
under the beam: a thin layer of high scattering sends more light back out and less of
it below (our Monte Carlo on 100 x 100 x 50 voxels, the paper's beam: under 0.1 cm of
coagulated tissue the absorbed power at 0.15 and 0.2 cm on the axis is 0.45 and 0.44 of
the native's, where uniform optics, even the fully coagulated ones, keep 0.93 and 0.63
of it). At the true optics the coarse model's rise of
the temperature at 0.1 and 0.2 cm is then about 20 % too large at the end of the single
pulse, and already 5-10 % off while the first layer forms
(``validation/reports/coagulation.md``, "The mean field at the true optics").
With the structured model error (:class:`~enkf.tissue.StructuredModelError`, the default
of ``tissue-enkf identify``) each member's relative sd of a step's tendency is therefore
``model_error_rel_std + mean_field_rel_std * sqrt(F_n)``: nothing before the damage,
0.16 at ``F = 0.2``, 0.27 at ``F = 0.8`` (``mean_field_rel_std = 0.25``); ``sqrt``
because the first layer changes the light most. Sized from those forward runs, not
from the filter's coverage. Per-node optics were tried (each node's own coagulated
optics, or its column's, or the log-fluence gradient of the two uniform media mixed by
depth): at the true optics they were no closer to the fine truth than the mean field
(0.1 cm RMS 2.5-3.1 deg C against 2.5), which takes an emulator of layered media.

With ES-MDA (``mda > 1``) the step is re-run from its start; the damage is then
recomputed from the damage at the start, never added twice: a step's damage is kept
(committed) when the next step starts where it ended.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

import fem

from .risk import MCMATLAB_A, MCMATLAB_E

__all__ = ["Coagulation", "CoagulationForwardModel", "coagulated_fraction",
           "effective_optics"]


def coagulated_fraction(omega: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``F`` (N,): the weighted mean of ``1 - exp(-omega)`` over the nodes.

    Parameters
    ----------
    omega : (N, n_nodes) damage integrals (>= 0)
    weights : (N, n_nodes) or (n_nodes,), >= 0, not all zero in a row
    """
    omega = np.atleast_2d(np.asarray(omega, float))
    w = np.asarray(weights, float)
    frac = -np.expm1(-omega)  # 1 - exp(-omega), exact for small omega
    return (frac * w).sum(axis=-1) / np.broadcast_to(w, frac.shape).sum(axis=-1)


def effective_optics(native, coagulated, F) -> np.ndarray:
    """``native + F (coagulated - native)``: the optics of a fraction ``F`` coagulated."""
    native = np.asarray(native, float)
    return native + np.asarray(F, float) * (np.asarray(coagulated, float) - native)


@dataclass
class Coagulation:
    """The damage-driven optics of ``TissueFilterSetup(parameter_model="coagulation")``.

    Parameters
    ----------
    E : float
        J/mol, Arrhenius activation energy of coagulation (default: MCmatlab's).
    A : float
        1/s, Arrhenius frequency factor (default: MCmatlab's; with ``E`` the rate is
        3.2 /s at 60 deg C and 1e-3 /s at 45 deg C).
    weight_exponent : float
        ``p`` of the weights ``q**p`` of the coagulated fraction (module doc; default 2).
    nominal_factor : (float, float)
        The nominal coagulated ``(mua, mus)`` as multiples of the nominal native ones:
        the centre of their default prior (``prior_range`` times it, unless
        ``ParameterModel.prior`` names ``mua_coag`` or ``mus_coag``). Coagulation
        raises scattering severalfold and absorption less (measured on liver, e.g.
        Ritz et al. 2001, Lasers Surg. Med. 29, 205-212); default (1.5, 3).
    mean_field_rel_std : float
        With the structured model error (``ModelError.kind = "structured"``):
        each member's relative error of a step's tendency grows by this times the square
        root of its coagulated fraction ``F`` (``model_error_rel_std +
        mean_field_rel_std * sqrt(F)``): the error of the mean field where real tissue
        coagulates as a layer under the beam (module doc, "The mean field's error").
        Default 0.25; 0 turns it off. No effect with the white model error (identical
        twins).
    """

    E: float = MCMATLAB_E
    A: float = MCMATLAB_A
    nominal_factor: tuple[float, float] = (1.5, 3.0)
    weight_exponent: float = 2.0
    mean_field_rel_std: float = 0.25

    def __post_init__(self):
        for name in ("E", "A", "weight_exponent"):
            v = getattr(self, name)
            if not (isinstance(v, numbers.Real) and math.isfinite(v) and v > 0):
                unit = {"E": " (J/mol)", "A": " (1/s)"}.get(name, "")
                raise ValueError(f"coagulation.{name} must be a finite number > 0{unit}, "
                                 f"got {v!r}")
        try:
            f = tuple(float(v) for v in self.nominal_factor)
        except (TypeError, ValueError):
            f = ()
        if len(f) != 2 or not all(math.isfinite(v) and v > 0 for v in f):
            raise ValueError(f"coagulation.nominal_factor must be two numbers > 0 (mua, mus), "
                             f"got {self.nominal_factor!r}")
        self.nominal_factor = f
        v = self.mean_field_rel_std
        if not (isinstance(v, numbers.Real) and math.isfinite(v) and v >= 0):
            raise ValueError(f"coagulation.mean_field_rel_std must be a finite number >= 0, "
                             f"got {v!r}")

    def weights(self, loads: np.ndarray) -> np.ndarray:
        """The weights of the coagulated fraction from nodal loads (negative ones, Monte
        Carlo noise, count as zero)."""
        return np.maximum(loads, 0.0) ** self.weight_exponent

    def nominal(self, native: dict) -> dict:
        """``{"mua_coag": ..., "mus_coag": ...}`` cm^-1 from the native nominal values."""
        return {"mua_coag": self.nominal_factor[0] * native["mua"],
                "mus_coag": self.nominal_factor[1] * native["mus"]}


class CoagulationForwardModel:
    """The forecast of the damage-driven model: a :class:`TissueForwardModel` whose members'
    optics follow their own damage (see the module doc).

    ``theta`` columns are ``names`` (:func:`enkf.tissue.parameter_names`): ``mua``,
    ``mus`` (native), ``mua_coag``, ``mus_coag`` and, when estimated, ``VHC``, ``TC``.
    """

    def __init__(self, base, coagulation: Coagulation, names):
        self.base = base
        self.coagulation = coagulation
        self.setup, self.mesh = base.setup, base.mesh
        names = tuple(names)
        self.i_native = [names.index("mua"), names.index("mus")]
        self.i_coag = [names.index("mua_coag"), names.index("mus_coag")]
        self.i_base = [names.index(n) for n in base.setup.parameters.estimate]  # the base model's order
        self.reset()

    # ------------------------------------------------------------------ damage bookkeeping
    def reset(self) -> None:
        """Forget the damage: the next forecast starts a run (no damage at its start)."""
        self._t = None  #: s, time of the committed damage
        self._omega = None  #: (N, n_nodes) committed damage
        self._pending = None  #: (t1, omega) of the last forecast, kept when the next starts

    def damage_at(self, t: float, N: int) -> np.ndarray:
        """(N, n_nodes) the members' damage at ``t`` (s): the last forecast's when it ended
        at ``t`` (committed then), the committed one at its time, else none (a new run)."""
        tol = 1e-9 * max(1.0, abs(t))
        if self._pending is not None and abs(self._pending[0] - t) <= tol:
            self._t, self._omega = self._pending
            self._pending = None
        elif self._t is None or abs(self._t - t) > tol or self._omega.shape[0] != N:
            self._t, self._omega = t, np.zeros((N, self.mesh.p.shape[1]))
            self._pending = None
        return self._omega

    def _latest(self, t: float) -> np.ndarray | None:
        tol = 1e-9 * max(1.0, abs(t))
        if self._pending is not None and abs(self._pending[0] - t) <= tol:
            return self._pending[1]
        if self._t is not None and abs(self._t - t) <= tol:
            return self._omega
        return None

    # ------------------------------------------------------------------ optics
    def weights(self, theta: np.ndarray) -> np.ndarray:
        """(N, n_nodes) the F weights: powers of the nodal loads per W of each member's
        native optics (:meth:`Coagulation.weights`)."""
        return self.coagulation.weights(
            self.base.loads(self.base_theta(theta, theta[:, self.i_native]), 1.0))

    def base_theta(self, theta: np.ndarray, optics: np.ndarray) -> np.ndarray:
        """The base model's ``theta`` with ``optics`` (N, 2) as its mua and mus."""
        out = theta[:, self.i_base].copy()
        out[:, [self.base.col["mua"], self.base.col["mus"]]] = optics
        return out

    def optics(self, theta: np.ndarray, F: np.ndarray) -> np.ndarray:
        """(N, 2) effective (mua, mus) cm^-1 of members with coagulated fractions ``F``."""
        return effective_optics(theta[:, self.i_native], theta[:, self.i_coag], F[:, None])

    def mean_field_rel_std(self, theta: np.ndarray, t: float) -> np.ndarray:
        """(N,) the members' addition to the structured model error's relative sd at ``t``
        (s): ``Coagulation.mean_field_rel_std`` times the square root of their coagulated
        fraction (the ``extra_rel_std`` of :class:`~enkf.tissue.StructuredModelError`)."""
        return self.coagulation.mean_field_rel_std * np.sqrt(self.effective(theta, t)[0])

    def effective(self, theta: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """``(F (N,), optics (N, 2))`` of the members ``theta`` with their damage at ``t``
        (no damage when the model holds none for that time, e.g. the prior)."""
        omega = self._latest(t)
        N = theta.shape[0]
        F = np.zeros(N) if omega is None or omega.shape[0] != N else \
            coagulated_fraction(omega, self.weights(theta))
        return F, self.optics(theta, F)

    # ------------------------------------------------------------------ the forecast
    def __call__(self, E_state: np.ndarray, theta: np.ndarray, t0: float, t1: float):
        """Members from ``t0`` to ``t1`` (s), their optics following their damage, which
        advances over each heat sub-step from the member's own temperatures."""
        N = E_state.shape[0]
        omega = self.damage_at(t0, N).copy()
        w = self.weights(theta)
        c = self.coagulation
        for a, b in self.base.substeps(t0, t1):
            F = coagulated_fraction(omega, w)
            X1 = self.base.step(E_state, self.base_theta(theta, self.optics(theta, F)), a, b,
                                self.setup.mean_power(a, b))
            fem.advance_damage(omega, E_state, X1, b - a, c.E, c.A, rule="trapezoid")
            E_state = X1
        self._pending = (float(t1), omega)
        return E_state

    # ------------------------------------------------------------------ delegated
    def warm_up(self, dt: float) -> None:
        self.base.warm_up(dt)

    def clamp_report(self) -> dict | None:
        return self.base.clamp_report()

    @property
    def clamp_counts(self) -> dict:
        return self.base.clamp_counts

    @clamp_counts.setter
    def clamp_counts(self, value: dict) -> None:
        self.base.clamp_counts = value

    def table_ranges(self) -> dict:
        return self.base.table_ranges()
