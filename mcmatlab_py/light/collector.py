"""The light collector and the deposition criteria (MCmatlab's ``lightCollector`` and
``depositionCriteria`` classes).

* :class:`LightCollector`: an objective lens (finite focal length ``f``: an image of the
  object plane at 1x magnification, ``res x res`` pixels over ``field_size``) or a fiber
  tip (``f = inf``: the power within the core ``diam`` and the acceptance angle
  ``asin(NA)``), placed at ``x, y, z`` and looking along the direction (``theta``,
  ``phi``). With ``n_time_bins > 0`` the detection is time-resolved between ``t_start``
  and ``t_end``; as in MCmatlab, two more bins hold what came before and after.
* :class:`DepositionCriteria`: which packets may add to ``NA``, ``NFR``, the image, the far
  field and the boundary maps (MCmatlab's examples 19 and 25).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fem.checks import check_number

from .._strict import StrictAttributes


def _finite(owner: str, name: str, value) -> float:
    return check_number(f"{owner}.{name}", value)


def _count(owner: str, name: str, value, allow_inf: bool = False) -> float | int:
    if allow_inf and value == math.inf:
        return math.inf
    return check_number(f"{owner}.{name}", value, integer=True, lo=0)


@dataclass
class LightCollector(StrictAttributes):
    """A lens or fiber that collects the escaping light (MCmatlab's ``MC.lightCollector``).

    Results (filled by the run): ``image`` (lens: (res, res) W/cm^2/W, the irradiance in
    the object plane at 1x; fiber: the collected power, W/W; time-resolved: one more axis
    of ``n_time_bins + 2`` time bins), ``X``, ``Y`` (cm, pixel centres), ``t`` (s, bin
    centres; the first and last bins hold all earlier and later light).
    """

    x: float = 0.0  #: cm, centre of the lens's focal (object) plane, or the fiber tip
    y: float = 0.0  #: cm
    z: float = 0.0  #: cm
    theta: float = 0.0  #: rad, polar angle of the direction the collector faces
    phi: float = math.pi / 2  #: rad, azimuth of that direction (MCmatlab's default pi/2)
    f: float = math.inf  #: cm, focal length of the lens; inf: a fiber
    diam: float = 1.0  #: cm, aperture (fiber core) diameter
    field_size: float = 1.0  #: cm, diameter of the imaged area (lens only)
    NA: float = 0.22  #: numerical aperture (fiber only)
    res: int = 1  #: pixels per side of the image (lens); 1 for a fiber
    t_start: float = 0.0  #: s, start of the detection window
    t_end: float = 1e-12  #: s, end of the detection window
    n_time_bins: int = 0  #: 0: not time-resolved

    # results
    image: object = None
    X: object = None
    Y: object = None
    t: object = None

    _owner_label = "MC.light_collector"
    _renamed = {"fieldSize": "field_size", "tStart": "t_start", "tEnd": "t_end",
                "nTimeBins": "n_time_bins"}

    @property
    def is_fiber(self) -> bool:
        return self.f == math.inf

    def validate(self, G) -> None:
        o = "MC.light_collector"
        for name in ("x", "y", "z", "theta", "phi", "t_start", "t_end"):
            setattr(self, name, _finite(o, name, getattr(self, name)))
        if not (self.f == math.inf or (isinstance(self.f, int | float) and 0 < self.f < math.inf)):
            raise ValueError(f"{o}.f must be a positive focal length (cm) or inf, got {self.f!r}")
        self.diam = check_number(f"{o}.diam", self.diam, lo=0.0, lo_open=True)
        self.field_size = check_number(f"{o}.field_size", self.field_size, lo=0.0, lo_open=True)
        self.NA = check_number(f"{o}.NA", self.NA, lo=0.0, lo_open=True)
        self.res = check_number(f"{o}.res", self.res, integer=True, lo=1)
        self.n_time_bins = check_number(f"{o}.n_time_bins", self.n_time_bins, integer=True, lo=0)
        if self.is_fiber and self.res != 1:
            raise ValueError(f"{o}.res must be 1 for a fiber (f = inf), got {self.res!r}")
        if self.n_time_bins and not self.t_end > self.t_start:
            raise ValueError(f"{o}.t_end must be after t_start, got {self.t_end!r} <= "
                             f"{self.t_start!r}")
        # the lens centre sits f behind the focal plane, along the viewing axis
        c = self.centre()
        if (abs(c[0]) < G.Lx / 2 and abs(c[1]) < G.Ly / 2 and abs(c[2] - G.Lz / 2) < G.Lz / 2):
            raise ValueError(f"{o}: the collector centre ({c[0]:.4g}, {c[1]:.4g}, {c[2]:.4g}) "
                             "cm is inside the cuboid")

    def axis(self) -> tuple[float, float, float]:
        """Unit vector of the viewing direction (theta, phi)."""
        return (math.sin(self.theta) * math.cos(self.phi),
                math.sin(self.theta) * math.sin(self.phi), math.cos(self.theta))

    def centre(self) -> tuple[float, float, float]:
        """cm: the lens centre (f behind the focal-plane centre) or the fiber tip."""
        if self.is_fiber:
            return (self.x, self.y, self.z)
        a = self.axis()
        return (self.x - self.f * a[0], self.y - self.f * a[1], self.z - self.f * a[2])


@dataclass
class DepositionCriteria(StrictAttributes):
    """Which packets deposit into the outputs (MCmatlab's ``MC.depositionCriteria``).

    All criteria hold together. Counts are of events in the media with index (0-based,
    as ``G.media``) in ``[min_medium_idx_to_consider, max_medium_idx_to_consider]``;
    refractions, reflections and interface transitions count by the medium entered. With
    ``evaluate_only_at_end_of_life`` (the default) a packet's whole path deposits if the
    criteria hold when it dies, escapes or is collected; else each deposit is judged on
    the counts so far. ``only_collected`` needs the end-of-life evaluation and a light
    collector. As in MCmatlab, a packet that dies inside (roulette, killed) meets a
    maximum only if that maximum is unlimited, and the deposits of a packet judged at the
    end of its life count times its final weight (a fraction of the launched weight: what
    escaped or reached the collector, or what was left when roulette ended it); the rest
    counts as absorbed by excluded packets in the energy balance.
    """

    min_scatterings: int = 0
    max_scatterings: float = math.inf
    min_refractions: int = 0
    max_refractions: float = math.inf
    min_reflections: int = 0
    max_reflections: float = math.inf
    min_interface_transitions: int = 0
    max_interface_transitions: float = math.inf
    min_medium_idx_to_consider: int = 0
    max_medium_idx_to_consider: float = math.inf
    only_collected: bool = False
    evaluate_only_at_end_of_life: bool = True

    _owner_label = "MC.deposition_criteria"
    _renamed = {"minMediumIdxToConsider": "min_medium_idx_to_consider (0-based)",
                "maxMediumIdxToConsider": "max_medium_idx_to_consider (0-based)"}

    KINDS = ("scatterings", "reflections", "refractions", "interface_transitions")

    @property
    def is_default(self) -> bool:
        return self == DepositionCriteria()

    def validate(self, use_light_collector: bool) -> None:
        o = "MC.deposition_criteria"
        for kind in self.KINDS:
            lo = _count(o, f"min_{kind}", getattr(self, f"min_{kind}"))
            hi = _count(o, f"max_{kind}", getattr(self, f"max_{kind}"), allow_inf=True)
            if hi < lo:
                raise ValueError(f"{o}.max_{kind} = {hi!r} is below min_{kind} = {lo!r}")
            setattr(self, f"min_{kind}", lo)
            setattr(self, f"max_{kind}", hi)
        self.min_medium_idx_to_consider = _count(o, "min_medium_idx_to_consider",
                                                 self.min_medium_idx_to_consider)
        self.max_medium_idx_to_consider = _count(o, "max_medium_idx_to_consider",
                                                 self.max_medium_idx_to_consider, allow_inf=True)
        if self.only_collected and not self.evaluate_only_at_end_of_life:
            raise ValueError(f"{o}.only_collected = True needs evaluate_only_at_end_of_life = True")
        if self.only_collected and not use_light_collector:
            raise ValueError(f"{o}.only_collected = True but MC.use_light_collector is False")
