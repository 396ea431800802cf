"""The live page in a real headless browser: identify --follow --serve on a folder a camera
writes, and replay over the recorded run.

Chromium comes from Debian's packages (``apt-get install chromium``), driven by
playwright with that executable (playwright's own browser downloads are not used). Where
either is missing the tests are skipped with a message. Screenshots go to the system's
temporary folder (``live_running.png``, ``live_final.png``, ``replay_final.png``).
"""

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("bokeh", reason="the live page needs bokeh (pip install 'tissue-enkf[camera]')")
playwright_api = pytest.importorskip("playwright.sync_api",
                                     reason="the browser test needs playwright (pip install "
                                            "playwright)")
tifffile = pytest.importorskip("tifffile")
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed "
                                 "(apt-get install chromium)")]

sys.path.insert(0, str(Path(__file__).parent))
from test_camera_cli import camera_config, frames  # noqa: E402

SHOTS = Path(tempfile.gettempdir())


@pytest.fixture(scope="module")
def browser():
    with playwright_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        yield b
        b.close()


def _wait_for(page, what: str, timeout: float) -> str:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            text = page.locator("text=" + what).first.inner_text(timeout=200)
            return text
        except playwright_api.Error:
            time.sleep(0.1)
    raise AssertionError(f"the page never showed {what!r}")


def _status(page) -> str:
    """The status line's whole text."""
    return page.locator("div", has_text="readings:").last.inner_text(timeout=2000)


def _readings(page) -> int:
    return int(_status(page).split("readings:")[1].split()[0])


@pytest.fixture(scope="module")
def served_run(tmp_path_factory, browser):
    """identify --follow --serve on a folder written at 4 Hz, seen in the browser."""
    tmp = tmp_path_factory.mktemp("live")
    cfg = camera_config(tmp, spot="[4.6, 3.2]")  # placed: the filter starts at frame 1
    live, out = tmp / "camera", tmp / "run"
    live.mkdir()
    f = frames(20)  # 2 s at 10 Hz, as the tiny block's heating and cooling
    cache = tmp / "cache"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "enkf.app.cli", "identify", str(cfg),
                             "--follow", str(live), "--out", str(out), "--serve", "0",
                             "--quiet", "--cache-dir", str(cache), "--idle-timeout", "20"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        url = None
        for line in proc.stdout:
            if line.startswith("live page: "):
                url = line.split("live page: ")[1].strip()
                break
        assert url, proc.stderr.read()

        def writer():
            for k, frame in enumerate(f):
                t = live / f".f{k}.tmp"
                tifffile.imwrite(t, frame.astype("f4"), photometric="minisblack")
                os.replace(t, live / f"f{k:03d}.tif")
                time.sleep(0.25)  # 4 Hz: the test's reads of the page (each a round trip to
                # headless Chromium) are slow on 2 cores; at 10 Hz they saw 2 values of 19
            (live / "END").write_text("")

        page = browser.new_page(viewport={"width": 1150, "height": 1000})
        page.goto(url)
        _wait_for(page, "waiting for the first reading", 60)  # the page is up
        th = threading.Thread(target=writer)
        th.start()
        seen, shot = [], False
        while th.is_alive() or not seen or "final estimate" not in _status(page):
            try:
                seen.append(_readings(page))
            except (playwright_api.Error, IndexError, ValueError):
                pass
            if seen and not shot and seen[-1] >= 8:
                page.screenshot(path=str(SHOTS / "live_running.png"), full_page=True)
                shot = True
            time.sleep(0.1)
        th.join()
        _wait_for(page, "final estimate", 60)
        time.sleep(0.5)
        final = _status(page)
        page.screenshot(path=str(SHOTS / "live_final.png"), full_page=True)
        page.close()
        proc.send_signal(signal.SIGINT)  # the finished run's page closes
        rc = proc.wait(timeout=30)
        yield {"seen": seen, "final": final, "rc": rc, "out": out}
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_the_live_page_updates_and_shows_the_final_estimate(served_run):
    seen = served_run["seen"]  # the readings the page showed, sampled every 0.1 s
    assert len(set(seen)) >= 4 and seen == sorted(seen)  # it updates as frames come
    out = served_run["out"]
    rows = (out / "estimates.csv").read_text().splitlines()
    assert len(rows) == 1 + 19
    last = dict(zip(rows[0].split(","), map(float, rows[-1].split(",")), strict=True))
    text = served_run["final"]
    assert "final estimate" in text and "readings: 19" in text and f"mua = {last['mua_mean']:.4g}" in text
    assert f"mus = {last['mus_mean']:.4g}" in text
    assert served_run["rc"] == 0
    for name in ("meta.json", "frame.npy", "risk.npy"):
        assert (out / "live" / name).exists(), name


def test_replay_shows_the_recorded_run(served_run, browser):
    out = served_run["out"]
    proc = subprocess.Popen([sys.executable, "-m", "enkf.app.cli", "replay", str(out),
                             "--port", "0", "--speed", "4"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        url = line.split(" at ")[1].split()[0]
        page = browser.new_page(viewport={"width": 1150, "height": 1000})
        page.goto(url)
        _wait_for(page, "readings:", 30)
        _wait_for(page, "final estimate", 30)
        time.sleep(0.5)
        text = _status(page)
        page.screenshot(path=str(SHOTS / "replay_final.png"), full_page=True)
        page.close()
        assert "final estimate" in text and "readings: 19" in text
        # the same estimate as the live page's at the end
        assert served_run["final"].split("readings")[1] == text.split("readings")[1]
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            assert proc.wait(timeout=20) == 0
        finally:
            if proc.poll() is None:
                proc.kill()
