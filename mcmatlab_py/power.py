"""The laser's power from what a clinic states, and several light sources in one model.

MCmatlab takes the incident (pulse peak) power ``P`` in W: ``MC.P`` for fluence-rate
dependent media, the heat simulation's power (``HS.P`` here), and the factor that turns
the normalised outputs into absolute ones (``P * NFR`` in W/cm^2, ``P * NA`` in
W/cm^3). Lasers are specified otherwise (MCmatlab's issues #21 and #37): an irradiance
(W/cm^2), a radiant exposure per pulse (J/cm^2) with the pulse duration, a pulse energy
(J) with the repetition rate. :func:`peak_power` converts any of these to ``P``, stating
the beam area it used (:func:`beam_area`); :func:`apply_power` sets it (and the pulse
train) on a model.

Several light sources, each with its own power (MCmatlab's issue #31), are MCmatlab's
own recipe made one call: one Monte Carlo run per source, combined with the powers as
weights (:func:`mcmatlab_py.combine.combine_models`, MCmatlab's ``combineModels``).
:func:`run_light_sources` returns that combined model: its outputs per W of the total
power, its ``MC.P`` and ``HS.P`` the total, ready for the heat simulation.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from fem.checks import check_number

__all__ = ["LaserPower", "absolute_absorption", "absolute_fluence_rate", "apply_power",
           "beam_area", "peak_power", "run_light_sources", "source_seeds"]


def _distr_code(value, name: str):
    if isinstance(value, str):
        codes = {"tophat": 0, "top-hat": 0, "gaussian": 1, "lambertian": 2, "cosine": 2}
        if value.lower() in codes:
            return codes[value.lower()]
    elif isinstance(value, int | float | np.integer | np.floating) and float(value) in (0, 1, 2):
        return int(value)
    raise ValueError(f"beam_area: {name} = {value!r} has no simple area (a custom "
                     "distribution): give area= in cm^2")


def beam_area(model_or_source, G=None) -> tuple[float, str]:
    """The area (cm^2) whose product with the peak irradiance is the beam's power.

    * top-hat of radius r (``"tophat"``, or a radial beam with ``radial_distr`` 0):
      ``pi r^2`` (the irradiance is uniform);
    * Gaussian of 1/e^2 radius w (``"gaussian"``, or ``radial_distr`` 1): ``pi w^2 / 2``
      (the centre's irradiance is ``2 P / (pi w^2)``);
    * an X/Y beam of half-widths a, b (``x_distr``, ``y_distr`` each top-hat ``2a`` or
      Gaussian ``sqrt(pi / 2) a``): the product of the two;
    * a plane wave: the top face ``Lx Ly`` (MCmatlab's ``P`` of a plane wave is the power
      on the top face).

    ``model_or_source``: a :class:`~mcmatlab_py.Model` (its ``MC.light_source`` and ``G``)
    or a :class:`~mcmatlab_py.LightSource` (with ``G`` for a plane wave). Returns
    ``(area, how)``: ``how`` says which rule gave it. Pencil beams, point sources and custom
    distributions raise a ``ValueError`` asking for the area.
    """
    from .light.source import source_kind

    src = getattr(getattr(model_or_source, "MC", None), "light_source", model_or_source)
    G = G if G is not None else getattr(model_or_source, "G", None)
    kind = source_kind(src.source_type)
    fpid = src.focal_plane_intensity_distribution
    if kind in ("tophat", "gaussian"):
        r = check_number("MC.light_source.radius", src.radius, lo=0.0)
        code = 0 if kind == "tophat" else 1
    elif kind == "radial":
        code = _distr_code(fpid.radial_distr, "focal_plane_intensity_distribution.radial_distr")
        r = check_number("focal_plane_intensity_distribution.radial_width", fpid.radial_width,
                         lo=0.0)
    elif kind == "xy":
        a = check_number("focal_plane_intensity_distribution.x_width", fpid.x_width, lo=0.0)
        b = check_number("focal_plane_intensity_distribution.y_width", fpid.y_width, lo=0.0)
        cx = _distr_code(fpid.x_distr, "focal_plane_intensity_distribution.x_distr")
        cy = _distr_code(fpid.y_distr, "focal_plane_intensity_distribution.y_distr")
        width = {0: lambda h: 2 * h, 1: lambda h: math.sqrt(math.pi / 2) * h}
        if cx not in width or cy not in width:
            raise ValueError("beam_area: a Lambertian focal-plane distribution has no simple "
                             "area: give area= in cm^2")
        area = width[cx](a) * width[cy](b)
        return area, (f"X/Y beam: {('top-hat', 'Gaussian')[cx]} half-width {a} cm x "
                      f"{('top-hat', 'Gaussian')[cy]} half-width {b} cm")
    elif kind == "plane_wave":
        if G is None:
            raise ValueError("beam_area: a plane wave's area is the top face Lx * Ly: give G")
        return G.Lx * G.Ly, f"plane wave on the top face {G.Lx} x {G.Ly} cm"
    else:
        raise ValueError(f"beam_area: a {kind} source has no beam area: give area= in cm^2")
    if code == 0:
        return math.pi * r**2, f"top-hat of radius {r} cm: pi r^2"
    if code == 1:
        return math.pi * r**2 / 2, f"Gaussian of 1/e^2 radius {r} cm: pi w^2 / 2 (peak)"
    raise ValueError("beam_area: a Lambertian focal-plane distribution has no simple area: "
                     "give area= in cm^2")


@dataclass(frozen=True)
class LaserPower:
    """MCmatlab's peak power ``P`` and where it came from."""

    P: float  #: W, incident peak power (MC.P, HS.P)
    area: float | None  #: cm^2, the beam area used (None: not needed)
    how: str  #: the conversion, in words, with the area's rule
    duration_on: float | None = None  #: s, pulse duration (pulsed lasers)
    duration_off: float | None = None  #: s, off time between pulses (1 / rate - duration)

    def __float__(self) -> float:
        return float(self.P)


def peak_power(*, irradiance=None, radiant_exposure=None, pulse_energy=None, average_power=None,
               pulse_duration=None, repetition_rate=None, area=None, model=None) -> LaserPower:
    """The incident peak power ``P`` (W) from one way of stating the laser.

    Give exactly one of

    * ``irradiance`` (W/cm^2, during the pulse or continuous): ``P = E A``;
    * ``radiant_exposure`` (J/cm^2 per pulse) and ``pulse_duration`` (s):
      ``P = H A / tau`` (rectangular pulses, as MCmatlab's on/off heat simulation);
    * ``pulse_energy`` (J) and ``pulse_duration``: ``P = Q / tau``;
    * ``average_power`` (W), ``repetition_rate`` (Hz) and ``pulse_duration``:
      ``P = P_avg / (f tau)``;

    ``area`` (cm^2) or ``model`` (its beam: :func:`beam_area`) gives the beam area where the
    conversion needs one. With ``repetition_rate``, ``duration_off = 1 / f - tau`` is
    returned for the heat simulation's pulse train. Values in mW/cm^2 are 1e-3 W/cm^2.
    """
    given = {k: v for k, v in (("irradiance", irradiance), ("radiant_exposure", radiant_exposure),
                               ("pulse_energy", pulse_energy), ("average_power", average_power))
             if v is not None}
    if len(given) != 1:
        raise ValueError("peak_power: give exactly one of irradiance, radiant_exposure, "
                         f"pulse_energy, average_power; got {sorted(given) or 'none'}")
    (what, value), = given.items()
    value = check_number(what, value, lo=0.0)
    tau = None if pulse_duration is None else check_number("pulse_duration", pulse_duration,
                                                           lo=0.0, lo_open=True)
    rate = None if repetition_rate is None else check_number("repetition_rate",
                                                             repetition_rate, lo=0.0,
                                                             lo_open=True)
    if tau is not None and rate is not None and tau * rate > 1:
        raise ValueError(f"pulse_duration = {tau} s is longer than the period 1 / "
                         f"repetition_rate = {1 / rate} s")
    needs_tau = what in ("radiant_exposure", "pulse_energy", "average_power")
    if needs_tau and tau is None:
        raise ValueError(f"peak_power: {what} needs pulse_duration (s), got None")
    if what == "average_power" and rate is None:
        raise ValueError("peak_power: average_power needs repetition_rate (Hz), got None")
    A, rule = None, ""
    if what in ("irradiance", "radiant_exposure"):
        if area is not None:
            A, rule = check_number("area", area, lo=0.0, lo_open=True), f"area {area} cm^2 given"
        elif model is not None:
            A, rule = beam_area(model)
        else:
            raise ValueError(f"peak_power: {what} needs the beam area: give area= (cm^2) or "
                             "model= (its light source's beam)")
    if what == "irradiance":
        P, how = value * A, f"{value} W/cm^2 x {A:.6g} cm^2 ({rule})"
    elif what == "radiant_exposure":
        P = value * A / tau
        how = f"{value} J/cm^2 x {A:.6g} cm^2 ({rule}) / {tau} s"
    elif what == "pulse_energy":
        P, how = value / tau, f"{value} J / {tau} s"
    else:
        P, how = value / (rate * tau), f"{value} W / ({rate} Hz x {tau} s)"
    off = None if rate is None or tau is None else 1.0 / rate - tau
    return LaserPower(P=P, area=A, how=f"P = {P:.6g} W = {how}", duration_on=tau,
                      duration_off=off)


def apply_power(model, power, n_pulses: int | None = None):
    """Set ``power`` (a :class:`LaserPower` or W) as the model's ``MC.P`` and ``HS.P``, and
    a pulsed laser's ``HS.duration_on``, ``duration_off`` (and ``n_pulses``). Returns the
    model."""
    P = float(power)
    check_number("P", P, lo=0.0, lo_open=True)
    model.MC.P = P
    model.HS.P = P
    if isinstance(power, LaserPower) and power.duration_on is not None:
        model.HS.duration_on = power.duration_on
        if power.duration_off is not None:
            model.HS.duration_off = power.duration_off
    if n_pulses is not None:
        model.HS.n_pulses = int(check_number("n_pulses", n_pulses, integer=True, lo=1))
    return model


def absolute_fluence_rate(model, P=None) -> np.ndarray:
    """``P * MC.NFR``, W/cm^2 (``P``: the model's ``MC.P`` unless given)."""
    return _absolute(model, "NFR", P)


def absolute_absorption(model, P=None) -> np.ndarray:
    """``P * MC.NA``, W/cm^3 (``P``: the model's ``MC.P`` unless given)."""
    return _absolute(model, "NA", P)


def _absolute(model, name: str, P):
    P = model.MC.P if P is None else P
    if P is None:
        raise ValueError(f"absolute {name}: the model's MC.P is None: give P (W)")
    values = getattr(model.MC, name)
    if values is None:
        raise ValueError(f"absolute {name}: run the Monte Carlo first (MC.{name} is None)")
    return float(check_number("P", P, lo=0.0)) * values


def source_seeds(seed: int | None, n: int) -> list[int | None]:
    """The seed of each of ``n`` sources' runs from the model's ``MC.seed`` (None: fresh)."""
    if seed is None:
        return [None] * n
    return [int(s) for s in np.random.SeedSequence(seed).generate_state(n, dtype=np.uint32)]


def run_light_sources(model, sources: list, powers: list[float], *, seeds=None, client=None):
    """Several light sources in one model, each with its own power (W).

    Runs the Monte Carlo of ``model`` once per source (a copy with ``MC.light_source`` set
    to it, ``MC.P`` to its power, and its own seed: ``seeds`` or :func:`source_seeds` of
    ``MC.seed``), then combines the runs with the powers as weights
    (:func:`~mcmatlab_py.combine.combine_models`). The result's ``NA``, ``NFR`` and the
    other maps are per W of the total power ``sum(powers)``, which becomes its ``MC.P`` and
    ``HS.P``: ``model.simulate_heat_distribution()`` on it heats with every source at its
    power. The sources share the wavelength, media and geometry of ``model``.
    """
    from .combine import combine_models
    from .model import LightSource

    if not sources:
        raise ValueError("run_light_sources: sources is empty")
    if len(powers) != len(sources):
        raise ValueError(f"run_light_sources: {len(sources)} sources but {len(powers)} powers")
    for k, src in enumerate(sources):
        if not isinstance(src, LightSource):
            raise ValueError(f"run_light_sources: sources[{k}] must be a LightSource, got "
                             f"{type(src).__name__}")
    powers = [check_number(f"powers[{k}]", p, lo=0.0, lo_open=True) for k, p in enumerate(powers)]
    seeds = source_seeds(model.MC.seed, len(sources)) if seeds is None else list(seeds)
    if len(seeds) != len(sources):
        raise ValueError(f"run_light_sources: {len(sources)} sources but {len(seeds)} seeds")
    runs = []
    for src, P, seed in zip(sources, powers, seeds, strict=True):
        m = copy.deepcopy(model)
        m.MC.light_source = copy.deepcopy(src)
        m.MC.P = P
        m.MC.seed = seed
        runs.append(m.run_monte_carlo(client=client))
    combined = combine_models(runs, powers=powers)
    combined.MC.P = combined.HS.P = float(sum(powers))
    return combined
