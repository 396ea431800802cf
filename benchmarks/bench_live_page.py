"""Does the live page slow the filter? 10 Hz frames of 64 x 64 pixels, with and without it.

The benchmark saves a camera's frames (64 x 64 pixels of 75 um, ``--pixels``, over the tiny block of
``examples/tiny.toml``, a warming spot with 0.1 deg C noise) into a folder at ``--rate``
Hz, each written beside and renamed into place, as a camera's software does;
``tissue-enkf identify --follow FOLDER`` runs in its own process, once without the page
and once with ``--serve`` and a headless Chromium showing it (playwright, Debian's
chromium). Reported for each: the frames assimilated (none dropped: all but the baseline
frame), the filter's step time (run.json ``step_s``: the wall time of each update, mean
and 95th percentile) and the stream's length against the data's. The two runs alternate
``--repeat`` times (the machine's other load changes between them).

The filter reads the frames as super-pixels, the means of ``--binning`` x ``--binning``
blocks (default 4: 16 x 16 readings of a 64 x 64 frame; 1 reads every pixel, whose dense
4096 x 4096 model-error covariance takes seconds a step).

    python benchmarks/bench_live_page.py [--frames 100] [--rate 10] [--repeat 2] [--pixels 64]
                                         [--binning 4]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CONFIG = """
[sensors]
positions = []
rate = {rate}

[sensors.camera]
shape = [{n}, {n}]
pixel_size = {pixel}
spot_center = [{c}, {c}]
# the frames are a stand-in for the model's image: a wide model error keeps the filter on
# them (the benchmark times the steps; validation/ measures the estimates)
model_error_rel_std = 0.5
binning = {binning}
"""


def frames(n: int, rate: float, pixels: int) -> np.ndarray:
    """(n, pixels, pixels) deg C: a spot that warms for 1 s, then cools."""
    y, x = np.mgrid[:pixels, :pixels]
    c, sd = (pixels - 1) / 2, 0.073 / (0.48 / pixels)  # as tests/test_camera_cli.py's
    shape = np.exp(-((x - c) ** 2 + (y - c) ** 2) / (2 * sd ** 2))
    t = np.arange(n) / rate
    amp = 5.5 * np.minimum(t, 1.0) * np.exp(-np.maximum(t - 1.0, 0.0) / 3.0)
    rng = np.random.default_rng(0)
    noise = 0.1 * rng.standard_normal((n, pixels, pixels))
    return (amp[:, None, None] * shape + noise).astype("f4")


def one_run(work: Path, cfg: Path, f: np.ndarray, rate: float, serve: bool, cache: str) -> dict:
    import tifffile

    live, out = work / "camera", work / "run"
    for p in (live, out):
        shutil.rmtree(p, ignore_errors=True)
    live.mkdir()
    cmd = [sys.executable, "-m", "enkf.app.cli", "identify", str(cfg), "--follow", str(live),
           "--out", str(out), "--quiet", "--cache-dir", cache, "--idle-timeout", "10"]
    if serve:
        cmd += ["--serve", "0"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE if serve else subprocess.DEVNULL, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))
    browser = pw = None
    if serve:
        url = next(line.split("live page: ")[1].strip() for line in proc.stdout
                   if line.startswith("live page: "))
        from playwright.sync_api import sync_playwright

        pw = sync_playwright().start()
        browser = pw.chromium.launch(executable_path=shutil.which("chromium"),
                                     args=["--no-sandbox"])
        page = browser.new_page()
        page.goto(url)
        page.locator("text=waiting for the first reading").first.wait_for(timeout=60_000)
    else:
        time.sleep(3.0)  # the filter's setup, as the page's start gives it in the other run
    tic = time.monotonic()
    for k, frame in enumerate(f):
        tmp = live / f".f{k}.tmp"
        tifffile.imwrite(tmp, frame, photometric="minisblack")
        os.replace(tmp, live / f"f{k:04d}.tif")
        time.sleep(max(0.0, tic + (k + 1) / rate - time.monotonic()))
    (live / "END").write_text("")
    written = time.monotonic() - tic
    # the run ends by itself without the page; with it, it keeps the page until Ctrl-C
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            info = json.loads((out / "run.json").read_text())
        except (OSError, ValueError):
            info = {}
        if info and "running" not in info:  # run.json rewritten at the stream's end
            break
        time.sleep(0.2)
    lag = time.monotonic() - tic - written
    if serve:
        browser.close()
        pw.stop()
        proc.send_signal(2)
    proc.wait(timeout=60)
    return {"readings": info.get("readings"), "step_mean": info["step_s"]["mean"],
            "step_p95": info["step_s"]["p95"], "written_s": written, "done_after_s": lag}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--rate", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--pixels", type=int, default=64, help="the frames are PIXELS x PIXELS")
    ap.add_argument("--binning", type=int, default=4,
                    help="sensors.camera.binning: the filter reads the means of BINNING x BINNING "
                         "blocks (1: every pixel)")
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="bench_live_"))
    text = (ROOT / "examples" / "tiny.toml").read_text()
    head, tail = text.split("[sensors]", 1)
    cfg = work / "camera.toml"
    cfg.write_text(head + CONFIG.format(rate=args.rate, n=args.pixels, pixel=0.48 / args.pixels,
                                        c=(args.pixels - 1) / 2, binning=args.binning)
                   + "\n[filter]" + tail.split("[filter]", 1)[1])
    cache = str(work / "cache")
    f = frames(args.frames, args.rate, args.pixels)
    rows = []
    for rep in range(args.repeat):
        for serve in (False, True):
            r = one_run(work, cfg, f, args.rate, serve, cache)
            rows.append((serve, r))
            print(f"repeat {rep} {'page' if serve else 'no page'}: {r}", flush=True)
    for serve in (False, True):
        rs = [r for s, r in rows if s == serve]
        print(f"{'with the page' if serve else 'without it'}: readings "
              f"{[r['readings'] for r in rs]} of {args.frames - 1}, step mean "
              f"{1e3 * np.mean([r['step_mean'] for r in rs]):.1f} ms, p95 "
              f"{1e3 * np.mean([r['step_p95'] for r in rs]):.1f} ms, done "
              f"{np.mean([r['done_after_s'] for r in rs]):.2f} s after the last frame")
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
