"""The advice on the live page (``identify --follow ... --serve`` with ``[advice]``): what the
page reads of ``advice.csv`` and shows, in a bokeh document without a browser (the
browser test of the page is tests/test_live_page.py)."""

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("bokeh", reason="the live page needs bokeh (pip install 'tissue-enkf[camera]')")

from enkf.app.live_page import RunSource, advice_columns, advice_text, make_document  # noqa: E402
from enkf.tissue.advice import AdviceRow  # noqa: E402
from enkf.tissue.outputs import write_advice_csv  # noqa: E402

Q = (0.05, 0.95)


def _row(t, stop, p_prot, p_surf):
    return AdviceRow(t, (stop[0] + 0.2, stop[1] + 0.2, stop[2] + 0.2), 0.9, stop,
                     {"protected_plan": p_prot, "protected_off": 0.0,
                      "protected_at_target": p_prot / 2, "surface_plan": p_surf,
                      "surface_off": 0.0, "surface_at_target": p_surf / 2}, 0.012)


def _run_dir(tmp_path: Path, advice_rows) -> Path:
    (tmp_path / "estimates.csv").write_text(
        "time_s,mua_mean,mua_std,mus_mean,mus_std,T1_mean,T1_std\n"
        + "".join(f"{r.time},1.5,0.1,120,10,40,0.5\n" for r in advice_rows))
    write_advice_csv(tmp_path / "advice.csv", advice_rows, Q)
    return tmp_path


def test_the_status_line_gives_the_stop_time_its_interval_and_the_risks():
    header = list(_row(0.1, (3.0, 2.5, 3.6), 0.2, 0.4).as_dict(Q))
    cols = advice_columns(header)
    assert cols["stop"] == ("stop_time_median_s", "stop_time_q5_s", "stop_time_q95_s")
    assert cols["quantiles"] == ["5", "95"]
    assert cols["risks"] == {"P(protected over its limit)": "p_protected_plan",
                             "P(surface over its limit)": "p_surface_plan"}
    row = list(_row(0.1, (3.0, 2.5, 3.6), 0.2, 0.4).as_dict(Q).values())
    assert advice_text(header, row) == (
        "stop the laser at 3.00 s (5%-95%: 2.50 s to 3.60 s) &middot; "
        "P(protected over its limit) = 0.20 &middot; P(surface over its limit) = 0.40")
    row = list(_row(0.1, (3.0, 2.5, np.inf), 0.2, 0.4).as_dict(Q).values())
    assert "2.50 s to beyond the horizon" in advice_text(header, row)


def _poll_of(doc, source):
    """Make the page on ``doc`` and return the callback it polls the run's files with."""
    polls = []
    add = doc.add_periodic_callback
    doc.add_periodic_callback = lambda callback, period: polls.append(callback) or add(callback, period)
    make_document(doc, source)
    return polls[0]


def test_the_page_shows_the_advice_as_it_is_written(tmp_path):
    from bokeh.document import Document
    from bokeh.models import ColumnDataSource, Div

    rows = [_row(0.1, (4.0, 3.0, np.inf), 0.3, 0.5), _row(0.2, (3.5, 3.1, 4.2), 0.25, 0.6)]
    run = _run_dir(tmp_path, rows)
    source = RunSource(run)
    doc = Document()
    poll = _poll_of(doc, source)
    poll()
    status = next(m for m in doc.select({"type": Div}) if m.name == "status")
    assert "readings: 2" in status.text
    assert "stop the laser at 3.50 s (5%-95%: 3.10 s to 4.20 s)" in status.text
    assert "P(protected over its limit) = 0.25" in status.text
    assert "P(surface over its limit) = 0.60" in status.text
    srcs = list(doc.select({"type": ColumnDataSource}))
    stop = next(s for s in srcs if set(s.data) == {"t", "m", "lo", "hi"})
    assert list(stop.data["t"]) == [0.1, 0.2] and list(stop.data["m"]) == [4.0, 3.5]
    assert np.isnan(stop.data["hi"][0]) and stop.data["hi"][1] == 4.2  # inf: not drawn
    risks = next(s for s in srcs if "p_surface_plan" in s.data)
    assert list(risks.data["p_protected_plan"]) == [0.3, 0.25]

    # a line being written is read once it is whole
    with open(run / "advice.csv", "a", encoding="utf-8") as fh:
        d = _row(0.3, (3.4, 3.2, 3.9), 0.1, 0.7).as_dict(Q)
        line = ",".join(f"{v:.6g}" for v in d.values())
        fh.write(line[:10])
        fh.flush()
        poll()
        assert len(stop.data["t"]) == 2
        fh.write(line[10:] + "\n")
    poll()
    assert list(stop.data["t"]) == [0.1, 0.2, 0.3]
    assert "stop the laser at 3.40 s" in status.text


def test_a_run_without_advice_shows_none(tmp_path):
    from bokeh.document import Document
    from bokeh.models import Div

    run = _run_dir(tmp_path, [_row(0.1, (4.0, 3.0, 5.0), 0.3, 0.5)])
    (run / "advice.csv").unlink()
    doc = Document()
    _poll_of(doc, RunSource(run))()
    status = next(m for m in doc.select({"type": Div}) if m.name == "status")
    assert "readings: 1" in status.text and "stop the laser" not in status.text


def test_replay_reveals_the_advice_with_its_readings(tmp_path):
    run = _run_dir(tmp_path, [_row(0.0, (4.0, 3.0, 5.0), 0.3, 0.5),
                              _row(50.0, (3.5, 3.1, 4.2), 0.25, 0.6)])
    source = RunSource(run, replay_speed=1.0)
    assert len(source.new_advice()) == 1  # the second row's time has not come
    assert source.advice_header[0] == "time_s"
