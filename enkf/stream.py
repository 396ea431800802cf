"""Online identification from a file that a sensor keeps appending to (``--follow``).

The file is a CSV with a header (``time`` in s, then one column per sensor or pixel
in deg C, as for ``tissue-enkf identify``); the acquisition program appends one line
per frame. :func:`follow_csv` reads each complete line as soon as it appears, runs one
filter step (:class:`enkf.tissue.OnlineIdentifier`) and hands the estimate to a
callback (which writes it) before it looks for the next line. It stops at a line
``# end``, or when no line has come for ``idle_timeout_s`` seconds.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["follow_csv", "parse_line"]


def parse_line(line: str, n_columns: int, where: str) -> tuple[float, np.ndarray]:
    """``(time, values)`` of one data line; empty fields and ``nan`` are missing values.

    Raises ValueError naming ``where`` (file and line) for a wrong field count, a field
    that is not a number, or an infinite or missing time.
    """
    fields = [f.strip() for f in line.rstrip("\r\n").split(",")]
    if len(fields) != n_columns:
        raise ValueError(f"{where}: expected {n_columns} comma-separated fields, got {len(fields)}")
    vals = []
    for j, f in enumerate(fields):
        if f == "" or f.lower() == "nan":
            vals.append(math.nan)
            continue
        try:
            vals.append(float(f))
        except ValueError:
            raise ValueError(f"{where}: field {j + 1} is not a number: {f!r}") from None
    v = np.array(vals)
    if not np.isfinite(v[0]):
        raise ValueError(f"{where}: the time must be a finite number, got {fields[0]!r}")
    if np.any(np.isinf(v[1:])):
        raise ValueError(f"{where}: a temperature is infinite (use an empty field for a gap)")
    return float(v[0]), v[1:]


def follow_csv(path: str | Path, identifier, on_update: Callable, *, poll_s: float = 0.02,
               idle_timeout_s: float = 10.0, wait_for_file_s: float = 10.0,
               columns: list[str] | None = None) -> int:
    """Feed the lines of a growing CSV to ``identifier`` as they arrive.

    Parameters
    ----------
    identifier : enkf.tissue.OnlineIdentifier
    on_update : callable
        ``on_update(estimate, line_number)`` after every line, before the next is read.
    poll_s : float
        s between looks at the file when no complete line is waiting.
    idle_timeout_s : float
        Stop after this long without a new line (a ``# end`` line stops at once).
    columns : list of str, optional
        The expected header (``time`` first); default: ``time`` and one column per
        observation of the identifier.

    Returns
    -------
    int, the number of readings assimilated.
    """
    path = Path(path)
    deadline = time.monotonic() + wait_for_file_s
    while not path.exists():
        if time.monotonic() > deadline:
            raise ValueError(f"--follow: {path} did not appear within {wait_for_file_s:g} s")
        time.sleep(poll_s)
    n_expected = identifier.n_obs + 1
    count = 0
    with open(path, encoding="utf-8", newline="") as fh:
        buf = ""
        header = None
        line_no = 0
        last = time.monotonic()
        while True:
            chunk = fh.readline()
            if chunk:
                buf += chunk
                if not buf.endswith("\n"):
                    continue  # the writer has not finished this line yet
                line, buf = buf, ""
                line_no += 1
                last = time.monotonic()
                text = line.strip()
                if not text:
                    continue
                if text.startswith("#"):
                    if text.lower().startswith("# end"):
                        break
                    continue
                where = f"{path}:{line_no}"
                if header is None:
                    header = [h.strip() for h in text.split(",")]
                    if header[0].lower() not in ("time", "t", "time_s"):
                        raise ValueError(f"{where}: the first column must be 'time' (s), "
                                         f"got {header[0]!r}")
                    if columns is not None and header != list(columns):
                        raise ValueError(f"{where}: columns {header} differ from the expected "
                                         f"{list(columns)}")
                    if len(header) != n_expected:
                        raise ValueError(f"{where}: {len(header) - 1} data columns, the setup "
                                         f"observes {identifier.n_obs}")
                    continue
                t, y = parse_line(line, n_expected, where)
                est = identifier.update(t, y)
                count += 1
                on_update(est, line_no)
                continue
            if time.monotonic() - last > idle_timeout_s:
                break
            time.sleep(poll_s)
    return count
