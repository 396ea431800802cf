"""Data readers of the tool: sensor CSV files, NPZ image series, and live streams.

:func:`read_sensor_csv` reads a finished CSV file, :func:`load_frames` an NPZ series of
thermal images, and :func:`follow_csv` a file that a sensor keeps appending to
(``identify --follow``).

The file is a CSV with a header (``time`` in s, then one column per sensor or pixel
in deg C, as for ``tissue-enkf identify``); the acquisition program appends one line
per frame. :func:`follow_csv` reads each complete line as soon as it appears, runs one
filter step (:class:`enkf.tissue.OnlineIdentifier`) and hands the estimate to a
callback (which writes it) before it looks for the next line. It stops at a line
``# end``, or when no line has come for ``idle_timeout_s`` seconds. A file that is
replaced (deleted and written anew, or rotated) or truncated while it is followed is
read again from its start, header first, after a warning.

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

from ..tissue.image import ThermalImage

__all__ = ["apply_time_offset", "follow_csv", "load_frames", "parse_header", "parse_line",
           "read_sensor_csv"]

_BOM = "\ufeff"
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


def follow_csv(path: str | Path, identifier, on_update: Callable, *, poll_s: float = 0.02,
               idle_timeout_s: float = 10.0, wait_for_file_s: float = 10.0,
               columns: list[str] | None = None,
               warn: Callable[[str], None] | None = None) -> int:
    """Feed the lines of a growing CSV to ``identifier`` as they arrive.

    Parameters
    ----------
    identifier : enkf.tissue.OnlineIdentifier
    on_update : callable
        ``on_update(estimate, line_number)`` after every line, before the next is read.
    poll_s : float
        s between looks at the file when no complete line is waiting.
    idle_timeout_s : float
        s, > 0 and finite: stop after this long without a new line (a ``# end`` line
        stops at once).
    columns : list of str, optional
        The expected header (``time`` first); default: ``time`` and one column per
        observation of the identifier.
    warn : callable, optional
        ``warn(message)`` when the file is replaced (a new file at ``path``: deleted and
        written anew, or rotated) or truncated; it is then read from its start, header
        first. Default: a ``warning: ...`` line on stderr.

    Returns
    -------
    int, the number of readings assimilated.
    """
    if not (math.isfinite(idle_timeout_s) and idle_timeout_s > 0):
        raise ValueError(f"idle_timeout_s must be a finite number of seconds > 0, got "
                         f"{shorten(idle_timeout_s)}")
    if warn is None:
        def warn(message):
            print(f"warning: {message}", file=sys.stderr)
    path = Path(path)
    deadline = time.monotonic() + wait_for_file_s
    while not path.exists():
        if time.monotonic() > deadline:
            raise ValueError(f"--follow: {path} did not appear within {wait_for_file_s:g} s")
        time.sleep(poll_s)
    n_expected = identifier.n_obs + 1
    count = 0
    # bytes, not text: the offset is then exact, to tell a truncated file from a read one
    fh = open(path, "rb")
    try:
        buf = b""
        header = None
        line_no = 0
        last = time.monotonic()
        while True:
            chunk = fh.readline()
            if chunk:
                buf += chunk
                if not buf.endswith(b"\n"):
                    continue  # the writer has not finished this line yet
                raw, buf = buf, b""
                line_no += 1
                last = time.monotonic()
                where = f"{path}:{line_no}"
                try:
                    line = raw.decode("utf-8")
                except UnicodeDecodeError:
                    raise ValueError(f"{where}: not UTF-8 text") from None
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
                t, y = parse_line(line, n_expected, where)
                est = identifier.update(t, y)
                count += 1
                on_update(est, line_no)
                continue
            change = _replaced_or_truncated(path, fh)
            if change == "truncated":
                fh.seek(0)
            elif change == "replaced":
                try:
                    new = open(path, "rb")
                except FileNotFoundError:  # gone again between two looks: at the next poll
                    change = None
                else:
                    fh.close()
                    fh = new
            if change is not None:
                warn(f"--follow: {path} was {change} after line {line_no}; reading it from "
                     "its start (header first)")
                buf, header, line_no, last = b"", None, 0, time.monotonic()
                continue
            if time.monotonic() - last > idle_timeout_s:
                break
            time.sleep(poll_s)
    finally:
        fh.close()
    return count


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
    try:
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark is dropped
    except FileNotFoundError:
        raise ValueError(f"data file {str(path)!r} does not exist") from None
    except (OSError, UnicodeDecodeError) as err:
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


def load_frames(path: str | Path, image: ThermalImage | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """``(times (n,), frames (n, ny*nx))`` from an NPZ with ``times`` and ``frames``.

    Frames are (n, ny, nx) deg C, NaN for dead pixels; ``image`` checks the shape.
    Raises ValueError naming the problem (not an NPZ (zip) file, missing array, complex
    or non-numeric array, wrong shape, Inf, unsorted or duplicate times, no frames).
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            is_zip = zipfile.is_zipfile(fh)
    except FileNotFoundError:
        raise ValueError(f"data file {str(path)!r} does not exist") from None
    except OSError as err:
        raise ValueError(f"data file {str(path)!r} cannot be read: {err.strerror}") from None
    if not is_zip:  # np.load would call it pickled data: e.g. a CSV renamed .npz
        raise ValueError(f"{path}: not a readable NPZ file: it is not a zip archive (numpy.savez "
                         "writes NPZ files as zip archives of arrays; is it a CSV or .npy?)")
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
    return times, frames.reshape(times.size, -1)
