"""Camera files (enkf.app.frames): FLIR radiometric JPEGs, TIFF stacks, HDF5, folders.

flyr reads FLIR files but cannot write them, and no sample ships with it: the FLIR file
here is built by :func:`flir_jpeg` after the layout flyr and exiftool read (a JPEG whose
APP1 segment ``FLIR\\0`` holds an FFF block: a record directory, the raw counts and the
CameraInfo record with the emissivity, the temperatures of the surroundings, the Planck
constants and FLIR's own time stamp). Its counts come from temperatures through the
radiometric model the camera inverts, written independently of flyr's code: the detector
sees ``e L(T) + (1 - e) L(T_refl)`` with ``L(T) = R1 / (R2 (exp(B / T) - F)) - O``.
"""

import datetime as dt
import io
import struct

import numpy as np
import pytest

from enkf.app.frames import read_frame_file, read_frames

# a FLIR camera's Planck constants (of the order exiftool lists for a FLIR E-series)
R1, R2, B, F, O = 21106.77, 0.012545258, 1501.0, 1.0, -7340


def planck_counts(T_K):
    return R1 / (R2 * (np.exp(B / np.asarray(T_K, float)) - F)) - O


def flir_jpeg(celsius, *, emissivity=0.95, reflected_C=20.0, clock=None, exif=None) -> bytes:
    """A minimal FLIR radiometric JPEG of the temperatures ``celsius`` (h, w)."""
    from PIL import Image

    h, w = celsius.shape
    raw = emissivity * planck_counts(celsius + 273.15) + (1 - emissivity) * planck_counts(
        reflected_C + 273.15)
    raw = np.round(raw).astype("<u2")
    raw_rec = bytearray(32)
    struct.pack_into("<HHH", raw_rec, 0, 2, w, h)
    raw_rec += raw.tobytes()
    cam = bytearray(1024)
    atm = 293.15
    # emissivity, distance (m), reflected, atmosphere, IR window temperature, its transmission
    struct.pack_into("<6f", cam, 32, emissivity, 0.0, reflected_C + 273.15, atm, atm, 1.0)
    struct.pack_into("<f", cam, 60, 0.0)  # relative humidity
    struct.pack_into("<3f", cam, 88, R1, B, F)
    struct.pack_into("<5f", cam, 112, 0.006569, 0.01262, -0.002276, -0.00667, 1.9)
    struct.pack_into("<if", cam, 776, O, R2)
    if clock is not None:  # FLIR's DateTimeOriginal: seconds, milliseconds
        struct.pack_into("<II", cam, 0x384, int(clock), int(round((clock % 1) * 1000)))
    records = [(1, 2, bytes(raw_rec)), (32, 1, bytes(cam))]
    n_entries = len(records) + 2  # two empty entries close the directory
    head = bytearray(0x40)
    head[0:4] = b"FFF\x00"
    struct.pack_into(">III", head, 0x14, 100, 0x40, n_entries)
    offset = 0x40 + 32 * n_entries
    directory, body = b"", b""
    for kind, sub, data in records:
        directory += struct.pack(">HHIIIIIII", kind, sub, 0x64, 1, offset + len(body), len(data),
                                 0, 0, 0)
        body += data
    directory += bytes(32 * (n_entries - len(records)))
    fff = bytes(head) + directory + body
    segment = b"\xff\xe1" + struct.pack(">H", 10 + len(fff)) + b"FLIR\x00\x01\x00\x00" + fff
    buf = io.BytesIO()
    img = Image.new("RGB", (w, h), (90, 90, 90))
    ex = Image.Exif()
    if exif is not None:  # (DateTimeOriginal, SubSecTimeOriginal)
        ex.get_ifd(0x8769).update({36867: exif[0], 37521: exif[1]})
    img.save(buf, "JPEG", exif=ex)
    jpg = buf.getvalue()
    return jpg[:2] + segment + jpg[2:]


def spot(shape=(6, 8), peak=12.0, base=30.0):
    y, x = np.mgrid[: shape[0], : shape[1]]
    return base + peak * np.exp(-((x - 4.2) ** 2 + (y - 2.6) ** 2) / 4.0)


needs_flyr = pytest.mark.skipif(__import__("importlib").util.find_spec("flyr") is None,
                                reason="flyr is not installed (pip install 'tissue-enkf[camera]')")


@needs_flyr
def test_a_flir_jpeg_gives_temperatures_with_its_emissivity(tmp_path):
    T = spot()
    p = tmp_path / "IR_0001.jpg"
    stamp = dt.datetime(2026, 3, 4, 10, 20, 30, tzinfo=dt.UTC).timestamp() + 0.25
    p.write_bytes(flir_jpeg(T, emissivity=0.95, clock=stamp))
    s = read_frame_file(p)
    assert s.frames.shape == (1, 6, 8) and s.clock
    # one count is ~0.005 K here
    np.testing.assert_allclose(s.frames[0], T, atol=0.02)
    assert s.times[0] == pytest.approx(stamp, abs=1e-3)
    # the file's emissivity is what makes them right: taken as 1 they read low
    as_black = read_frame_file(p, emissivity=1.0).frames[0]
    assert np.all(as_black < T - 0.2)


@needs_flyr
def test_a_flir_sequence_as_a_folder_gets_times_from_the_clock(tmp_path):
    t0 = dt.datetime(2026, 3, 4, 10, 20, 30, tzinfo=dt.UTC).timestamp()
    for k in range(3):
        (tmp_path / f"IR_{k + 1:04d}.jpg").write_bytes(flir_jpeg(spot(peak=2.0 * k),
                                                                 clock=t0 + 0.1 * k))
    s = read_frames(tmp_path)
    np.testing.assert_allclose(s.times, [0.0, 0.1, 0.2], atol=2e-3)
    assert s.frames.shape == (3, 6, 8) and s.frames[2].max() > s.frames[0].max() + 3


@needs_flyr
def test_flir_time_from_exif_when_the_camera_info_has_none(tmp_path):
    p = tmp_path / "a.jpg"
    p.write_bytes(flir_jpeg(spot(), exif=("2026:03:04 10:20:30", "375")))
    s = read_frame_file(p)
    want = dt.datetime(2026, 3, 4, 10, 20, 30, tzinfo=dt.UTC).timestamp() + 0.375
    assert s.times[0] == pytest.approx(want)


def test_tiff_stacks_with_their_times(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    frames = np.random.default_rng(0).normal(30, 1, (4, 5, 6)).astype("f4")
    tifffile.imwrite(tmp_path / "a.tif", frames, photometric="minisblack",
                     metadata={"times": [0.1, 0.2, 0.35, 0.5]})
    s = read_frames(tmp_path / "a.tif")
    np.testing.assert_array_equal(s.times, [0.1, 0.2, 0.35, 0.5])
    np.testing.assert_array_equal(s.frames, frames)
    tifffile.imwrite(tmp_path / "ij.tif", frames, imagej=True,
                     metadata={"finterval": 0.1, "axes": "TYX"})
    np.testing.assert_allclose(read_frames(tmp_path / "ij.tif").times, 0.1 * np.arange(4))
    # one page a frame, each with the camera's DateTime and SubSecTime tags
    for k in range(4):
        tifffile.imwrite(tmp_path / "pages.tif", frames[k], append=True,
                         datetime=f"2026:03:04 10:20:{30 + k // 2:02d}", contiguous=False,
                         extratags=[(37520, "s", 0, f"{5 * (k % 2)}", True)])
    np.testing.assert_allclose(read_frames(tmp_path / "pages.tif").times, [0, 0.5, 1, 1.5])
    tifffile.imwrite(tmp_path / "untimed.tif", frames, photometric="minisblack")
    with pytest.raises(ValueError, match="carry no times: set sensors.rate"):
        read_frames(tmp_path / "untimed.tif")
    np.testing.assert_allclose(read_frames(tmp_path / "untimed.tif", rate=10.0).times,
                               [0, 0.1, 0.2, 0.3])


def test_hdf5_frames_with_times_or_a_rate(tmp_path):
    h5py = pytest.importorskip("h5py")
    frames = np.random.default_rng(1).normal(30, 1, (3, 4, 5))
    with h5py.File(tmp_path / "a.h5", "w") as f:
        f["frames"] = frames
        f["times"] = [0.1, 0.2, 0.3]
    s = read_frames(tmp_path / "a.h5")
    np.testing.assert_array_equal(s.times, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(s.frames, frames)
    with h5py.File(tmp_path / "r.h5", "w") as f:
        f["frames"] = frames.astype("f4")
        f["frames"].attrs["rate"] = 20.0
    np.testing.assert_allclose(read_frames(tmp_path / "r.h5").times, [0, 0.05, 0.1])


def _bad_h5(tmp_path, kind):
    h5py = pytest.importorskip("h5py")
    p = tmp_path / f"{kind}.h5"
    with h5py.File(p, "w") as f:
        if kind == "strings":
            f["frames"] = np.array([b"a", b"b"])
        elif kind == "complex":
            f["frames"] = np.ones((2, 3, 3), complex)
        elif kind == "group":
            f.create_group("frames")
        elif kind == "external link":
            f["frames"] = h5py.ExternalLink("/etc/other.h5", "/frames")
        elif kind == "external storage":
            (tmp_path / "raw.bin").write_bytes(bytes(72))
            f.create_dataset("frames", (1, 3, 3), "<f8", external=[(str(tmp_path / "raw.bin"),
                                                                     0, 72)])
        elif kind == "missing":
            f["images"] = np.ones((2, 3, 3))
        elif kind == "short times":
            f["frames"] = np.ones((3, 3, 3))
            f["times"] = [0.1, 0.2]
        elif kind == "unsorted":
            f["frames"] = np.ones((3, 3, 3))
            f["times"] = [0.1, 0.3, 0.2]
    return p


@pytest.mark.parametrize("kind, pattern", [
    ("strings", "must hold numbers"), ("complex", "complex"), ("group", "is a group"),
    ("external link", "link to another file"), ("external storage", "other files"),
    ("missing", "no dataset 'frames'"), ("short times", "2 times for 3 frames"),
    ("unsorted", "strictly increasing"),
])
def test_bad_hdf5_is_refused_naming_the_file(tmp_path, kind, pattern):
    p = _bad_h5(tmp_path, kind)
    with pytest.raises(ValueError, match=pattern) as info:
        read_frames(p, rate=10.0)
    assert str(p) in str(info.value)


@needs_flyr
def test_bad_camera_files_are_refused_naming_the_file(tmp_path):
    pytest.importorskip("tifffile")
    cases = {
        "plain.jpg": (lambda: _plain_jpeg(), "no FLIR radiometric data"),
        "cut.jpg": (lambda: flir_jpeg(spot())[:300], "not a readable FLIR"),
        "text.jpg": (lambda: b"time,T\n0.1,30\n", "not a JPEG"),
        "noise.tif": (lambda: np.random.default_rng(2).bytes(500), "not a readable TIFF"),
        "text.h5": (lambda: b"hello", "not a readable HDF5"),
        "frames.bmp": (lambda: b"BM", "not a camera file"),
    }
    for name, (make, pattern) in cases.items():
        p = tmp_path / name
        p.write_bytes(make())
        with pytest.raises(ValueError, match=pattern) as info:
            read_frames(p, rate=10.0)
        assert str(p) in str(info.value), name


def test_a_truncated_tiff_stack_is_refused(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    p = tmp_path / "a.tif"
    tifffile.imwrite(p, np.ones((20, 16, 16), "f4"), photometric="minisblack")
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=str(p)):
        read_frames(p, rate=10.0)


def test_a_stack_the_memory_cannot_hold_is_refused_before_it_is_read(tmp_path, monkeypatch):
    h5py = pytest.importorskip("h5py")
    from mcmatlab_py import budget

    p = tmp_path / "big.h5"
    with h5py.File(p, "w") as f:  # declared, never written: nothing is stored
        f.create_dataset("frames", (100_000, 1024, 1024), "f4")
    monkeypatch.setattr(budget, "available_memory", lambda: 2**30)
    with pytest.raises(ValueError, match="needs about .* of memory"):
        read_frames(p, rate=10.0)


def test_a_folder_and_its_odd_files(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    for k in (10, 2, 1):  # natural order: 1, 2, 10
        tifffile.imwrite(tmp_path / f"f{k}.tif", np.full((3, 4), float(k), "f4"))
    (tmp_path / ".f3.tif.partial").write_bytes(b"half")  # a writer's temporary: passed over
    (tmp_path / "notes.txt").write_text("x")
    s = read_frames(tmp_path, rate=5.0)
    assert s.frames[:, 0, 0].tolist() == [1.0, 2.0, 10.0]
    np.testing.assert_allclose(s.times, [0, 0.2, 0.4])
    tifffile.imwrite(tmp_path / "f11.tif", np.ones((3, 5), "f4"))
    with pytest.raises(ValueError, match=r"f11.tif: frames of \(3, 5\) pixels"):
        read_frames(tmp_path, rate=5.0)
    with pytest.raises(ValueError, match="no camera file"):
        read_frames(_empty(tmp_path), rate=5.0)


def _empty(tmp_path):
    d = tmp_path / "empty"
    d.mkdir()
    return d


def _plain_jpeg():
    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (8, 6)).save(buf, "JPEG")
    return buf.getvalue()


def test_a_missing_library_says_how_to_install_it(monkeypatch, tmp_path):
    import builtins

    real = builtins.__import__

    def no_tifffile(name, *a, **k):
        if name == "tifffile":
            raise ImportError(name)
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_tifffile)
    monkeypatch.delitem(__import__("sys").modules, "tifffile", raising=False)
    (tmp_path / "a.tif").write_bytes(b"II*\x00")
    with pytest.raises(ValueError, match=r'tissue-enkf\[camera\]'):
        read_frames(tmp_path / "a.tif", rate=1.0)


def test_a_fifo_is_refused_before_it_is_read(tmp_path):
    import os

    p = tmp_path / "cam.tif"
    os.mkfifo(p)
    with pytest.raises(ValueError, match="pipe or FIFO"):
        read_frames(p, rate=1.0)


@pytest.mark.parametrize("suffix", [".seq", ".csq", ".SEQ"])
def test_a_flir_sequence_file_is_refused_with_the_way_to_export_it(tmp_path, suffix):
    p = tmp_path / f"run{suffix}"
    p.write_bytes(b"FFF\x00" + bytes(64))
    with pytest.raises(ValueError, match=r"FLIR sequences .* not read here: export .* "
                                         r"radiometric JPEGs or as a TIFF stack"):
        read_frame_file(p)
