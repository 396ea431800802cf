"""Property tests of the data readers on hostile bytes (issue 51), a few seconds in all.

Whatever the bytes, an NPZ series either loads (finite increasing times, frames of the
declared shape) or is refused with a ValueError, and nothing is allocated from a header
before it is checked; a followed stream never stops on a bad data line: every line is
assimilated, skipped (with its number) or a comment (the filter's health check may still
stop it on a reading it cannot follow).
"""

from __future__ import annotations

import io
import zipfile

import numpy as np
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from enkf.app.readers import follow_csv, load_frames
from enkf.problem import FilterDivergence
from enkf.tissue import OnlineIdentifier
from mcmatlab_py.files import npz_headers


def _valid_npz() -> bytes:
    buf = io.BytesIO()
    np.savez(buf, times=np.array([0.1, 0.2, 0.3]), frames=np.arange(24.0).reshape(3, 2, 4))
    return buf.getvalue()


VALID = _valid_npz()
SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])


@SETTINGS
@given(st.lists(st.tuples(st.integers(0, len(VALID) - 1), st.integers(0, 255)), max_size=8),
       st.integers(0, len(VALID)))
# a member's flags in the central directory: compressed patched data (bit 5), encrypted
@example(flips=[(654, 32)], cut=724)
@example(flips=[(654, 1)], cut=724)
def test_a_damaged_npz_loads_or_is_refused(tmp_path_factory, flips, cut):
    raw = bytearray(VALID[:max(cut, 30)])
    for pos, byte in flips:
        if pos < len(raw):
            raw[pos] = byte
    p = tmp_path_factory.mktemp("npz") / "f.npz"
    p.write_bytes(bytes(raw))
    try:
        times, frames = load_frames(p)
    except ValueError as err:
        assert str(err)
        return
    assert times.ndim == 1 and np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)
    assert frames.shape[0] == times.size and not np.any(np.isinf(frames))


@SETTINGS
@given(st.binary(max_size=300))
def test_random_bytes_are_no_npz(tmp_path_factory, data):
    p = tmp_path_factory.mktemp("npz") / "f.npz"
    p.write_bytes(data)
    try:
        npz_headers(p, "data file")
    except ValueError as err:
        assert "data file" in str(err)


@SETTINGS
@given(st.lists(st.tuples(st.sampled_from(["<i8", "<f8", "|u1", "<c16", "|O"]),
                          st.lists(st.integers(0, 10**7), min_size=1, max_size=3)),
                min_size=1, max_size=2))
def test_forged_headers_are_refused_before_allocation(tmp_path_factory, members):
    p = tmp_path_factory.mktemp("npz") / "f.npz"
    with zipfile.ZipFile(p, "w") as zf:
        for k, (descr, shape) in enumerate(members):
            buf = io.BytesIO()
            np.lib.format.write_array_header_1_0(
                buf, {"descr": descr, "fortran_order": False, "shape": tuple(shape)})
            zf.writestr(("times", "frames")[k] + ".npy", buf.getvalue() + bytes(64))
    try:
        load_frames(p)
    except ValueError as err:
        assert str(err)


LINES = st.one_of(
    st.sampled_from(["", "# note", "abc,def", "inf,37", "nan,37", "0.1,inf", "1_0,3",
                     "0.5", "0.5,1,2", "-1,30", "1e400,2", ",", '"0.7","3"', "0x10,1"]),
    st.builds(lambda t, y: f"{t:.3f},{y:.2f}", st.floats(0.01, 3.0), st.floats(-50, 150)),
    st.text(alphabet="0123456789.,e-+ \t\"", max_size=20),
    st.binary(max_size=12).map(lambda b: b.decode("latin-1")),
)


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.lists(LINES, max_size=6))
def test_a_stream_never_stops_on_a_data_line(tmp_path_factory, tissue, lines):
    p = tmp_path_factory.mktemp("live") / "live.csv"
    body = "".join(f"{line}\n".replace("\r", " ") for line in lines if "\n" not in line)
    p.write_bytes(b"time,sensor_0\n" + body.encode("utf-8", "surrogateescape") + b"# end\n")
    skipped, seen = [], []
    try:
        n = follow_csv(p, OnlineIdentifier(tissue.setup(n_members=8)),
                       lambda est, line: seen.append(est.time), idle_timeout_s=1.0,
                       warn=lambda m: None, skipped=skipped)
    except FilterDivergence:  # the health check's verdict on a wild reading, not the reader's
        n = len(seen)
    assert n == len(seen) and np.all(np.diff(seen) > 0)
    assert all(2 <= line <= 1 + len(body.splitlines()) for line, _ in skipped)
