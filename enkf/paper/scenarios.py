"""The paper's scenarios: Table 1's tissue, the laser of each scenario, the true optics,
and the paper's model in MCmatlab style (see :mod:`enkf.paper` for the choices made
where the paper is silent)."""

from __future__ import annotations

import numpy as np

from ..tissue.image import ThermalImage
from ..tissue.parameters import tracked_points

__all__ = [
    "CAMERA",
    "PULSES",
    "SCENARIOS",
    "TABLE",
    "camera_image",
    "heating_time",
    "mua_ramp",
    "mus_ramp",
    "paper_model",
    "train_optics",
    "true_parameters",
]

SCENARIOS = ("constant", "time-varying", "all-params", "pulse-train")
TABLE = {"mua": 1.0, "mus": 100.0, "VHC": 3.76, "TC": 0.0037}  # Table 1 of the paper


def mua_ramp(t):
    """The paper's time-varying absorption (eq. TV_absorption), cm^-1."""
    return 0.6 * t + 1.0 if t <= 5.0 else 4.0


def mus_ramp(t):
    """The paper's time-varying scattering (eq. TV_scattering), cm^-1."""
    return 80.0 * t + 100.0 if t <= 5.0 else 500.0


#: laser of each scenario: (P W, duration_on s, duration_off s, n_pulses). Beyond the paper,
#: "pulse-train" fires three 2 s pulses of 0.75 W, 3 s apart, and the tissue changes
#: while it is heated: mua and mus rise during each pulse and hold between pulses, so
#: each pulse meets different optics (see train_optics)
PULSES = {"constant": (0.5, 5.0, 10.0, 1), "time-varying": (0.5, 5.0, 10.0, 1),
          "all-params": (0.5, 5.0, 10.0, 1), "pulse-train": (0.75, 2.0, 3.0, 3)}


def heating_time(t: float, scenario: str = "pulse-train") -> float:
    """s of laser-on time before ``t``."""
    _, on, off, n = PULSES[scenario]
    period = on + off
    k = min(int(t // period), n)
    return float(k * on + (min(t - k * period, on) if k < n else 0.0))


def train_optics(t: float) -> tuple[float, float]:
    """(mua, mus) cm^-1 of the pulse-train scenario: +0.3 and +40 per second of heating."""
    h = heating_time(t)
    return 1.0 + 0.3 * h, 100.0 + 40.0 * h


def true_parameters(scenario: str, times: np.ndarray) -> dict[str, np.ndarray]:
    """Truth of every parameter at ``times`` (s)."""
    times = np.asarray(times, float)
    if scenario == "constant":
        mua = np.full(times.shape, TABLE["mua"])
        mus = np.full(times.shape, TABLE["mus"])
    elif scenario == "pulse-train":
        optics = np.array([train_optics(t) for t in times]).reshape(-1, 2)
        mua, mus = optics[:, 0], optics[:, 1]
    else:
        mua = np.array([mua_ramp(t) for t in times])
        mus = np.array([mus_ramp(t) for t in times])
    return {"mua": mua, "mus": mus, "VHC": np.full(times.shape, TABLE["VHC"]),
            "TC": np.full(times.shape, TABLE["TC"])}


def paper_model(grid=(100, 100, 50), n_photons: int = 10**7, seed: int = 1, progress=True,
                scenario: str = "constant"):
    """The paper's model (MCmatlab style) on a voxel grid ``(nx, ny, nz)``; the laser of
    ``scenario`` (:data:`PULSES`)."""
    from mcmatlab_py import Medium, Model

    model = Model()
    model.G.nx, model.G.ny, model.G.nz = grid
    model.G.Lx, model.G.Ly, model.G.Lz = 0.5, 0.5, 0.25
    model.G.media = [Medium("standard tissue", mua=TABLE["mua"], mus=TABLE["mus"], g=0.9,
                            n=1.3, VHC=TABLE["VHC"], TC=TABLE["TC"])]
    MC = model.MC
    MC.n_photons_requested = n_photons
    MC.seed = seed
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.progress = progress
    MC.light_source.source_type = "tophat"
    MC.light_source.radius = 0.1
    HS = model.HS
    HS.P, HS.duration_on, HS.duration_off, HS.n_pulses = PULSES[scenario]
    HS.dt = 0.1
    HS.T_initial = 0.0
    HS.heat_boundary_type = 0
    HS.temp_sensor_positions = [tuple(p) for p in tracked_points()]
    HS.progress = progress
    return model


#: the camera of the image experiments: 16 x 16 pixels of 250 um over the beam
CAMERA = (-0.2, 0.2, -0.2, 0.2, 16, 16, 4)


def camera_image(camera: tuple):
    """The :class:`enkf.tissue.image.ThermalImage` of a ``TruthConfig.camera`` tuple."""
    x0, x1, y0, y1, ny, nx, sub = camera
    return ThermalImage((x0, x1), (y0, y1), (int(ny), int(nx)), subsamples=int(sub))
