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


def test_the_axes_widen_in_steps_and_hold_every_curve(tmp_path):
    """The curves' ranges are set by the server: they hold all the data drawn (bands
    included) and change only when a reading leaves them, so that the browser does not
    relabel the axes at every reading."""
    from bokeh.document import Document
    from bokeh.models import Plot, Range1d

    from enkf.app.live_page import SPARE, TIME_SPAN_S

    run = _run_dir(tmp_path, [_row(0.1, (4.0, 3.0, 5.0), 0.3, 0.5)])
    (run / "advice.csv").unlink()
    source = RunSource(run)
    doc = Document()
    poll = _poll_of(doc, source)
    poll()

    def ranges():
        figs = [f for f in doc.select({"type": Plot}) if f.title is not None]
        return {f.title.text: (f.x_range.start, f.x_range.end, f.y_range.start, f.y_range.end)
                for f in figs if isinstance(f.y_range, Range1d)}

    first = ranges()
    mua = next(v for k, v in first.items() if k.startswith("mua"))
    assert mua[:2] == (0.0, TIME_SPAN_S)
    assert mua[2] < 1.5 - 0.2 and mua[3] > 1.5 + 0.2  # the band, mean +- 2 sd
    temps = next(v for k, v in first.items() if k.startswith("temperatures"))
    assert temps[2] < 40 - 1.0 and temps[3] > 40 + 1.0
    with open(run / "estimates.csv", "a", encoding="utf-8") as fh:  # inside: nothing moves
        fh.write("0.2,1.52,0.1,121,10,40.2,0.5\n")
    poll()
    assert ranges() == first
    with open(run / "estimates.csv", "a", encoding="utf-8") as fh:  # above, and later
        fh.write("6.1,2.5,0.1,121,10,40.2,0.5\n")
    poll()
    mua = next(v for k, v in ranges().items() if k.startswith("mua"))
    assert mua[:2] == (0.0, 2 * TIME_SPAN_S)
    # a clock far from 0 (a camera's own): the axis starts at the first reading's
    run2 = tmp_path / "late"
    run2.mkdir()
    (run2 / "estimates.csv").write_text(
        "time_s,mua_mean,mua_std,mus_mean,mus_std,T1_mean,T1_std\n1000.1,1.5,0.1,120,10,40,0.5\n")
    doc2 = Document()
    _poll_of(doc2, RunSource(run2))()
    fig = next(f for f in doc2.select({"type": Plot}) if f.title is not None
               and f.title.text.startswith("mua"))
    assert (fig.x_range.start, fig.x_range.end) == (1000.0, 1000.0 + TIME_SPAN_S)
    assert mua[3] >= 2.7 and mua[2] == first[next(k for k in first if k.startswith("mua"))][2]
    assert mua[3] == pytest.approx(2.7 + SPARE * (2.7 - mua[2]))
