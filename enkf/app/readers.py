"""Data readers of the tool: sensor CSV files, NPZ image series, and live streams.

:func:`read_sensor_csv` reads a finished CSV file, :func:`load_frames` an NPZ series of
thermal images, and :func:`follow_csv` a file that a sensor keeps appending to
(``identify --follow``).

The file is a CSV with a header (``time`` in s, then one column per sensor or pixel
in deg C, as for ``tissue-enkf identify``); the acquisition program appends one line
per frame. :func:`follow_csv` reads each complete line as soon as it appears, runs one
filter step (:class:`enkf.tissue.OnlineIdentifier`) and hands the estimate to a
callback (which writes it) before it looks for the next line. It stops at a line
``# end``, or when no line has come for ``idle_timeout_s`` seconds. A bad line in the
stream is skipped with a warning naming its number, and the stream goes on. A file that
is replaced (deleted and written anew, or rotated) or truncated while it is followed is
read again from its start, header first, after a warning; a clock that restarts then
stops the stream with an error naming the file and the line.

Every reader opens only regular files (:func:`mcmatlab_py.files.open_regular`): a pipe,
a FIFO or a device is refused before it is read, and a file is refused before it is
read when the memory cannot hold it (an NPZ archive: from its headers, before anything
is unpacked).

Files are UTF-8, with or without a byte-order mark (as spreadsheet programs write them);
the header and the lines are parsed with the :mod:`csv` module, so quoted names
(``"time","probe"``) are accepted. Error messages cut long values (:func:`shorten`).
"""

from __future__ import annotations

import csv
import math
import os
import re
import sys
import time
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from fem.checks import shorten
from mcmatlab_py.budget import MAX_STEPS, check_memory, format_bytes
from mcmatlab_py.files import npz_headers, open_regular

from ..tissue.image import ThermalImage

__all__ = ["CSV_MEMORY_PER_BYTE", "SHOWN_SKIPS", "apply_time_offset", "follow_csv", "load_frames",
           "parse_header", "parse_line", "read_sensor_csv"]

_BOM = "\ufeff"
#: bytes of memory per byte of a CSV file while it is read (its text, the lines, the parsed
#: rows): a file the memory cannot hold is refused before it is read
CSV_MEMORY_PER_BYTE = 8
_TIME_NAMES = ("time", "t", "time_s")
#: a number as a CSV file writes it: ASCII digits, an optional sign, point and exponent, or
#: inf (refused later, naming it)
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?inf(?:inity)?",
                     re.IGNORECASE)


def _fields(line: str, where: str) -> list[str]:
    """The comma-separated fields of one line, quotes removed (the csv module's rules)."""
    try:
        row = next(csv.reader([line.rstrip("\r\n")], skipinitialspace=True), [])
    except csv.Error as err:
        raise ValueError(f"{where}: not a CSV line ({err})") from None
    return [f.strip() for f in row]


def parse_header(line: str, where: str) -> list[str]:
    """The column names of a header line: ``time`` (s) first, then one or more sensors.

    A leading byte-order mark and quotes around names are removed. Raises ValueError
    naming ``where`` for a first column that is not the time, no sensor column, or a
    name given twice.
    """
    names = _fields(line.removeprefix(_BOM), where)
    first = names[0] if names else ""
    if first.lower() not in _TIME_NAMES:
        raise ValueError(f"{where}: the first column must be 'time' (s), got "
                         f"{shorten(repr(first))} (is this a CSV with a header?)")
    if len(names) < 2:
        raise ValueError(f"{where}: no sensor columns after 'time'")
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ValueError(f"{where}: the header names column {shorten(repr(dup))} twice")
    return names


def parse_line(line: str, n_columns: int, where: str) -> tuple[float, np.ndarray]:
    """``(time, values)`` of one data line; empty fields and ``nan`` are missing values.

    Raises ValueError naming ``where`` (file and line) for a wrong field count, a field
    that is not a number, or an infinite or missing time.
    """
    fields = _fields(line, where)
    if len(fields) != n_columns:
        raise ValueError(f"{where}: expected {n_columns} comma-separated fields, got {len(fields)}")
    vals = []
    for j, f in enumerate(fields):
        if f == "" or f.lower() in ("nan", "+nan", "-nan"):  # C's printf writes -nan
            vals.append(math.nan)
            continue
        if not _NUMBER.fullmatch(f):  # float() also takes "1_0" (10) and other digits
            raise ValueError(f"{where}: field {j + 1} is not a number: "
                             f"{shorten(repr(f))}")
        vals.append(float(f))
    v = np.array(vals)
    if not np.isfinite(v[0]):
        raise ValueError(f"{where}: the time must be a finite number, got "
                         f"{shorten(repr(fields[0]))}")
    if np.any(np.isinf(v[1:])):
        raise ValueError(f"{where}: a temperature is infinite (use an empty field for a gap)")
    return float(v[0]), v[1:]


#: bad lines of a followed file that are each shown; later ones are counted only
SHOWN_SKIPS = 20


class _Stream:
    """The lines of a followed file, read as bytes (the offset is then exact, to tell a
    truncated file from a read one), each at most ``max_line`` bytes: a longer line is
    passed over without being held in memory and reported as too long."""

    def __init__(self, fh, max_line: int):
        self.fh, self.max_line = fh, max_line
        self.buf = b""  #: the start of a line the writer has not finished
        self.too_long = False  #: passing over the rest of a too long line
        self.line_no = 0
        self.grew = False

    def next(self):
        """``(line number, bytes or None for a too long line)``, or None when no complete
        line is waiting; ``self.grew`` then says whether part of one came."""
        self.grew = False
        while True:
            chunk = self.fh.readline(self.max_line + 1 - len(self.buf))
            if not chunk:
                return None
            self.grew = True
            if self.too_long:
                if chunk.endswith(b"\n"):
                    self.too_long = False
                    self.line_no += 1
                    return self.line_no, None
                continue
            self.buf += chunk
            if self.buf.endswith(b"\n"):
                raw, self.buf = self.buf, b""
                self.line_no += 1
                return self.line_no, raw
            if len(self.buf) > self.max_line:
                self.buf, self.too_long = b"", True

    def restart(self, fh) -> None:
        self.fh, self.buf, self.too_long, self.line_no = fh, b"", False, 0


def follow_csv(path: str | Path, identifier, on_update: Callable, *, poll_s: float = 0.02,
               idle_timeout_s: float = 10.0, wait_for_file_s: float = 10.0,
               columns: list[str] | None = None,
               warn: Callable[[str], None] | None = None,
               skipped: list | None = None) -> int:
    """Feed the lines of a growing CSV to ``identifier`` as they arrive.

    A data line that cannot be used (not a number, a wrong field count, an infinite or
    missing time, an infinite temperature, a time not after the last reading's, not
    UTF-8, longer than a line of this many columns can be) is skipped with a warning
    that names the file and the line, and the stream goes on. A file that is replaced
    (deleted and written anew, or rotated) or truncated is read again from its start,
    header first, after a warning; its readings up to the last one assimilated are
    passed over when they repeat it exactly (a writer that rewrites the whole file), and
    one that is new but not later than it (a clock that restarted: another acquisition)
    stops the stream with a ValueError naming the file and the line. A last line that
    never got its end of line (the writer stopped in the middle of it) is reported when
    the stream ends, not assimilated.

    Parameters
    ----------
    identifier : enkf.tissue.OnlineIdentifier
    on_update : callable
        ``on_update(estimate, line_number)`` after every line, before the next is read.
    poll_s : float
        s between looks at the file when no complete line is waiting.
    idle_timeout_s : float
        s, > 0 and finite: stop after this long without a new line or part of one (a
        ``# end`` line stops at once).
    columns : list of str, optional
        The expected header (``time`` first); default: ``time`` and one column per
        observation of the identifier.
    warn : callable, optional
        ``warn(message)`` for a skipped line (the first :data:`SHOWN_SKIPS`), a file
        replaced or truncated, and an unfinished last line. Default: a ``warning: ...``
        line on stderr.
    skipped : list, optional
        Receives ``(line_number, reason)`` for every line skipped (``line_number`` counts
        the lines of the file read last).

    Returns
    -------
    int, the number of readings assimilated.

    Raises
    ------
    ValueError
        The file is missing, not a regular file (a pipe: the replacement checks need a
        file), has a header that does not fit, or its clock restarted.
    """
    if not (math.isfinite(idle_timeout_s) and idle_timeout_s > 0):
        raise ValueError(f"idle_timeout_s must be a finite number of seconds > 0, got "
                         f"{shorten(idle_timeout_s)}")
    if warn is None:
        def warn(message):
            print(f"warning: {message}", file=sys.stderr)
    skipped = [] if skipped is None else skipped
    path = Path(path)
    deadline = time.monotonic() + wait_for_file_s
    while not (path.exists() or path.is_symlink()):
        if time.monotonic() > deadline:
            raise ValueError(f"--follow: {path} did not appear within {wait_for_file_s:g} s")
        time.sleep(poll_s)
    n_expected = identifier.n_obs + 1
    max_dt = getattr(identifier.setup, "max_dt", None)
    assimilated = {}  # time -> digest of the reading: a rewritten file's repeats are passed
    # over (a digest, not the values: a camera's frames would fill the memory)
    count = 0
    # a field as a program writes it is at most ~25 characters ("-1.2345678901234567e+308")
    stream = _Stream(open_regular(path, "--follow file"), 64 * n_expected + 4096)
    header = None
    changed = None  # how the file changed, until its first new reading
    last = time.monotonic()

    def skip(line_no, reason):
        skipped.append((line_no, reason))
        if len(skipped) <= SHOWN_SKIPS:
            more = (" (further skipped lines are counted, not shown)"
                    if len(skipped) == SHOWN_SKIPS else "")
            warn(f"--follow: {path}:{line_no}: {reason}: line skipped{more}")

    try:
        while True:
            got = stream.next()
            if got is None:
                if stream.grew:
                    last = time.monotonic()  # part of a line: the writer is at work
                change = _replaced_or_truncated(path, stream.fh)
                after = stream.line_no
                if change == "truncated":
                    stream.fh.seek(0)
                    stream.restart(stream.fh)
                elif change == "replaced":
                    try:
                        new = open_regular(path, "--follow file")
                    except ValueError:  # gone again between two looks: at the next poll
                        if path.exists() and not path.is_file():
                            raise
                        change = None
                    else:
                        stream.fh.close()
                        stream.restart(new)
                if change is not None:
                    warn(f"--follow: {path} was {change} after line {after}; reading it from "
                         "its start (header first)")
                    header, changed, last = None, change, time.monotonic()
                    continue
                if time.monotonic() - last > idle_timeout_s:
                    break
                time.sleep(poll_s)
                continue
            line_no, raw = got
            last = time.monotonic()
            where = f"{path}:{line_no}"
            if raw is None:
                if header is None:
                    raise ValueError(f"{where}: the header is longer than "
                                     f"{stream.max_line} bytes")
                skip(line_no, f"longer than {stream.max_line} bytes")
                continue
            try:
                line = raw.decode("utf-8")
            except UnicodeDecodeError:
                if header is None:
                    raise ValueError(f"{where}: not UTF-8 text") from None
                skip(line_no, "not UTF-8 text")
                continue
            if line_no == 1:
                line = line.removeprefix(_BOM)
            text = line.strip()
            if not text:
                continue
            if text.startswith("#"):
                if text.lower().startswith("# end"):
                    break
                continue
            if header is None:
                header = parse_header(text, where)
                if columns is not None and header != list(columns):
                    raise ValueError(f"{where}: columns {shorten(header)} differ from the "
                                     f"expected {list(columns)}")
                if len(header) != n_expected:
                    raise ValueError(f"{where}: {len(header) - 1} data columns, the setup "
                                     f"observes {identifier.n_obs}")
                continue
            try:
                t, y = parse_line(line, n_expected, where)
            except ValueError as err:
                skip(line_no, str(err).removeprefix(f"{where}: "))
                continue
            if t <= identifier.time:
                if assimilated.get(t) == _digest(y):
                    continue  # a rewritten file repeats what was assimilated
                if changed is not None:
                    raise ValueError(
                        f"{where}: the clock restarted: time {t!r} s is not after the last "
                        f"reading's {identifier.time!r} s in a file {changed} while followed "
                        "(another acquisition? follow it in a new run)")
                skip(line_no, f"time {t!r} s is not after the last reading's "
                              f"{identifier.time!r} s")
                continue
            if max_dt is not None and (t - identifier.time) / max_dt > MAX_STEPS:
                skip(line_no, f"time {t!r} s is more than {MAX_STEPS} heat steps of "
                              f"HS.dt = {max_dt:g} s after the last reading")
                continue
            est = identifier.update(t, y)
            assimilated[t] = _digest(y)
            changed = None
            count += 1
            on_update(est, line_no)
        if stream.buf:  # the writer stopped in the middle of a line
            reason = (f"the last line has no end of line ({len(stream.buf)} bytes; did the "
                      "writer stop in the middle of it?): not assimilated")
            skipped.append((stream.line_no + 1, reason))
            warn(f"--follow: {path}:{stream.line_no + 1}: {reason}")
    finally:
        stream.fh.close()
    return count


def _digest(y: np.ndarray) -> bytes:
    """16 bytes that tell one reading's values from another's (every NaN alike)."""
    import hashlib

    return hashlib.blake2b(np.where(np.isnan(y), np.nan, y).tobytes(), digest_size=16).digest()


def _replaced_or_truncated(path: Path, fh) -> str | None:
    """``"replaced"`` when ``path`` is now another file than the open ``fh`` (another inode:
    deleted and written anew, or rotated), ``"truncated"`` when it is shorter than what
    was read of it, else None (also while ``path`` is missing: the writer may be about to
    create it again)."""
    try:
        now = os.stat(path)
    except FileNotFoundError:
        return None
    was = os.fstat(fh.fileno())
    if (now.st_ino, now.st_dev) != (was.st_ino, was.st_dev):
        return "replaced"
    if now.st_size < fh.tell():
        return "truncated"
    return None


def apply_time_offset(path, times: np.ndarray, values: np.ndarray, offset: float | None):
    """Shift times by ``data.time_offset`` and drop the readings before the laser starts."""
    if offset is None:
        if times[0] <= 0:
            raise ValueError(f"{path}: times must be > 0 s (the prior is at t = 0; set "
                             f"data.time_offset to the laser's start), got {float(times[0])!r}")
        return times, values
    times = times - offset
    keep = times > 0
    if not np.any(keep):
        raise ValueError(f"{path}: no reading after the laser's start (data.time_offset = "
                         f"{offset!r} s, last time {float(times[-1] + offset)!r} s)")
    return times[keep], values[keep]


def read_sensor_csv(path: str | Path, n_columns: int | None = None, *,
                    columns: list[str] | None = None, time_offset: float | None = None
                    ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``(times (M,) s, data (M, p) deg C, column names)`` of a measured-data CSV.

    A header names the columns: ``time`` (s) first, then one column per sensor (and
    pixel); empty fields or ``nan`` are gaps. Raises ValueError naming the file, the
    line and the problem for: a missing or unreadable file, no header, no rows, a
    field that is not a number, a wrong number of fields or columns, Inf, a missing,
    negative or zero time, unsorted or duplicate times.

    Parameters
    ----------
    n_columns : the number of data columns the config observes (checked)
    columns : header names of the data columns to use, in this order (other columns
        are ignored; a missing name is an error); default: every column after ``time``
    time_offset : s, subtracted from the times (the laser's start on the data's
        clock); the readings at or before the start are then dropped. Default: none,
        and every time must be > 0.
    """
    path = Path(path)
    with open_regular(path, "data file") as fh:  # not a pipe, FIFO or device
        size = os.fstat(fh.fileno()).st_size
        check_memory(CSV_MEMORY_PER_BYTE * size, f"data file {str(path)!r} "
                     f"({format_bytes(size)})", "the number of readings (split the file, or "
                     "save camera frames as an NPZ series)")
        data = fh.read()
    try:
        text = data.decode("utf-8-sig")  # a byte-order mark is dropped
    except UnicodeDecodeError as err:
        raise ValueError(f"data file {str(path)!r} cannot be read as text: {err}") from None
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines())
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ValueError(f"data file {str(path)!r} is empty (need a header: time, sensors...)")
    names = parse_header(lines[0][1], f"{path}:{lines[0][0]}")
    if columns is not None:
        missing = [c for c in columns if c not in names[1:]]
        if missing:
            raise ValueError(f"{path}:{lines[0][0]}: missing column {shorten(repr(missing[0]))} "
                             f"(data.columns); the header has {shorten(names)}")
        pick = [names.index(c) - 1 for c in columns]
    else:
        pick = list(range(len(names) - 1))
    if n_columns is not None and len(pick) != n_columns:
        raise ValueError(f"{path}:{lines[0][0]}: {len(pick)} data columns, the config "
                         f"observes {n_columns} (sensors.positions, then camera pixels)")
    if len(lines) == 1:
        raise ValueError(f"data file {str(path)!r} has a header but no rows")
    times, rows = [], []
    for no, ln in lines[1:]:
        t, y = parse_line(ln, len(names), f"{path}:{no}")
        times.append(t)
        rows.append(y[pick])
    times = np.array(times)
    d = np.diff(times)
    if np.any(d <= 0):
        k = int(np.flatnonzero(d <= 0)[0])
        what = "duplicate" if d[k] == 0 else "unsorted"
        raise ValueError(f"{path}: {what} times: {float(times[k])!r} then "
                         f"{float(times[k + 1])!r} s")
    times, values = apply_time_offset(path, times, np.array(rows).reshape(len(times), len(pick)),
                                  time_offset)
    return times, values, ["time"] + [names[j + 1] for j in pick]


def load_frames(path: str | Path, image: ThermalImage | None = None, *, flat: bool = True
                ) -> tuple[np.ndarray, np.ndarray]:
    """``(times (n,), frames (n, ny*nx))`` from an NPZ with ``times`` and ``frames``
    (``flat=False``: frames (n, ny, nx)).

    Frames are (n, ny, nx) deg C, NaN for dead pixels; ``image`` checks the shape.
    Raises ValueError naming the problem (not an NPZ (zip) file, missing array, complex
    or non-numeric array, wrong shape, Inf, unsorted or duplicate times, no frames).
    """
    path = Path(path)
    headers = npz_headers(path, "data file")  # before anything is unpacked
    unpacked = sum(headers[k][2] for k in ("times", "frames") if k in headers)
    # the arrays, their float64 copies and the reshaped frames
    check_memory(3 * unpacked, f"data file {str(path)!r} ({format_bytes(unpacked)} of "
                 "arrays once unpacked)", "the number of frames or pixels (split the file)")
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in ("times", "frames") if k in f.files}
    except (OSError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: not a readable NPZ file ({exc})") from exc
    except ValueError as exc:  # an object array (pickled data), a damaged member
        raise ValueError(f"{path}: not a readable NPZ file ({shorten(str(exc))})") from exc
    missing = [k for k in ("times", "frames") if k not in arrays]
    if missing:
        raise ValueError(f"{path}: missing array(s) {missing} (need 'times' and 'frames')")
    for k, a in arrays.items():
        if np.iscomplexobj(a):  # a float cast would drop the imaginary part silently
            raise ValueError(f"{path}: {k!r} is complex ({a.dtype}); it must hold real numbers")
        if a.dtype.kind not in "biuf":
            raise ValueError(f"{path}: {k!r} must hold numbers, got dtype {a.dtype}")
    times, frames = (np.asarray(arrays[k], float) for k in ("times", "frames"))
    if times.ndim != 1 or times.size == 0:
        raise ValueError(f"{path}: 'times' must be a non-empty 1-D array, got shape {times.shape}")
    if frames.ndim != 3 or frames.shape[0] != times.size:
        raise ValueError(f"{path}: 'frames' must be (n, ny, nx) with n = {times.size}, "
                         f"got shape {frames.shape}")
    if image is not None and frames.shape[1:] != tuple(int(v) for v in image.shape):
        raise ValueError(f"{path}: frames are {frames.shape[1:]} pixels, the camera "
                         f"(ThermalImage.shape) {tuple(image.shape)}")
    if not np.all(np.isfinite(times)):
        raise ValueError(f"{path}: 'times' must be finite, got {float(times[~np.isfinite(times)][0])!r}")
    if np.any(np.diff(times) <= 0):
        k = int(np.flatnonzero(np.diff(times) <= 0)[0])
        raise ValueError(f"{path}: 'times' must be strictly increasing, got {float(times[k])!r} then "
                         f"{float(times[k + 1])!r}")
    if np.any(np.isinf(frames)):
        raise ValueError(f"{path}: 'frames' hold Inf (use NaN for a dead pixel)")
    return times, frames.reshape(times.size, -1) if flat else frames
