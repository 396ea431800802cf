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

``--pin`` runs the filter (and the page's server, its child) on the last CPU and the
browser's processes on the others (``taskset``): on two cores a browser that the scheduler
moves onto the filter's core lengthens the filter's steps, one kept off it does not.

    python benchmarks/bench_live_page.py [--frames 100] [--rate 10] [--repeat 2] [--pixels 64]
                                         [--binning 4] [--modes none page] [--pin]
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


def _cpu_s(pids) -> float:
    """CPU seconds (user + system) of the living processes ``pids`` (Linux ``/proc``)."""
    tick, total = os.sysconf("SC_CLK_TCK"), 0.0
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += (int(fields[11]) + int(fields[12])) / tick
    return total


def _descendants(pid: int) -> list[int]:
    """The living processes below ``pid`` (its children, theirs, ...)."""
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(d.name))
    out, todo = [], [pid]
    while todo:
        kids = children.get(todo.pop(), [])
        out += kids
        todo += kids
    return out


def _cpu_parts(filter_pid: int) -> dict:
    """CPU seconds so far: the filter, its page server (its children), the browser (the
    other descendants of this process)."""
    server = _descendants(filter_pid)
    browser = [p for p in _descendants(os.getpid()) if p != filter_pid and p not in server]
    return {"filter": _cpu_s([filter_pid]), "server": _cpu_s(server), "browser": _cpu_s(browser)}


def one_run(work: Path, cfg: Path, f: np.ndarray, rate: float, mode: str, cache: str,
            pin: bool = False) -> dict:
    import tifffile

    serve = mode != "none"

    live, out = work / "camera", work / "run"
    for p in (live, out):
        shutil.rmtree(p, ignore_errors=True)
    live.mkdir()
    cmd = [sys.executable, "-m", "enkf.app.cli", "identify", str(cfg), "--follow", str(live),
           "--out", str(out), "--quiet", "--cache-dir", cache, "--idle-timeout", "10"]
    if serve:
        cmd += ["--serve", "0"]
    if pin:  # the filter (and its page's server) on the last CPU
        cmd = ["taskset", "-c", str(os.cpu_count() - 1), *cmd]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE if serve else subprocess.DEVNULL, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))
    browser = pw = None
    if mode == "server":
        next(line for line in proc.stdout if line.startswith("live page: "))
    if mode == "page":
        url = next(line.split("live page: ")[1].strip() for line in proc.stdout
                   if line.startswith("live page: "))
        from playwright.sync_api import sync_playwright

        pw = sync_playwright().start()
        browser = pw.chromium.launch(executable_path=shutil.which("chromium"),
                                     args=["--no-sandbox"])
        if pin:  # the browser's processes on the other CPUs
            others = f"0-{os.cpu_count() - 2}"
            filt = set(_descendants(proc.pid)) | {proc.pid}
            for pid in set(_descendants(os.getpid())) - filt:
                subprocess.run(["taskset", "-a", "-p", "-c", others, str(pid)],
                               capture_output=True, check=False)
        page = browser.new_page()
        page.goto(url)
        page.locator("text=waiting for the first reading").first.wait_for(timeout=60_000)
    else:
        time.sleep(3.0)  # the filter's setup, as the page's start gives it in the other run
    cpu0, tic = _cpu_parts(proc.pid), time.monotonic()
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
    cpu = _cpu_parts(proc.pid)
    if browser is not None:
        browser.close()
        pw.stop()
    if serve:
        proc.send_signal(2)
    proc.wait(timeout=60)
    return {"readings": info.get("readings"), "step_mean": info["step_s"]["mean"],
            "step_p95": info["step_s"]["p95"], "written_s": written, "done_after_s": lag,
            "cpu_s": {k: round(cpu[k] - cpu0[k], 2) for k in cpu}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--rate", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--pixels", type=int, default=64, help="the frames are PIXELS x PIXELS")
    ap.add_argument("--binning", type=int, default=4,
                    help="sensors.camera.binning: the filter reads the means of BINNING x BINNING "
                         "blocks (1: every pixel)")
    ap.add_argument("--modes", nargs="+", default=["none", "page"],
                    choices=["none", "server", "page"],
                    help="the runs of each repeat: no page, the server with no browser, the page")
    ap.add_argument("--pin", action="store_true",
                    help="the filter on the last CPU, the browser on the others (Linux taskset)")
    args = ap.parse_args(argv)
    if args.pin and (shutil.which("taskset") is None or (os.cpu_count() or 1) < 2):
        ap.error("--pin needs taskset (util-linux) and at least 2 CPUs")
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
        for mode in args.modes:
            r = one_run(work, cfg, f, args.rate, mode, cache, args.pin)
            rows.append((mode, r))
            print(f"repeat {rep} {mode}: {r}", flush=True)
    for mode in args.modes:
        rs = [r for m, r in rows if m == mode]
        cpu = {k: np.mean([r["cpu_s"][k] for r in rs]) for k in rs[0]["cpu_s"]}
        print(f"{mode}: readings "
              f"{[r['readings'] for r in rs]} of {args.frames - 1}, step mean "
              f"{1e3 * np.mean([r['step_mean'] for r in rs]):.1f} ms, p95 "
              f"{1e3 * np.mean([r['step_p95'] for r in rs]):.1f} ms, done "
              f"{np.mean([r['done_after_s'] for r in rs]):.2f} s after the last frame; CPU s "
              + ", ".join(f"{k} {v:.1f}" for k, v in cpu.items()))
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
