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

__all__ = ["follow_folder"]


def _end_marker(folder: Path) -> bool:
    return any(e.name.split(".")[0].upper() == "END" for e in os.scandir(folder))


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
    identifier = None
    buffered_t, buffered_f = [], []
    t_first = None  # the first frame's clock
    count = n_frames = 0
    shape = None
    last = time.monotonic()

    def skip(name, reason):
        skipped.append((name, reason))
        if len(skipped) <= SHOWN_SKIPS:
            warn(f"--follow: {folder / name}: {reason}: skipped")

    def assimilate(t, frame, name):
        nonlocal count
        if t <= identifier.time:
            if t > 0 or identifier.history:
                skip(name, f"time {t!r} s is not after the last frame's {identifier.time!r} s")
            return
        est = identifier.update(t, identifier.setup.sensors.image.readings(frame))
        count += 1
        on_update(est, name)

    while True:
        # END is looked for before the listing, never after: the frames that arrived while
        # the filter worked on the last listing (and were written before END) are in this
        # one, so the stream ends only once they are read
        ended = _end_marker(folder)
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
            if series.times is None:
                if rate is None:
                    raise ValueError(f"{f}: the frames carry no times: set sensors.rate (Hz) in "
                                     "the config")
                times = (n_frames + np.arange(n)) / float(rate)
            elif series.clock:
                if t_first is None:
                    t_first = float(series.times[0])
                times = series.times - t_first
            else:
                times = series.times
            n_frames += n
            for t, frame in zip(times, series.frames, strict=True):
                if not np.isfinite(frame).any():
                    skip(f.name, f"every pixel of the frame at {t:g} s is NaN")
                    continue
                if on_frame is not None:
                    on_frame(float(t), frame)
                if identifier is None:
                    buffered_t.append(float(t))
                    buffered_f.append(frame)
                    identifier = start(np.array(buffered_t), np.array(buffered_f))
                    if identifier is not None:
                        for tb, fb in zip(buffered_t, buffered_f, strict=True):
                            assimilate(tb, fb, f.name)
                        buffered_t, buffered_f = [], []
                else:
                    assimilate(float(t), frame, f.name)
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
    if identifier is None and buffered_t:
        identifier = start(np.array(buffered_t), np.array(buffered_f), final=True)
        for tb, fb in zip(buffered_t, buffered_f, strict=True):
            assimilate(tb, fb, "(the first frames)")
    return count

