"""Opening user files without hanging or running out of memory.

A path a user gives may name a pipe (``--data <(cat f)``, ``/dev/stdin`` fed by a pipe:
it can be read only once), a FIFO that no program writes to (opening it for reading
waits forever), a device (``/dev/zero`` never ends), a directory, or a file far larger
than the memory. :func:`open_regular` opens a file without waiting and refuses all of
these before a byte is read, with an error that names the file; :func:`read_regular`
reads one whole. :func:`npz_headers` reads only the headers of an NPZ archive's arrays,
so that an archive whose arrays cannot fit (a lying ``.npy`` header that declares a huge
shape, a zip bomb) is refused before anything is unpacked.
"""

from __future__ import annotations

import math
import os
import stat
import zipfile
from pathlib import Path

import numpy as np

from .budget import format_bytes

__all__ = ["file_kind", "npz_headers", "open_regular", "read_regular"]


def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, in words ("a regular file", "a pipe or FIFO")."""
    for test, word in ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a directory"),
                       (stat.S_ISFIFO, "a pipe or FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return word
    return "not a regular file"


def open_regular(path: str | Path, what: str, max_bytes: int | None = None,
                 error: type[Exception] = ValueError):
    """Open the regular file ``path`` for reading bytes; the open file object.

    Raises ``error`` naming ``what`` (``"data file"``) and the path for a missing or
    unreadable file, anything that is not a regular file (a pipe, a FIFO, a device, a
    directory: refused before it is read, so a FIFO without a writer does not hang), and
    a file of more than ``max_bytes``.
    """
    name = os.fspath(path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:  # O_NONBLOCK: a FIFO opens at once instead of waiting for a writer
        fd = os.open(name, flags)
    except FileNotFoundError:
        raise error(f"{what} {name!r} does not exist") from None
    except OSError as err:
        raise error(f"{what} {name!r} cannot be read: {err.strerror}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            hint = ": save it to a file first" if stat.S_ISFIFO(st.st_mode) else ""
            raise error(f"{what} {name!r} is {file_kind(st.st_mode)}, not a regular file{hint}")
        if max_bytes is not None and st.st_size > max_bytes:
            raise error(f"{what} {name!r} is {format_bytes(st.st_size)}, more than the "
                        f"{format_bytes(max_bytes)} it may have")
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: str | Path, what: str, max_bytes: int,
                 error: type[Exception] = ValueError) -> bytes:
    """The bytes of the regular file ``path`` (see :func:`open_regular`); a file that grows
    past ``max_bytes`` while it is read is refused as well."""
    with open_regular(path, what, max_bytes, error) as fh:
        data = fh.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise error(f"{what} {os.fspath(path)!r} grew past the {format_bytes(max_bytes)} it "
                    "may have while it was read")
    return data


def npz_headers(path: str | Path, what: str, error: type[Exception] = ValueError
                ) -> dict[str, tuple[tuple[int, ...], np.dtype, int]]:
    """``{name: (shape, dtype, unpacked bytes)}`` of the arrays of the NPZ archive ``path``,
    read from the ``.npy`` headers alone (nothing is unpacked but the headers).

    Raises ``error`` naming the file for what :func:`open_regular` refuses, a file that is
    no zip archive or is damaged, and an array whose header declares more data than the
    archive's member holds (a lying header would make numpy allocate its shape first).
    """
    name = os.fspath(path)
    out = {}
    with open_regular(path, what, error=error) as fh:
        if not zipfile.is_zipfile(fh):
            raise error(f"{what} {name!r} is not a readable NPZ file: it is not a zip archive "
                        "(numpy.savez writes NPZ files as zip archives of arrays; is it a CSV "
                        "or .npy?)")
        try:
            with zipfile.ZipFile(fh) as zf:
                for info in zf.infolist():
                    if not info.filename.endswith(".npy"):
                        continue
                    with zf.open(info) as member:
                        version = np.lib.format.read_magic(member)
                        read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                                else np.lib.format.read_array_header_2_0)
                        shape, _, dtype = read(member)
                        header = member.tell()
                    n = math.prod(int(s) for s in shape) * dtype.itemsize
                    if dtype.hasobject:
                        n = 0  # pickled objects: refused by the loader (allow_pickle=False)
                    if n > info.file_size - header:
                        raise error(f"{what} {name!r}: array {info.filename[:-4]!r} declares "
                                    f"shape {tuple(shape)} ({format_bytes(n)}), but the file "
                                    f"holds {format_bytes(info.file_size - header)} of it: "
                                    "damaged or forged")
                    out[info.filename[:-4]] = (tuple(int(s) for s in shape), dtype,
                                               info.file_size)
        # zipfile raises NotImplementedError for features it cannot read (compression
        # methods, patched data) and RuntimeError for an encrypted member
        except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError, ValueError,
                NotImplementedError, RuntimeError) as err:
            if isinstance(err, error):
                raise
            raise error(f"{what} {name!r} is not a readable NPZ file ({err})") from None
    return out
