"""``identify --follow FILE``: one camera file that grows while the camera writes it.

A TIFF stack (``.tif``, ``.tiff``: pages appended, one a frame) or an HDF5 file (``.h5``,
``.hdf5``, ``.hdf``: dataset ``frames`` (k, ny, nx) deg C resized along its first axis) is
read as it grows, and each frame goes to the filter as :func:`enkf.app.follow_frames.follow_folder`
gives it the frames of a folder (:class:`enkf.app.follow_frames.FrameFeed`): the same
``start``, ``on_update`` and ``on_frame``, the same skips.

Only the frames not read yet are read:

- TIFF, through ``tifffile``: the file's chain of pages is followed on from the last page
  read (a page at a time, as ``tifffile.TiffWriter.write`` or ``imwrite(..., append=True)``
  add them; a contiguous series, such as an ImageJ hyperstack, gets its pages only when
  its writer closes it). Times, as :func:`enkf.app.frames.read_tiff` reads them, from the
  first page on: ``times`` in tifffile's JSON metadata (each page's own, or its series'),
  ImageJ's ``finterval``, or each page's ``DateTime`` (and ``SubSecTime``);
- HDF5, through ``h5py``: the rows of ``frames`` after those read, with their ``times``
  (a dataset as long as ``frames``, or growing just behind it: a frame waits for its time)
  or the attribute ``rate`` (Hz) of ``frames``. The file is opened at each change for SWMR
  reading (``swmr=True``: a writer in SWMR mode is read consistently while it writes), and
  without HDF5's file locks, so that the follower never stops the camera's writer from
  opening the file.

Files without times get ``k / rate`` (``sensors.rate``); a clock's times are made seconds
since the first frame, which is the baseline at the laser's start.

A file being written may be momentarily unreadable: it is read again while it changes.
The newest frame is taken once a later one follows it or the file has not changed for one
poll (a writer that puts the page's header before its pixels is not read half way). A file
that has not changed for ``settle_s`` and still cannot be read is refused (ValueError)
when none of its frames was read; after that it is reported once with a warning, read
again when it changes, and recorded as skipped when the stream ends. A frame of another
shape than the first, every pixel NaN, with infinite values, without the time its
predecessors had, or whose time is not after the last one's, is skipped with a warning;
the first frame's problems refuse the file. A file replaced
(written anew and renamed into place) or truncated is read on from the frame after the
last one read, after a warning.

The stream ends as a folder's does: at a file named ``END`` (any case, any suffix) beside
the followed file, once every frame written before it is read, or after
``idle_timeout_s`` without a change of the file.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import struct
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from fem.checks import shorten
from mcmatlab_py.files import open_regular

from .follow_frames import FrameFeed, end_marker, frame_times
from .frames import (
    FLIR_SEQUENCE_SUFFIXES,
    FRAME_SUFFIXES,
    HDF5_SUFFIXES,
    TIFF_SUFFIXES,
    FrameSeries,
    _dataset,
    _declared,
    _frames_array,
    _page_clock,
    read_frame_file,
    require,
)
from .readers import SHOWN_SKIPS

__all__ = ["CAMERA_SUFFIXES", "GROWING_SUFFIXES", "follow_file"]

#: the camera files followed as they grow (others: the folder they are written into)
GROWING_SUFFIXES = TIFF_SUFFIXES + HDF5_SUFFIXES
#: the suffixes that ``--follow FILE`` sends here (the others than GROWING_SUFFIXES are
#: refused with what to follow instead); any other file is a CSV
CAMERA_SUFFIXES = FRAME_SUFFIXES + FLIR_SEQUENCE_SUFFIXES


class _Unreadable(Exception):
    """The file cannot be read now (a writer at work, or damage): read again if it changes."""


class _BadFrame(ValueError):
    """One frame that is read but cannot be used: skipped (the first refuses the file)."""


@contextlib.contextmanager
def _tifffile_quiet():
    # tifffile logs (rather than raises) a page offset past the end of the file: the usual
    # state of a file whose next page is being written, said here by what follows
    log = logging.getLogger("tifffile")
    level = log.level
    log.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        log.setLevel(level)


class _NotWhole(Exception):
    """A page of a growing file not written whole yet: read again at the next change."""


class _TiffPages:
    """The pages of a growing TIFF file, each read once."""

    def __init__(self, path: Path, settle_s: float = 1.0):
        self.path = path
        self.tifffile = require("tifffile", f"the TIFF file {str(path)!r}")
        self.reset()
        self.timing = None  # where the times come from, fixed by the first page
        self.finterval = None  # s, ImageJ's
        self.pending: list[float] = []  # tifffile metadata's times not given to a page yet
        self.settle_s = settle_s  # s: how long a page without its time is read again
        self.retried: dict[int, float] = {}  # page: when it was first read without its time

    def reset(self) -> None:
        """Follow the chain from its start again (a file replaced)."""
        self.ptr = None  # offset of the pointer to the next page's IFD
        self.walked = 0  # pages passed in this file's chain

    def read(self, first: int, hold_newest: bool, whole: bool = True) -> tuple[list, bool]:
        """The pages from ``first`` on as ``(k, time or None, frame or _BadFrame)``, and
        whether the newest was held back; ``whole`` False: the file changed within
        ``settle_s``, and a page without its time is read again later, not skipped."""
        out, held = [], False
        try:
            with _tifffile_quiet(), open_regular(self.path, "camera file") as fh, \
                    self.tifffile.TiffFile(fh, name=self.path.name) as tf:
                fmt, handle = tf.tiff, tf.filehandle
                size = os.fstat(fh.fileno()).st_size

                def pointer(at):  # the offset stored at ``at``; 0: none (yet)
                    if at + fmt.offsetsize > size:
                        return 0
                    handle.seek(at)
                    return struct.unpack(fmt.offsetformat, handle.read(fmt.offsetsize))[0]

                if self.ptr is None:  # after the header: byte order, magic (, BigTIFF's sizes)
                    self.ptr = 8 if fmt.is_bigtiff else 4
                if self.timing is None and tf.imagej_metadata:
                    self.finterval = tf.imagej_metadata.get("finterval") or None
                while True:
                    offset = pointer(self.ptr)
                    if offset == 0 or offset + fmt.tagnosize > size:
                        break  # no next page (yet)
                    handle.seek(offset)
                    (tagno,) = struct.unpack(fmt.tagnoformat, handle.read(fmt.tagnosize))
                    nxt = offset + fmt.tagnosize + tagno * fmt.tagsize
                    if tagno == 0 or nxt + fmt.offsetsize > size:
                        break  # its IFD not written yet
                    if self.walked >= first:
                        if hold_newest and pointer(nxt) == 0:
                            held = True
                            break
                        handle.seek(offset)
                        page = self.tifffile.TiffPage(tf, index=self.walked)
                        out.append(self._frame(page, self.walked, whole=whole))
                    elif self.timing == "metadata":  # read before (a file replaced): its
                        handle.seek(offset)  # time is passed over, the later ones kept
                        self._metadata_time(self.tifffile.TiffPage(tf, index=self.walked))
                    self.ptr, self.walked = nxt, self.walked + 1
        except Exception as err:  # noqa: BLE001 - tifffile raises many kinds on damaged files
            if out:  # what was read is kept; the rest is read again at the next change
                return out, True
            if str(self.path) in str(err):  # ours, naming the file
                raise _Unreadable(str(err).removeprefix(f"{self.path}: ")) from None
            raise _Unreadable(f"not a readable TIFF file ({type(err).__name__}: "
                              f"{shorten(str(err))})") from None
        if self.walked == 0 and not held:
            raise _Unreadable("no image in this TIFF file")
        return out, held

    def _frame(self, page, k: int, whole: bool = True) -> tuple:
        """``(k, time, frame or _BadFrame)`` of ``page``; while the file still grows
        (``whole`` False) a page whose time is not written yet raises (read again at the
        next change) instead of being skipped."""
        path = self.path
        t = None
        try:
            if page.shape is None or len(page.shape) != 2:
                raise _BadFrame(f"a page of shape {page.shape}, not one frame (ny, nx)")
            try:
                _declared(path, (1, *page.shape), np.dtype(page.dtype).itemsize)
            except ValueError as err:
                raise _BadFrame(str(err).removeprefix(f"{path}: ")) from None
            # tifffile's errors (they may name the file too) mean a page not whole yet:
            # they reach read(), which reads the page again at the file's next change
            raw = page.asarray()
            try:
                frame = _frames_array(path, raw)[0]
            except ValueError as err:
                raise _BadFrame(str(err).removeprefix(f"{path}: ")) from None
            if self.timing is None:  # the first page says where the times are
                self.timing = ("metadata" if self._metadata_times(page) is not None
                               else "imagej" if self.finterval
                               else "clock" if _page_clock(page) is not None else "none")
            if self.timing == "metadata" and self._metadata_times(page) is None \
                    and not self.pending and not whole:
                # a page whose description comes after it: read again while the file
                # grows, for settle_s at most (then a page without a time is skipped)
                first_try = self.retried.setdefault(k, time.monotonic())
                if time.monotonic() - first_try <= self.settle_s:
                    raise _NotWhole("its time is not in the file yet")
            if self.timing == "metadata":
                t = self._metadata_time(page)
            elif self.timing == "imagej":
                t = float(self.finterval) * k
            elif self.timing == "clock":
                t = _page_clock(page)
                if t is None:
                    raise _BadFrame("no DateTime tag, unlike the first page")
        except _BadFrame as err:
            return k, t, err
        return k, t, frame

    @staticmethod
    def _metadata_times(page) -> list | None:
        """The times in tifffile's JSON metadata of ``page`` (its series'), or None."""
        if not page.is_shaped:
            return None
        try:
            meta = json.loads(page.shaped_description)
            return list(np.asarray(meta["times"], float).reshape(-1))
        except (ValueError, TypeError, KeyError):
            return None

    def _metadata_time(self, page) -> float:
        """The time of ``page``: its own in tifffile's metadata, or the next of its series'."""
        times = self._metadata_times(page)
        if times is not None:
            self.pending = times
        if not self.pending:
            raise _BadFrame("no time in tifffile's metadata, unlike the first page")
        return float(self.pending.pop(0))

    @property
    def clock(self) -> bool:
        return self.timing in ("imagej", "clock")


class _Hdf5Rows:
    """The rows of a growing HDF5 dataset ``frames``, each read once."""

    def __init__(self, path: Path):
        self.path = path
        self.h5py = require("h5py", f"the HDF5 file {str(path)!r}")
        self.clock = False

    def reset(self) -> None:
        """Nothing is kept between reads but the number of frames read."""

    def _open(self):
        h5py = self.h5py
        open_regular(self.path, "camera file").close()  # a regular file, as the reader's
        try:  # SWMR reading; a file that does not allow it is opened as any other
            return h5py.File(self.path, "r", swmr=True, locking=False)
        except OSError:
            return h5py.File(self.path, "r", locking=False)

    def read(self, first: int, hold_newest: bool, whole: bool = True) -> tuple[list, bool]:
        """The rows from ``first`` on as ``(k, time or None, frame or _BadFrame)``, and
        whether the newest was held back (``whole``: as for TIFF pages; a row is whole
        once the dataset is resized to hold it)."""
        path, h5py = self.path, self.h5py
        try:
            with self._open() as f:
                ds = _dataset(h5py, f, "frames", path)
                if ds is None:
                    raise ValueError(f"{path}: no dataset 'frames' (need 'frames' (n, ny, nx) "
                                     f"deg C, and 'times' (n,) s or an attribute 'rate'); it "
                                     f"has {shorten(sorted(f.keys()))}")
                if ds.ndim != 3:
                    raise ValueError(f"{path}: 'frames' must be (n, ny, nx) to grow along its "
                                     f"first axis, got shape {ds.shape}")
                ts = _dataset(h5py, f, "times", path)
                rate = ds.attrs.get("rate")
                n = ds.shape[0] if ts is None else min(ds.shape[0], ts.size)
                held = hold_newest and n > first
                n -= held
                if n <= first:
                    return [], held
                _declared(path, (n - first, *ds.shape[1:]), ds.dtype.itemsize)
                raw = ds[first:n]
                times = None if ts is None else np.asarray(ts[first:n], float).reshape(-1)
        except Exception as err:  # noqa: BLE001 - h5py raises OSError, KeyError, ...
            if str(path) in str(err):  # ours, naming the file
                raise _Unreadable(str(err).removeprefix(f"{path}: ")) from None
            hint = (" (a writer that keeps the file open lets it be read in SWMR mode: h5py's "
                    "swmr_mode = True)" if "already open for write" in str(err) else "")
            raise _Unreadable(f"not a readable HDF5 file ({type(err).__name__}: "
                              f"{shorten(str(err))}){hint}") from None
        if times is None and rate is not None:
            rate = float(np.asarray(rate).reshape(-1)[0])
            if not (np.isfinite(rate) and rate > 0):
                raise _Unreadable(f"attribute 'rate' of 'frames' must be > 0 Hz, got {rate!r}")
            times, self.clock = np.arange(first, n) / rate, True
        out = []
        for i, k in enumerate(range(first, n)):
            t = None if times is None else float(times[i])
            try:
                frame = _frames_array(path, raw[i])[0]
            except ValueError as err:
                frame = _BadFrame(str(err).removeprefix(f"{path}: "))
            if t is not None and not np.isfinite(t):
                frame = _BadFrame(f"its time {t!r} s is not finite")
            out.append((k, t, frame))
        return out, held


def follow_file(path: str | Path, start: Callable, on_update: Callable, *,
                poll_s: float = 0.02, idle_timeout_s: float = 10.0,
                wait_for_file_s: float = 10.0, settle_s: float = 1.0,
                rate: float | None = None, on_frame: Callable | None = None,
                warn: Callable[[str], None] | None = None,
                skipped: list | None = None) -> int:
    """Feed the frames of the camera file ``path`` to the filter as the camera adds them.

    Parameters
    ----------
    start, on_update, on_frame, rate, warn :
        As for :func:`enkf.app.follow_frames.follow_folder`; ``on_update(estimate, name)``
        gets ``name`` = ``"FILE frame k"`` (k from 0).
    skipped : list, optional
        Receives ``(name, reason)`` for every frame skipped.

    Returns the number of frames assimilated. Raises ValueError for a file that does not
    appear, is not a TIFF or HDF5 file (a single-frame or FLIR file: follow the folder it is
    written into), cannot be read once it has stopped changing while none of its frames was
    read, or whose first frame cannot be used.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in FLIR_SEQUENCE_SUFFIXES:
        read_frame_file(path)  # refused with the way to export them
    if suffix not in GROWING_SUFFIXES:
        raise ValueError(f"--follow {path}: a {suffix or 'suffix-less'} file is not followed as "
                         f"it grows: follow a TIFF stack or HDF5 file "
                         f"({', '.join(GROWING_SUFFIXES)}), a CSV, or the folder the camera "
                         "writes its frames into")
    if warn is None:
        def warn(message):
            print(f"warning: {message}", file=sys.stderr)
    skipped = [] if skipped is None else skipped
    deadline = time.monotonic() + wait_for_file_s
    while not path.exists():
        if time.monotonic() > deadline:
            raise ValueError(f"--follow: {path} did not appear within {wait_for_file_s:g} s")
        time.sleep(poll_s)
    source = _TiffPages(path, settle_s) if suffix in TIFF_SUFFIXES else _Hdf5Rows(path)

    def skip(name, reason):
        skipped.append((name, reason))
        if len(skipped) <= SHOWN_SKIPS:
            warn(f"--follow: {path.parent / name}: {reason}: skipped")

    feed = FrameFeed(start, on_update, skip, on_frame)
    n_read = 0  # frames read (used or skipped)
    shape = t_first = None
    seen = read_at = None  # the file's (inode, size, mtime) at the last poll, at the last read
    held = False  # the newest frame waits for a later one, or a poll without a change
    failing = None  # (reason, since the file last changed) while it cannot be read
    reported = replaced = False  # a warning given: the file unreadable, replaced
    last = time.monotonic()
    while True:
        ended = end_marker(path.parent)  # before the file, as for a folder
        try:
            st = os.stat(path)
            sig = (st.st_ino, st.st_size, st.st_mtime_ns)
        except FileNotFoundError:  # between a writer's removal and rename
            sig = None
        quiet = sig == seen
        if sig != seen:
            last = time.monotonic()
        if sig is not None and read_at is not None and (
                sig[0] != read_at[0] or sig[1] < read_at[1]):
            if not replaced:  # once: a writer may replace it at every frame
                warn(f"--follow: {path} was {'replaced' if sig[0] != read_at[0] else 'truncated'}"
                     f" after frame {n_read - 1}; read on from the next frame (further "
                     "replacements are not reported)")
                replaced = True
            source.reset()
            read_at = None
        seen = sig
        got = []
        if sig is not None and (sig != read_at or (held and quiet)):
            read_at = sig
            try:
                got, held = source.read(n_read, hold_newest=not quiet,
                                        whole=time.monotonic() - last > settle_s)
                failing = None
            except _Unreadable as err:
                held = False
                if failing is None or not quiet:
                    failing = (str(err), time.monotonic())
        settled = failing is not None and time.monotonic() - failing[1] > settle_s
        if settled and not reported:
            if n_read == 0:
                raise ValueError(f"{path}: {failing[0]}")
            warn(f"--follow: {path}: cannot be read after frame {n_read - 1}: {failing[0]} "
                 "(read again when it changes)")
            reported = True
        for k, t, frame in got:
            n_read = k + 1
            name = f"{path.name} frame {k}"
            if isinstance(frame, _BadFrame):
                if k == 0:
                    raise ValueError(f"{path}: the first frame: {frame}")
                skip(name, str(frame))
                continue
            if shape is None:
                shape = frame.shape
            elif frame.shape != shape:
                skip(name, f"a frame of {frame.shape} pixels, the first frame's {shape}")
                continue
            one = FrameSeries(None if t is None else np.array([t]), frame[None],
                              source.clock, str(path))
            times, t_first = frame_times(one, k, rate, t_first)
            feed.add(float(times[0]), frame, name)
        if got:
            last = time.monotonic()
        if ended and not held and (failing is None or settled):
            break
        if time.monotonic() - last > idle_timeout_s:
            break
        if not got:
            time.sleep(poll_s)
    if failing is not None:
        skip(f"{path.name} frame {n_read}", f"the frames from here on could not be read when "
                                            f"the stream ended ({failing[0]})")
    return feed.finish()
