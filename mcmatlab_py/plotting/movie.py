"""The heat run's live temperature slices and its movie (MCmatlab's ``makeMovie``).

At every update of a heat run :class:`TemperatureMonitor` redraws the three
orthogonal temperature slices (at ``HS.slice_positions``, by default through the hottest
voxel of each update; colour range ``HS.plot_temp_limits``) and, for a movie, keeps the
rendered frame; the movie opens on the geometry illustration (first run only) and the
frames are written as an H.264 MP4 by the ffmpeg binary of the imageio-ffmpeg package
(:func:`write_movie`), holding the first and last frame for a second as MCmatlab does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .figures import heat_slices
from .slices import orthogonal_slices, update_slices

__all__ = ["FPS", "HOLD_FRAMES", "TemperatureMonitor", "write_movie"]

FPS = 30  #: frames per second of the movie
HOLD_FRAMES = 30  #: the first and last frames are repeated this many times (a second)
FRAME_SIZE = (11.0, 4.0)  #: inches at 100 dpi: 1100 x 400 pixels


class TemperatureMonitor:
    """Live slices of a heat run and the frames of its movie."""

    def __init__(self, model, M, *, show: bool, record: bool):
        import matplotlib.pyplot as plt
        from matplotlib.colors import Normalize

        self.model, self.M, self.show, self.record = model, M, show, record
        self.frames: list[np.ndarray] = []
        G, HS = model.G, model.HS
        self.limits = np.asarray(HS.plot_temp_limits, float)
        empty = np.full((G.nx, G.ny, G.nz), np.nan)
        self.positions = heat_slices(HS, empty)  # the user's, or the middle until it heats
        self.fig = plt.figure(figsize=FRAME_SIZE, dpi=100, layout="constrained")
        if self.fig.canvas.manager is not None:
            self.fig.canvas.manager.set_window_title("Temperature evolution")
        self.axes, self.images = orthogonal_slices(
            self.fig, empty, G, self.positions, cmap="hot", norm=Normalize(0, 1),
            label="temperature [deg C]", title="Temperature evolution")

    def _rgb(self, fig) -> np.ndarray:
        fig.canvas.draw()
        rgba = np.asarray(fig.canvas.buffer_rgba())
        h, w = rgba.shape[0] - rgba.shape[0] % 2, rgba.shape[1] - rgba.shape[1] % 2
        return np.ascontiguousarray(rgba[:h, :w, :3])  # even sizes for yuv420p

    def geometry_frame(self) -> None:
        """Record the geometry illustration as the movie's first frame."""
        import matplotlib.pyplot as plt

        G = self.model.G
        fig = plt.figure(figsize=FRAME_SIZE, dpi=100, layout="constrained")
        orthogonal_slices(fig, self.M, G, self.positions,
                          categories=[m.name for m in G.media], title="Geometry illustration")
        self.frames.append(self._rgb(fig))
        plt.close(fig)

    def update(self, T_vox: np.ndarray, t: float, *, record: bool | None = None) -> None:
        """Show the voxel temperatures (deg C) at time ``t`` (s); keep the frame if recording."""
        HS = self.model.HS
        self.positions = heat_slices(HS, T_vox - HS.T_initial)
        lo = float(T_vox.min()) if np.isnan(self.limits[0]) else self.limits[0]
        hi = float(T_vox.max()) if np.isnan(self.limits[1]) else self.limits[1]
        if hi <= lo:
            hi = lo + 1.0
        update_slices(self.axes, self.images, T_vox, self.model.G, self.positions)
        for im in self.images:
            im.set_clim(lo, hi)
        self.fig.suptitle(f"Temperature evolution, t = {t:#.3g} s")
        if self.record if record is None else record:
            self.frames.append(self._rgb(self.fig))
        if self.show:
            import matplotlib.pyplot as plt

            plt.pause(0.001)

    def finish(self, HS) -> None:
        """Write (or, with ``defer_movie_write``, keep) the movie; close the figure unless shown."""
        import matplotlib.pyplot as plt

        if self.record and self.frames:
            frames = np.stack(self.frames)
            if HS.movie_frames is not None and HS.movie_frames.shape[1:] == frames.shape[1:]:
                frames = np.concatenate([HS.movie_frames, frames])
            if HS.defer_movie_write:
                HS.movie_frames = frames
            else:
                write_movie(frames, HS.movie_path)
                HS.movie_frames = None
        if not self.show:
            plt.close(self.fig)


def write_movie(frames: np.ndarray, path: str | Path, fps: int = FPS,
                hold: int = HOLD_FRAMES) -> Path:
    """Write RGB ``frames`` (n, h, w, 3) uint8 as an H.264 MP4 through imageio-ffmpeg.

    The first and last frames are held for ``hold`` frames. ``h`` and ``w`` must be even.
    """
    try:
        import imageio_ffmpeg
    except ImportError as err:  # pragma: no cover - depends on the installation
        raise ImportError("HS.make_movie needs the imageio-ffmpeg package: "
                          "pip install 'tissue-enkf[movie]'") from err
    frames = np.asarray(frames, dtype=np.uint8)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[1] % 2 or frames.shape[2] % 2:
        raise ValueError(f"frames must be (n, h, w, 3) with even h and w, got {frames.shape}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    h, w = frames.shape[1:3]
    writer = imageio_ffmpeg.write_frames(str(path), (w, h), fps=fps, codec="libx264",
                                         pix_fmt_out="yuv420p", macro_block_size=1,
                                         ffmpeg_log_level="error")
    writer.send(None)  # start ffmpeg
    try:
        for k in np.r_[np.zeros(hold, int), np.arange(len(frames)), np.full(hold, len(frames) - 1)]:
            writer.send(np.ascontiguousarray(frames[k]))
    finally:
        writer.close()
    return path
