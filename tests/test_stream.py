"""Online identification: OnlineIdentifier and follow_csv on a file that grows."""

import threading
import time

import numpy as np
import pytest

from enkf.app.readers import follow_csv, parse_line
from enkf.tissue import OnlineIdentifier, identify


def test_online_identifier_learns_like_the_batch_filter(tissue):
    s = tissue.setup()
    times, data = tissue.twin_data(s, 1.4, 100.0)
    online = OnlineIdentifier(s)
    for t, y in zip(times, data, strict=True):
        est = online.update(t, y)
    batch = identify(s, times, data)
    # different random streams, the same information: estimates within their spreads
    assert abs(est.param_mean[0] - batch.param_mean[-1, 0]) < 2 * batch.param_std[-1, 0] + 0.02
    assert est.param_std[0] < online.history[0].param_std[0]
    assert len(online.history) == 20 and est.time == pytest.approx(times[-1])
    with pytest.raises(ValueError, match="after"):
        online.update(times[-1], data[-1])
    with pytest.raises(ValueError, match="must hold 1 values"):
        online.update(times[-1] + 0.1, [1.0, 2.0])


def test_a_replay_gives_the_same_estimates(tissue):
    s = tissue.setup()
    times, data = tissue.twin_data(s, 1.2, 100.0)
    runs = []
    for _ in range(2):
        o = OnlineIdentifier(s)
        runs.append([o.update(t, y).param_mean for t, y in zip(times[:5], data[:5], strict=True)])
    np.testing.assert_array_equal(np.array(runs[0]), np.array(runs[1]))


def test_follow_reads_lines_as_they_are_appended(tmp_path, tissue):
    s = tissue.setup()
    times, data = tissue.twin_data(s, 1.4, 100.0)
    path = tmp_path / "live.csv"
    written = []

    def writer():
        with open(path, "w") as f:
            f.write("time,sensor_0\n")
            f.flush()
            for k, (t, y) in enumerate(zip(times[:8], data[:8, 0], strict=True)):
                if k == 3:
                    f.write(f"{t:.3f},\n")  # a gap
                else:
                    f.write(f"{t:.3f},")  # half a line first: must wait for the rest
                    f.flush()
                    time.sleep(0.01)
                    f.write(f"{y:.4f}\n")
                f.flush()
                written.append(k)
                time.sleep(0.03)
            f.write("# end\n")

    seen = []
    th = threading.Thread(target=writer)
    th.start()
    n = follow_csv(path, OnlineIdentifier(s), lambda est, line: seen.append((est, line)),
                   idle_timeout_s=5.0)
    th.join()
    assert n == 8 and len(seen) == 8
    assert [line for _, line in seen] == list(range(2, 10))
    assert not seen[3][0].analysed and seen[4][0].analysed


@pytest.mark.parametrize("line, pattern", [
    ("0.1,abc\n", "field 2 is not a number"),
    ("0.1\n", "expected 2"),
    (",20.0\n", "time must be a finite"),
    ("0.1,inf\n", "infinite"),
])
def test_bad_lines_name_the_place(line, pattern):
    with pytest.raises(ValueError, match=pattern):
        parse_line(line, 2, "live.csv:7")


def test_follow_refuses_a_wrong_header(tmp_path, tissue):
    path = tmp_path / "live.csv"
    for header, pattern in [("time,a,b", "2 data columns, the setup observes 1"),
                            ("t_ms,a", "first column must be 'time'")]:
        path.write_text(f"{header}\n0.1,1,2\n")
        with pytest.raises(ValueError, match=pattern):
            follow_csv(path, OnlineIdentifier(tissue.setup()), lambda *a: None, idle_timeout_s=0.2)
