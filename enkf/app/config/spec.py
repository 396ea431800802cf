"""A parsed identification config (:class:`IdentifyConfig`) and its ``[data]`` table."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mcmatlab_py.budget import check_steps

from ..readers import apply_time_offset, load_frames, read_sensor_csv

__all__ = ["DataSpec", "IdentifyConfig"]


@dataclass
class DataSpec:
    """The ``[data]`` table: where the measurements are and how to read them."""

    file: Path | None = None  #: default data file (``--data`` wins), relative to the config
    columns: list | None = None  #: CSV header names, in the order of sensors.positions
    time_offset: float | None = None  #: s, the laser's start on the data's clock


@dataclass
class IdentifyConfig:
    """A parsed identification config: the model (G, MC, HS) and the filter's settings."""

    model: object
    setup_kw: dict  #: TissueFilterSetup arguments, without grid/absorption/power/nominal
    grid: tuple  #: the filter's coarse voxels
    emulator_kw: dict
    exact: bool
    raw: dict  #: the parsed TOML (for run.json)
    param_bounds: np.ndarray | None = None  #: (n_par, 2) health-check range, None: default
    data: DataSpec = None  #: the [data] table
    rate: float | None = None  #: Hz, the sensor's nominal rate (sensors.rate)
    medium: int = 0  #: index in G.media of the medium whose parameters are estimated
    #: how the emulator's table is built: "auto" (white where it applies, else table),
    #: "table" (direct Monte Carlo per point) or "white"
    emulator_method: str = "auto"
    #: build each table point the first time a member needs it (the same numbers; a cold
    #: start pays only for the part of the table the ensemble visits), else all at once
    emulator_on_demand: bool = True
    #: ES-MDA updates of the smoother over the whole window after the filter (0: none;
    #: enkf.tissue.smooth_constant or smooth_drifting), reported in summary.json
    smoother_iterations: int = 0
    #: the smoother's ``knots`` (1: constant optics, smooth_constant; >= 2: optics drifting
    #: while heated, smooth_drifting), ``discrepancy`` and ``discrepancy_time`` (s)
    smoother_options: dict = None
    #: index in G.media of a second estimated medium (``filter.medium = [first, second]``:
    #: its optics are the parameters mua2, mus2), None: one
    second_medium: int | None = None
    #: the node grid of the second medium's optics (``filter.emulator.mua2_range``,
    #: ``mus2_range``, ``media_nodes``): TwoMediaEmulator.build's arguments
    media_nodes: dict = None
    #: the node grid of the beam's radius when it is estimated (``filter.emulator.
    #: radius_range``, ``radius_nodes``): BeamRadiusEmulator.build's arguments
    beam_nodes: dict = None
    #: a camera whose spot's centre is estimated from its first frames
    #: (``sensors.camera.spot_center = "auto"``): :class:`~enkf.app.config.camera.
    #: CameraRegistration`, which :meth:`read_data` uses
    camera_registration: object = None
    camera_emissivity: float | None = None  #: replaces a FLIR file's emissivity
    #: the ``[advice]`` table (:class:`~enkf.app.config.advice.AdviceSpec`), None without one
    advice: object = None

    @property
    def n_obs(self) -> int:
        """Data columns after ``time``: the point sensors, then the camera's pixels."""
        kw = self.setup_kw
        return len(kw["sensor_positions"]) + (kw["image"].n_pixels if "image" in kw else 0)

    def read_data(self, path: str | Path) -> tuple[np.ndarray, np.ndarray]:
        """``(times (M,) s, data (M, n_obs) deg C)`` of a CSV, or of an NPZ image series.

        Raises ValueError naming the file and the problem (see :func:`read_sensor_csv`
        and :func:`enkf.app.readers.load_frames`).
        """
        from ..frames import FLIR_SEQUENCE_SUFFIXES, FRAME_SUFFIXES

        data = self.data or DataSpec()
        camera = FRAME_SUFFIXES + FLIR_SEQUENCE_SUFFIXES  # sequences: refused by the reader
        if Path(path).suffix.lower() in camera or Path(path).is_dir():
            times, values = self._camera_data(path, data)
        else:
            times, values, _ = read_sensor_csv(path, self.n_obs, columns=data.columns,
                                               time_offset=data.time_offset)
        max_dt = self.setup_kw.get("max_dt")
        if max_dt is not None and len(times):
            check_steps(float(times[-1]) / max_dt, f"{path}: the filter's heat steps over "
                        f"{float(times[-1]):g} s of data in steps of HS.dt = {max_dt:g} s", "HS.dt")
        if not np.isfinite(values).any():
            raise ValueError(f"{path}: no usable reading: all {values.size} values are NaN "
                             "(the filter would report its prior as the estimate)")
        return times, values

    def _camera_data(self, path, data: DataSpec) -> tuple[np.ndarray, np.ndarray]:
        """The frames of a camera file or folder (enkf.app.frames), (n, ny*nx) deg C; with
        ``spot_center = "auto"`` the camera is registered from them first."""
        from ..frames import read_frames

        if "image" not in self.setup_kw or len(self.setup_kw["sensor_positions"]):
            raise ValueError(f"{path}: camera frames: the config needs [sensors.camera] and no "
                             "point sensors (sensors.positions = [])")
        image = self.setup_kw["image"]
        if Path(path).suffix.lower() == ".npz":
            times, frames = load_frames(path, image, flat=False)
            clock = False
        else:
            series = read_frames(path, rate=self.rate, emissivity=self.camera_emissivity)
            times, frames, clock = series.times, series.frames, series.clock
        if frames.shape[1:] != tuple(int(v) for v in image.shape):
            raise ValueError(f"{path}: frames are {frames.shape[1:]} pixels, the camera "
                             f"(sensors.camera.shape) {list(image.shape)}")
        if self.camera_registration is not None:
            self.setup_kw["image"] = self.camera_registration.estimate(frames, path)
        # times from a clock start at the first frame: the laser's start, unless
        # data.time_offset says otherwise
        offset = 0.0 if clock and data.time_offset is None else data.time_offset
        return apply_time_offset(path, times, self.setup_kw["image"].readings(frames), offset)

    def camera_record(self) -> dict:
        """summary.json's ``camera``: where the spot's centre was found (or nothing)."""
        reg = self.camera_registration
        if reg is None or reg.spot_center is None:
            return {}
        return {"camera": {"spot_center_px": [round(v, 3) for v in reg.spot_center],
                           "estimated_from": "the first frames"}}

    def emulator(self, *, cache_dir=None, progress=True, client=None):
        """The absorption emulator of this model on the filter's mesh (cached)."""
        from mcmatlab_py.emulator import AbsorptionEmulator, DirectMonteCarloAbsorption, EmulatorSpec

        spec = EmulatorSpec.from_model(self.model, medium=self.medium,
                                       mesh_divisions=tuple(self.grid), **self.emulator_kw)
        if self.exact:
            return DirectMonteCarloAbsorption(spec, client=client)
        kw = dict(cache_dir=cache_dir, progress=progress, out_of_range="clamp", client=client,
                  method=self.emulator_method, on_demand=self.emulator_on_demand)
        if self.second_medium is not None:
            from mcmatlab_py.emulator.media import TwoMediaEmulator

            return TwoMediaEmulator.build(spec, self.second_medium, **self.media_nodes, **kw)
        if self.beam_nodes is not None:
            from mcmatlab_py.emulator.media import BeamRadiusEmulator

            return BeamRadiusEmulator.build(spec, **self.beam_nodes, **kw)
        return AbsorptionEmulator.build(spec, **kw)

    def setup(self, absorption, seed: int | None = None):
        """The :class:`~enkf.tissue.TissueFilterSetup` with ``absorption``."""
        import fem

        from ...tissue import TissueFilterSetup

        G, HS = self.model.G, self.model.HS
        m = G.media[self.medium]  # the others keep their values (in the emulator's spec)
        nominal = {"mua": m.mua, "mus": m.mus, "VHC": m.VHC, "TC": m.TC}
        if self.second_medium is not None:
            m2 = G.media[self.second_medium]
            nominal.update(mua2=m2.mua, mus2=m2.mus)
        if self.beam_nodes is not None:
            nominal["beam_radius"] = float(self.model.MC.light_source.radius)
        kw = dict(self.setup_kw)
        if seed is not None:
            kw["seed"] = seed
        boundary = fem.HeatBoundary.from_mcmatlab(
            HS.heat_boundary_type,
            temperature=None if HS.heat_boundary_type != 2 else HS.T_ambient,
            h=HS.heat_transfer_coefficient if HS.heat_boundary_type == 2 else 0.0)
        return TissueFilterSetup.build(
            grid=fem.BoxGrid(*self.grid, G.Lx, G.Ly, G.Lz), absorption=absorption,
            power=HS.laser_power, nominal=nominal, T_initial=float(HS.T_initial),
            heat_boundary=boundary, **kw)
