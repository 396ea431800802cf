"""What thermal cameras write: FLIR radiometric JPEGs, TIFF stacks, HDF5, NPZ, folders.

:func:`read_frames` reads one file or a folder of frames into a :class:`FrameSeries`:
frames ``(n, ny, nx)`` deg C and their times, each format through a kept library (the
times, in this order):

- FLIR radiometric JPEG (``.jpg``, ``.jpeg``), through ``flyr``: FLIR's own
  ``DateTimeOriginal`` (ms), else EXIF ``DateTimeOriginal`` with ``SubSecTimeOriginal``;
- TIFF stack (``.tif``), through ``tifffile``: ``times`` in tifffile's JSON metadata
  (the stack's, or each page's in order when it was written a page at a time), ImageJ's
  ``finterval``, or each page's ``DateTime`` (and ``SubSecTime``);
- HDF5 (``.h5``, ``.hdf5``), through ``h5py``: dataset ``times``, or attribute ``rate``
  (Hz) of ``frames``;
- NPZ (``.npz``), through numpy: array ``times`` (required);
- a folder of these: each file's times, or the order of the names.

The libraries are the ``[camera]`` extra.

A FLIR file holds the detector's raw counts; the temperatures come from them with the
file's emissivity, distance, reflected and atmospheric temperatures and Planck constants
(``R1, R2, B, F, O``), as the camera computes them (flyr's formula, after FLIR's). An
``emissivity`` replaces the file's (a camera set to 0.95 looking at skin of 0.98).

Times from a clock (absolute timestamps) are made seconds since the first frame
(:attr:`FrameSeries.clock` is True): unless ``data.time_offset`` says otherwise, the
first frame is taken as the laser's start, the baseline before heating. Files without
times are given ``k / rate`` with ``sensors.rate``; without it they are refused.

Every reader keeps the guarantees of :mod:`enkf.app.readers` (docs/robustness.md): a
regular file only (:func:`mcmatlab_py.files.open_regular`), the memory checked from the
declared shape before the pixels are read, nothing unpickled (HDF5 object, string and
compound data, external links and external or virtual storage are refused), and every
error names the file and what is wrong. A missing library is named with the command that
installs it.
"""

from __future__ import annotations

import datetime as dt
import importlib
import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fem.checks import shorten
from mcmatlab_py.budget import check_memory, format_bytes
from mcmatlab_py.files import open_regular

__all__ = ["FLIR_SUFFIXES", "FRAME_SUFFIXES", "FrameSeries", "frame_files", "read_frame_file",
           "read_frames", "require"]

FLIR_SUFFIXES = (".jpg", ".jpeg")
TIFF_SUFFIXES = (".tif", ".tiff")
HDF5_SUFFIXES = (".h5", ".hdf5", ".hdf")
#: the files a folder of frames may hold (others are ignored)
FRAME_SUFFIXES = FLIR_SUFFIXES + TIFF_SUFFIXES + HDF5_SUFFIXES + (".npz",)
#: FLIR's raw frame sequences: refused with the way to export them
FLIR_SEQUENCE_SUFFIXES = (".seq", ".csq")
#: the largest single camera file read (a FLIR JPEG is a few MB; a stack is checked
#: against the memory instead)
MAX_JPEG_BYTES = 256 * 2**20
#: bytes of memory per pixel value while a stack is read (its own dtype, the float64
#: frames, a copy when the times are applied)
_BYTES_PER_VALUE = 24
_INSTALL = 'pip install "tissue-enkf[camera]"'


@dataclass
class FrameSeries:
    """Frames of a thermal camera and their times."""

    times: np.ndarray | None  #: (n,) s; None: the files carry no times
    frames: np.ndarray  #: (n, ny, nx) deg C, NaN for dead pixels
    clock: bool = False  #: times came from a clock: seconds since the first frame
    source: str = ""  #: the file or folder


def require(module: str, what: str):
    """Import ``module`` (a package of the ``[camera]`` extra) or raise a ValueError that
    says how to install it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        pkg = {"flyr": "flyr", "tifffile": "tifffile", "h5py": "h5py", "bokeh": "bokeh"}.get(
            module, module)
        raise ValueError(f"{what} needs the Python package {pkg!r}, which is not installed: "
                         f"{_INSTALL} (or pip install {pkg})") from None


def _check_values(path, name: str, a: np.ndarray) -> None:
    if np.iscomplexobj(a):
        raise ValueError(f"{path}: {name} is complex ({a.dtype}); it must hold real numbers")
    if a.dtype.kind not in "biuf":
        raise ValueError(f"{path}: {name} must hold numbers, got dtype {shorten(str(a.dtype))}")


def _frames_array(path, frames, name="frames") -> np.ndarray:
    """(n, ny, nx) float64 deg C from a stack (or one frame (ny, nx))."""
    a = np.asarray(frames)
    _check_values(path, name, a)
    if a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or 0 in a.shape:
        raise ValueError(f"{path}: {name} must be (n, ny, nx) or one (ny, nx) frame, got "
                         f"shape {a.shape}")
    a = a.astype(float)
    if np.any(np.isinf(a)):
        raise ValueError(f"{path}: {name} hold Inf (use NaN for a dead pixel)")
    return a


def _declared(path, shape, itemsize: int) -> None:
    """Refuse a stack whose declared pixels the memory cannot hold, before reading them."""
    n = float(np.prod([float(s) for s in shape]))
    check_memory(n * max(itemsize, 1) + _BYTES_PER_VALUE * n,
                 f"camera file {str(path)!r} ({format_bytes(n * itemsize)} of pixels)",
                 "the number of frames or pixels (split the file)")


# --------------------------------------------------------------------------- FLIR

def _flir_clock(fh, records) -> float | None:
    """s since the epoch: FLIR's CameraInfo ``DateTimeOriginal`` (at 0x384: int32u seconds,
    int32u milliseconds in its low 16 bits; exiftool's FLIR tags), None when zero."""
    info = records.get(32)
    if info is None or info[3] < 0x384 + 8:
        return None
    fh.seek(info[2] + 0x384)
    raw = fh.read(8)
    if len(raw) < 8:
        return None
    seconds, sub = struct.unpack("<II", raw)
    return None if seconds == 0 else seconds + (sub & 0xFFFF) / 1000.0


def _exif_clock(exif) -> float | None:
    """s since the epoch from EXIF ``DateTimeOriginal`` + ``SubSecTimeOriginal`` (or
    ``DateTime`` + ``SubSecTime``), None without them."""
    sub_ifd = exif.get_ifd(0x8769)
    for tag, sub_tag, where in ((36867, 37521, sub_ifd), (306, 37520, exif)):
        text = where.get(tag)
        if not isinstance(text, str):
            continue
        try:
            stamp = dt.datetime.strptime(text.strip("\x00 "), "%Y:%m:%d %H:%M:%S")
        except ValueError:
            continue
        sub = str(sub_ifd.get(sub_tag) or exif.get(sub_tag) or "").strip("\x00 ")
        frac = float(f"0.{sub}") if sub.isdigit() else 0.0
        return stamp.replace(tzinfo=dt.UTC).timestamp() + frac
    return None


def read_flir(path: str | Path, emissivity: float | None = None) -> FrameSeries:
    """One frame of a FLIR radiometric JPEG: deg C from its raw counts and calibration."""
    flyr = require("flyr", f"the FLIR file {str(path)!r}")
    from flyr.records import extract_flir_app1, parse_flir_records

    with open_regular(path, "camera file", MAX_JPEG_BYTES) as fh:
        if fh.read(2) != b"\xff\xd8":
            raise ValueError(f"{path}: not a JPEG file (a FLIR radiometric JPEG starts with "
                             "FF D8)")
        try:
            fh.seek(0)
            app1 = extract_flir_app1(fh)
            records = parse_flir_records(app1)
            clock = _flir_clock(app1, records)
            fh.seek(0)
            thermogram = flyr.unpack(fh)
            if emissivity is not None:
                thermogram = thermogram.adjust_metadata(emissivity=float(emissivity))
            with np.errstate(all="ignore"):
                celsius = np.asarray(thermogram.celsius, float)
        except (KeyError, IndexError, struct.error, ValueError, OSError, EOFError) as err:
            why = "no FLIR radiometric data (an ordinary JPEG?)" if isinstance(err, KeyError) \
                or "no metadata" in str(err) else shorten(str(err) or type(err).__name__)
            raise ValueError(f"{path}: not a readable FLIR radiometric JPEG: {why}") from None
        if clock is None:
            fh.seek(0)
            from PIL import Image

            try:
                with Image.open(fh) as img:
                    clock = _exif_clock(img.getexif())
            except OSError:
                clock = None
    if not np.isfinite(celsius).any():
        raise ValueError(f"{path}: the FLIR calibration gives no finite temperature (its "
                         "Planck constants or emissivity are damaged)")
    celsius[~np.isfinite(celsius)] = np.nan
    return FrameSeries(None if clock is None else np.array([clock]), celsius[None],
                       clock=clock is not None, source=str(path))


# --------------------------------------------------------------------------- TIFF

def _page_clock(page) -> float | None:
    tag = page.tags.get(306)
    if tag is None or not isinstance(tag.value, str):
        return None
    try:
        stamp = dt.datetime.strptime(tag.value.strip("\x00 "), "%Y:%m:%d %H:%M:%S")
    except ValueError:
        return None
    sub = page.tags.get(37520)
    sub = str(sub.value).strip("\x00 ") if sub is not None else ""
    return stamp.replace(tzinfo=dt.UTC).timestamp() + (float(f"0.{sub}") if sub.isdigit() else 0.0)


def read_tiff(path: str | Path) -> FrameSeries:
    """A TIFF stack (pages or a 3-D series) of deg C."""
    path = Path(path)
    tifffile = require("tifffile", f"the TIFF file {str(path)!r}")
    with open_regular(path, "camera file") as fh:
        try:
            with tifffile.TiffFile(fh, name=path.name) as tf:
                if not tf.series:
                    raise ValueError(f"{path}: no image in this TIFF file")
                series = tf.series
                if len({tuple(x.shape) for x in series}) > 1:
                    raise ValueError(f"{path}: its images differ in shape "
                                     f"{shorten([tuple(x.shape) for x in series])}")
                shape = (len(series), *series[0].shape)  # a stack, or one page a frame
                _declared(path, shape, np.dtype(series[0].dtype).itemsize)
                frames = series[0].asarray() if len(series) == 1 else np.stack(
                    [x.asarray() for x in series])
                metas = [m or {} for m in tf.shaped_metadata or ()]
                meta = metas[0] if metas else {}
                if 1 < len(series) == len(metas) and all("times" in m for m in metas):
                    # written a page (a series) at a time, each with its own times
                    meta = {"times": np.concatenate([np.asarray(m["times"], float).reshape(-1)
                                                     for m in metas])}
                ij = tf.imagej_metadata or {}
                pages = [p for p in tf.pages if p is not None]
                clocks = [_page_clock(p) for p in pages] if len(pages) > 1 else []
        except Exception as err:  # noqa: BLE001 - tifffile raises many kinds on damaged files
            if str(path) in str(err):  # ours, naming the file
                raise
            raise ValueError(f"{path}: not a readable TIFF file ({type(err).__name__}: "
                             f"{shorten(str(err))})") from None
    frames = _frames_array(path, frames)
    n = frames.shape[0]
    if "times" in meta:
        times = np.asarray(meta["times"], dtype=float).reshape(-1)
        return FrameSeries(_checked_times(path, times, n), frames, source=str(path))
    if ij.get("finterval"):
        return FrameSeries(float(ij["finterval"]) * np.arange(n), frames, clock=True,
                           source=str(path))
    if len(clocks) == n and all(c is not None for c in clocks):
        return FrameSeries(np.array(clocks), frames, clock=True, source=str(path))
    return FrameSeries(None, frames, source=str(path))


# --------------------------------------------------------------------------- HDF5

def _dataset(h5py, f, name: str, path):
    """The dataset ``name`` of ``f``, refused when it is a link to another file or has
    external or virtual storage (which would read other files), or holds no numbers."""
    link = f.get(name, getlink=True)
    if link is None:
        return None
    if not isinstance(link, h5py.HardLink | h5py.SoftLink):
        raise ValueError(f"{path}: {name!r} is a link to another file ({type(link).__name__}); "
                         "copy the data into this file")
    ds = f[name]
    if not isinstance(ds, h5py.Dataset):
        raise ValueError(f"{path}: {name!r} is a group, not an array")
    if ds.external or ds.is_virtual:
        raise ValueError(f"{path}: {name!r} keeps its data in other files (external or "
                         "virtual storage); copy the data into this file")
    if ds.dtype.kind not in "biuf":
        raise ValueError(f"{path}: {name!r} must hold numbers, got dtype "
                         f"{shorten(str(ds.dtype))}")
    return ds


def read_hdf5(path: str | Path) -> FrameSeries:
    """An HDF5 file with a dataset ``frames`` (n, ny, nx) deg C and ``times`` (n,) s, or an
    attribute ``rate`` (Hz) of ``frames``."""
    path = Path(path)
    h5py = require("h5py", f"the HDF5 file {str(path)!r}")
    with open_regular(path, "camera file") as fh:
        try:
            with h5py.File(fh, "r") as f:
                ds = _dataset(h5py, f, "frames", path)
                if ds is None:
                    raise ValueError(f"{path}: no dataset 'frames' (need 'frames' (n, ny, nx) "
                                     f"deg C, and 'times' (n,) s or an attribute 'rate'); it "
                                     f"has {shorten(sorted(f.keys()))}")
                _declared(path, ds.shape, ds.dtype.itemsize)
                frames = ds[()]
                rate = ds.attrs.get("rate")
                ts = _dataset(h5py, f, "times", path)
                times = None if ts is None else np.asarray(ts[()], float).reshape(-1) \
                    if ts.size <= frames.shape[0] + 1 else None
                if ts is not None and times is None:
                    raise ValueError(f"{path}: 'times' holds {ts.size} values for "
                                     f"{frames.shape[0]} frames")
        except Exception as err:  # noqa: BLE001 - h5py raises OSError, KeyError, ...
            if str(path) in str(err):  # ours, naming the file
                raise
            raise ValueError(f"{path}: not a readable HDF5 file ({type(err).__name__}: "
                             f"{shorten(str(err))})") from None
    frames = _frames_array(path, frames)
    n = frames.shape[0]
    if times is not None:
        return FrameSeries(_checked_times(path, times, n), frames, source=str(path))
    if rate is not None:
        rate = float(np.asarray(rate).reshape(-1)[0])
        if not (np.isfinite(rate) and rate > 0):
            raise ValueError(f"{path}: attribute 'rate' of 'frames' must be > 0 Hz, got {rate!r}")
        return FrameSeries(np.arange(n) / rate, frames, clock=True, source=str(path))
    return FrameSeries(None, frames, source=str(path))


# --------------------------------------------------------------------------- NPZ, folders

def _checked_times(path, times: np.ndarray, n: int) -> np.ndarray:
    if times.shape != (n,):
        raise ValueError(f"{path}: {times.size} times for {n} frames")
    if not np.all(np.isfinite(times)):
        raise ValueError(f"{path}: the times must be finite, got "
                         f"{float(times[~np.isfinite(times)][0])!r}")
    d = np.diff(times)
    if np.any(d <= 0):
        k = int(np.flatnonzero(d <= 0)[0])
        raise ValueError(f"{path}: the times must be strictly increasing, got "
                         f"{float(times[k])!r} then {float(times[k + 1])!r} s")
    return times


def read_frame_file(path: str | Path, emissivity: float | None = None) -> FrameSeries:
    """The frames of one camera file, by its suffix (see the module's table)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in FLIR_SUFFIXES:
        return read_flir(path, emissivity)
    if suffix in TIFF_SUFFIXES:
        return read_tiff(path)
    if suffix in HDF5_SUFFIXES:
        return read_hdf5(path)
    if suffix == ".npz":
        from .readers import load_frames

        times, frames = load_frames(path, flat=False)
        return FrameSeries(times, frames, source=str(path))
    if suffix in FLIR_SEQUENCE_SUFFIXES:
        # flyr reads FLIR's radiometric JPEGs, not the raw frame sequences of its cameras
        raise ValueError(f"{path}: FLIR sequences ({', '.join(FLIR_SEQUENCE_SUFFIXES)}) are "
                         "not read here: export the sequence from FLIR's software (FLIR "
                         "Tools, FLIR Thermal Studio) as radiometric JPEGs or as a TIFF stack "
                         "of temperatures, and give those")
    raise ValueError(f"{path}: not a camera file this tool reads (suffixes "
                     f"{', '.join(FRAME_SUFFIXES)})")


def _natural(name: str):
    """Sort key: ``frame2`` before ``frame10``."""
    return [int(p) if p.isdigit() else p.lower() for p in re.split(r"(\d+)", name)]


def frame_files(folder: str | Path) -> list[Path]:
    """The camera files of ``folder`` in natural name order (hidden files and files of
    other suffixes, such as a writer's ``.tmp``, are passed over)."""
    folder = Path(folder)
    names = [e.name for e in os.scandir(folder)
             if not e.name.startswith(".") and Path(e.name).suffix.lower() in FRAME_SUFFIXES]
    return [folder / n for n in sorted(names, key=_natural)]


def read_frames(path: str | Path, *, rate: float | None = None,
                emissivity: float | None = None) -> FrameSeries:
    """Frames and times of a camera file or of a folder of frames (one or more a file).

    Parameters
    ----------
    rate : Hz, the frames' rate where the files carry no times (``sensors.rate``).
    emissivity : replaces a FLIR file's emissivity.

    Returns a :class:`FrameSeries` whose times are set (clock times made seconds since
    the first frame). Raises ValueError naming the file for every problem.
    """
    path = Path(path)
    if path.is_dir():
        files = frame_files(path)
        if not files:
            raise ValueError(f"{path}: a folder with no camera file "
                             f"({', '.join(FRAME_SUFFIXES)})")
        parts = [read_frame_file(f, emissivity) for f in files]
        shapes = {p.frames.shape[1:] for p in parts}
        if len(shapes) > 1:
            bad = next(p for p in parts if p.frames.shape[1:] != parts[0].frames.shape[1:])
            raise ValueError(f"{bad.source}: frames of {bad.frames.shape[1:]} pixels, the "
                             f"folder's first file {parts[0].frames.shape[1:]}")
        n_bytes = sum(p.frames.nbytes for p in parts)
        check_memory(2 * n_bytes, f"the frames of {str(path)!r} ({format_bytes(n_bytes)})",
                     "the number of frames (split the folder)")
        timed = [p.times is not None for p in parts]
        frames = np.concatenate([p.frames for p in parts])
        if all(timed):
            times = np.concatenate([p.times for p in parts])
            clock = parts[0].clock
            series = FrameSeries(times, frames, clock, str(path))
            if clock:
                _checked_times(path, times, times.size)
        elif any(timed):
            k = timed.index(not timed[0])
            raise ValueError(f"{files[k]}: {'has' if timed[k] else 'has no'} times, unlike "
                             f"{files[0].name}: the folder's files must all carry times or none")
        else:
            series = FrameSeries(None, frames, False, str(path))
    else:
        series = read_frame_file(path, emissivity)
    if series.times is None:
        if rate is None:
            raise ValueError(f"{path}: the frames carry no times: set sensors.rate (Hz) in the "
                             "config")
        series.times, series.clock = np.arange(series.frames.shape[0]) / float(rate), True
    elif series.clock:
        series.times = _checked_times(path, series.times - series.times[0],
                                      series.frames.shape[0])
    if not np.isfinite(series.frames).any():
        raise ValueError(f"{path}: no usable reading: every pixel of every frame is NaN")
    return series


def describe(series: FrameSeries) -> dict:
    """run.json's record of what was read."""
    return {"frames": int(series.frames.shape[0]), "shape": list(series.frames.shape[1:]),
            "times_from": "clock" if series.clock else "file"}
