"""``[sensors.camera]``: the camera's pixels on the tissue, and its files read as data.

Two ways to place the camera (``sensors.camera``)::

    shape = [16, 16]              # [ny, nx], as the frames are
    x_range = [-0.2, 0.2]         # cm: the imaged region of the top face, the spot at x = y = 0
    y_range = [-0.2, 0.2]

or, as a bench sets it up (registration)::

    shape = [64, 64]
    pixel_size = 0.0125           # cm (or [dx, dy])
    spot_center = [31.5, 31.5]    # [column, row] in pixels of the laser spot's centre,
                                  # or "auto": estimated from the first frames
    rotation = 0.0                # deg, from the tissue's x axis to the image's rows
    mirror = false                # the image is mirrored
    emissivity = 0.98             # optional: replaces a FLIR file's emissivity

With ``spot_center = "auto"`` the centre is the rise-weighted centre of the first frames
that show the spot (:func:`enkf.tissue.image.estimate_spot_center`); the run records it.
"""

from __future__ import annotations

import numpy as np

from fem.checks import shorten
from mcmatlab_py.config import ConfigError

from ...tissue.image import ThermalImage, estimate_spot_center

__all__ = ["CAMERA_KEYS", "CameraRegistration", "camera_settings"]

CAMERA_KEYS = {"x_range", "y_range", "shape", "noise_var", "subsamples", "binning",
               "model_error_rel_std", "model_error_lengths", "pixel_size", "spot_center",
               "rotation", "mirror",
               "emissivity"}


class CameraRegistration:
    """What places a camera whose spot's centre is estimated from its frames."""

    def __init__(self, shape, pixel_size, rotation, mirror, kw, G):
        self.shape, self.pixel_size, self.rotation, self.mirror = shape, pixel_size, rotation, mirror
        self.kw, self.G = kw, G
        self.spot_center = None  #: (column, row) once estimated

    def image(self, spot_center) -> ThermalImage:
        """The camera with the spot's centre at ``spot_center`` (checked on the tissue)."""
        image = ThermalImage.registered(self.shape, self.pixel_size, spot_center, self.rotation,
                                        self.mirror, **self.kw)
        _inside(image, self.G, f"with the spot's centre at column {spot_center[0]:.2f}, row "
                               f"{spot_center[1]:.2f}")
        return image

    def estimate(self, frames: np.ndarray, where, complete: bool = True) -> ThermalImage | None:
        """The registered camera from its first frames ``(n, ny, nx)``, None while they do
        not show the spot yet (``complete=False``); ValueError naming ``where`` when a whole
        file never does."""
        c = estimate_spot_center(frames, float(np.sqrt(self.kw["noise_var"])), complete=complete)
        if c is None:
            if complete:
                raise ValueError(f"{where}: the laser spot cannot be found in the frames (no "
                                 "pixel rises 20 noise sds above the first frame): set "
                                 "sensors.camera.spot_center = [column, row]")
            return None
        self.spot_center = c
        return self.image(c)


def _inside(image: ThermalImage, G, how: str = "") -> None:
    x0, x1, y0, y1 = image.footprint_bounds()
    tol = 1e-9 * max(G.Lx, G.Ly)
    if x0 < -G.Lx / 2 - tol or x1 > G.Lx / 2 + tol or y0 < -G.Ly / 2 - tol or y1 > G.Ly / 2 + tol:
        raise ConfigError(f"sensors.camera{' ' + how if how else ''} sees x in [{x0:.4g}, "
                          f"{x1:.4g}], y in [{y0:.4g}, {y1:.4g}] cm, outside the top face "
                          f"([-{G.Lx / 2}, {G.Lx / 2}] x [-{G.Ly / 2}, {G.Ly / 2}] cm): a "
                          "smaller region (fewer pixels) or a larger G.Lx, G.Ly")


def camera_settings(cam: dict, G, num, pair, model_error: dict
                    ) -> tuple[ThermalImage, CameraRegistration | None, float | None]:
    """``(image, registration or None, emissivity or None)`` of ``[sensors.camera]``.

    ``num``, ``pair``: the config's number checks; ``model_error``: the ThermalImage
    keywords of the camera's model error. With ``spot_center = "auto"`` the image is a
    placeholder (the spot at the image's centre) until :meth:`CameraRegistration.estimate`.
    """
    if "shape" not in cam:
        raise ConfigError("sensors.camera.shape is missing")
    shape = cam["shape"]
    if not (isinstance(shape, list) and len(shape) == 2):
        raise ConfigError(f"sensors.camera.shape must be [ny, nx], got {shorten(repr(shape))}")
    shape = tuple(num(f"sensors.camera.shape[{i}]", v, integer=True, lo=1)
                  for i, v in enumerate(shape))
    kw = dict(noise_var=num("sensors.camera.noise_var", cam.get("noise_var", 0.01), positive=True),
              subsamples=num("sensors.camera.subsamples", cam.get("subsamples", 4), integer=True,
                             lo=1),
              binning=num("sensors.camera.binning", cam.get("binning", 1), integer=True, lo=1),
              **model_error)
    if shape[0] % kw["binning"] or shape[1] % kw["binning"]:
        raise ConfigError(f"sensors.camera.binning must divide the shape {list(shape)}, got "
                          f"{kw['binning']}")
    emissivity = None
    if "emissivity" in cam:
        emissivity = num("sensors.camera.emissivity", cam["emissivity"], positive=True, hi=1.0)
    rotation = num("sensors.camera.rotation", cam.get("rotation", 0.0), lo=-360.0, hi=360.0)
    mirror = cam.get("mirror", False)
    if not isinstance(mirror, bool):
        raise ConfigError(f"sensors.camera.mirror must be true or false, got {shorten(repr(mirror))}")
    placed = {"pixel_size", "spot_center"} & set(cam)
    ranged = {"x_range", "y_range"} & set(cam)
    if placed and ranged:
        raise ConfigError("sensors.camera: give x_range and y_range, or pixel_size and "
                          f"spot_center, not both (got {sorted(placed | ranged)})")
    if placed:
        for k in ("pixel_size", "spot_center"):
            if k not in cam:
                raise ConfigError(f"sensors.camera.{k} is missing (with "
                                  f"{(placed - {k}).pop()})")
        ps = cam["pixel_size"]
        ps = [ps, ps] if not isinstance(ps, list) else ps
        if len(ps) != 2:
            raise ConfigError(f"sensors.camera.pixel_size must be a length or [dx, dy] (cm), got "
                              f"{shorten(repr(cam['pixel_size']))}")
        ps = tuple(num(f"sensors.camera.pixel_size[{i}]", v, positive=True, hi=10.0)
                   for i, v in enumerate(ps))
        reg = CameraRegistration(shape, ps, rotation, mirror, kw, G)
        sc = cam["spot_center"]
        if sc == "auto":
            return (ThermalImage.registered(shape, ps, ((shape[1] - 1) / 2, (shape[0] - 1) / 2),
                                            rotation, mirror, **kw), reg, emissivity)
        if not (isinstance(sc, list) and len(sc) == 2):
            raise ConfigError(f"sensors.camera.spot_center must be [column, row] (pixels) or "
                              f"\"auto\", got {shorten(repr(sc))}")
        sc = tuple(num(f"sensors.camera.spot_center[{i}]", v, lo=-1e4, hi=1e4)
                   for i, v in enumerate(sc))
        return reg.image(sc), None, emissivity
    for k in ("x_range", "y_range"):
        if k not in cam:
            raise ConfigError(f"sensors.camera.{k} is missing (or give pixel_size and "
                              "spot_center)")
    image = ThermalImage(pair("sensors.camera.x_range", cam["x_range"]),
                         pair("sensors.camera.y_range", cam["y_range"]), shape,
                         rotation=rotation, mirror=mirror, **kw)
    _inside(image, G)
    return image, None, emissivity
