"""``identify --follow FOLDER``: the frames a camera writes into a folder, as they come.

Each new camera file (:data:`enkf.app.frames.FRAME_SUFFIXES`; hidden files and other
suffixes, such as a writer's ``.tmp``, are passed over) is read as soon as it can be: a
file that cannot be read yet is tried again while it grows (a writer at work), and
skipped with a warning naming it once it has stayed the same for ``settle_s`` and still
cannot be read. Files are taken in natural name order (``IR_2`` before ``IR_10``) as they
appear; a frame whose time is not after the last one's is skipped with a warning. The
stream stops at a file named ``END`` (any case, any suffix), once every frame written
before it is read, or after ``idle_timeout_s`` without a new file.

Times: a clock's (FLIR, TIFF tags) are made seconds since the first frame, which is the
baseline at the laser's start and is not assimilated; files without times get
``k / rate``. The filter may start only once the first frames are in (a camera whose
spot's centre is estimated from them): ``start(times, frames)`` is called with the frames
so far until it returns the identifier, which then assimilates them in order.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .frames import frame_files, read_frame_file
from .readers import SHOWN_SKIPS

__all__ = ["FrameFeed", "end_marker", "follow_folder", "frame_times"]


def end_marker(folder: Path) -> bool:
    """Whether ``folder`` holds the file that ends a stream: ``END``, any case, any suffix."""
    return any(e.name.split(".")[0].upper() == "END" for e in os.scandir(folder))


class FrameFeed:
    """The frames of a followed camera, in order, to the filter (``follow_folder`` and
    :func:`enkf.app.follow_file.follow_file`).

    Until ``start(times (k,) s, frames (k, ny, nx))`` returns the identifier the frames
    are kept; it then assimilates them in order, and every later frame as it comes. A frame
    whose time is not after the last one's is skipped (the baseline at t = 0 silently), as
    is a frame whose every pixel is NaN. ``skip(name, reason)`` records a skipped frame.
    """

    def __init__(self, start: Callable, on_update: Callable, skip: Callable,
                 on_frame: Callable | None = None):
        self.start, self.on_update, self.skip, self.on_frame = start, on_update, skip, on_frame
        self.identifier = None
        self.count = 0  #: frames assimilated
        self._times, self._frames = [], []  # kept until the filter starts

    def _assimilate(self, t: float, frame: np.ndarray, name: str) -> None:
        ident = self.identifier
        if t <= ident.time:
            if t > 0 or ident.history:
                self.skip(name, f"time {t!r} s is not after the last frame's {ident.time!r} s")
            return
        est = ident.update(t, ident.setup.sensors.image.readings(frame))
        self.count += 1
        self.on_update(est, name)

    def add(self, t: float, frame: np.ndarray, name: str) -> None:
        """One frame (ny, nx) deg C at ``t`` s, read from ``name``."""
        if not np.isfinite(frame).any():
            self.skip(name, f"every pixel of the frame at {t:g} s is NaN")
            return
        if self.on_frame is not None:
            self.on_frame(t, frame)
        if self.identifier is not None:
            self._assimilate(t, frame, name)
            return
        self._times.append(t)
        self._frames.append(frame)
        self.identifier = self.start(np.array(self._times), np.array(self._frames))
        if self.identifier is not None:
            self._flush(name)

    def _flush(self, name: str) -> None:
        for tb, fb in zip(self._times, self._frames, strict=True):
            self._assimilate(tb, fb, name)
        self._times, self._frames = [], []

    def finish(self) -> int:
        """The stream ended: a filter still waiting starts with the frames it has (``start``
        with ``final=True``). Returns the number of frames assimilated."""
        if self.identifier is None and self._times:
            self.identifier = self.start(np.array(self._times), np.array(self._frames),
                                         final=True)
            self._flush("(the first frames)")
        return self.count


def frame_times(series, n_before: int, rate: float | None,
                t_first: float | None) -> tuple[np.ndarray, float | None]:
    """The times (n,) s of the frames of ``series`` (a :class:`enkf.app.frames.FrameSeries`)
    that follow ``n_before`` frames of the stream, and the first frame's clock.

    A clock's times are made seconds since the stream's first frame (``t_first``, set by
    the first series that has one); frames without times get ``k / rate``.
    """
    n = series.frames.shape[0]
    if series.times is None:
        if rate is None:
            raise ValueError(f"{series.source}: the frames carry no times: set sensors.rate "
                             "(Hz) in the config")
        return (n_before + np.arange(n)) / float(rate), t_first
    if series.clock:
        if t_first is None:
            t_first = float(series.times[0])
        return series.times - t_first, t_first
    return series.times, t_first


def follow_folder(path: str | Path, start: Callable, on_update: Callable, *,
                  poll_s: float = 0.02, idle_timeout_s: float = 10.0,
                  wait_for_file_s: float = 10.0, settle_s: float = 1.0,
                  rate: float | None = None, emissivity: float | None = None,
                  on_frame: Callable | None = None,
                  warn: Callable[[str], None] | None = None,
                  skipped: list | None = None) -> int:
    """Feed the frames written into the folder ``path`` to the filter as they arrive.

    Parameters
    ----------
    start : callable
        ``start(times (k,) s, frames (k, ny, nx), final=False) -> identifier or None``:
        the frames so far; None to wait for more (the identifier then gets them all);
        ``final=True`` when the stream ended first (it must then return one, or raise).
    on_update : callable
        ``on_update(estimate, name)`` after each frame assimilated, before the next is read.
    on_frame : callable, optional
        ``on_frame(time, frame (ny, nx))`` for every frame read (the live page's picture).
    rate : Hz, for files without times.
    warn, skipped : as for :func:`enkf.app.readers.follow_csv`; ``skipped`` receives
        ``(file name, reason)``.

    Returns the number of frames assimilated. Raises ValueError for a folder that does not
    appear, is not a folder, or frames of another shape than the first.
    """
    if warn is None:
        def warn(message):
            print(f"warning: {message}", file=sys.stderr)
    skipped = [] if skipped is None else skipped
    folder = Path(path)
    deadline = time.monotonic() + wait_for_file_s
    while not folder.exists():
        if time.monotonic() > deadline:
            raise ValueError(f"--follow: {folder} did not appear within {wait_for_file_s:g} s")
        time.sleep(poll_s)
    if not folder.is_dir():
        raise ValueError(f"--follow: {folder} is not a folder")
    done: set[str] = set()
    waiting: dict[str, tuple] = {}  # name -> (size, mtime, since) of a file not read yet
    t_first = None  # the first frame's clock
    n_frames = 0
    shape = None
    last = time.monotonic()

    def skip(name, reason):
        skipped.append((name, reason))
        if len(skipped) <= SHOWN_SKIPS:
            warn(f"--follow: {folder / name}: {reason}: skipped")

    feed = FrameFeed(start, on_update, skip, on_frame)

    while True:
        # END is looked for before the listing, never after: the frames that arrived while
        # the filter worked on the last listing (and were written before END) are in this
        # one, so the stream ends only once they are read
        ended = end_marker(folder)
        new = [f for f in frame_files(folder) if f.name not in done]
        progressed = False
        for f in new:
            try:
                st = os.stat(f)
            except FileNotFoundError:
                continue  # renamed or removed between the listing and now
            sig = (st.st_size, st.st_mtime_ns)
            try:
                series = read_frame_file(f, emissivity)
            except ValueError as err:
                prev = waiting.get(f.name)
                if prev is None or prev[:2] != sig:  # new, or still being written
                    waiting[f.name] = (*sig, time.monotonic())
                elif time.monotonic() - prev[2] > settle_s:
                    done.add(f.name)
                    waiting.pop(f.name, None)
                    skip(f.name, str(err).removeprefix(f"{f}: "))
                continue
            done.add(f.name)
            waiting.pop(f.name, None)
            progressed = True
            if shape is None:
                shape = series.frames.shape[1:]
            elif series.frames.shape[1:] != shape:
                skip(f.name, f"frames of {series.frames.shape[1:]} pixels, the first file's {shape}")
                continue
            n = series.frames.shape[0]
            times, t_first = frame_times(series, n_frames, rate, t_first)
            n_frames += n
            for t, frame in zip(times, series.frames, strict=True):
                feed.add(float(t), frame, f.name)
        if progressed or waiting:
            last = time.monotonic()
        if ended and not waiting:
            break
        if time.monotonic() - last > idle_timeout_s:
            break
        if not progressed:
            time.sleep(poll_s)
    for name in waiting:
        skip(name, "could not be read when the stream ended (a writer that stopped?)")
    return feed.finish()
