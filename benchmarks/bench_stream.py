"""Online mode: does the estimate of each frame come out before the next frame (10 Hz)?

A writer thread appends the paper's sensor series (constant scenario, seed 0) to a CSV
at 10 Hz, as an acquisition program would; :func:`enkf.stream.follow_csv` with the
paper's filter (N = 50 on 20 x 20 x 10, emulator cached) reads each line as it comes
and appends the estimate to an output CSV. Latency is from the moment a line is
flushed to the moment its estimate is flushed.

    python benchmarks/bench_stream.py [--scenario constant] [--rate 10]
"""

from __future__ import annotations

import argparse
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from enkf.app.readers import follow_csv
from enkf.paper import TruthConfig, emulator_for, filter_setup, generate_truth, noisy_sensor
from enkf.tissue import OnlineIdentifier


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="constant")
    ap.add_argument("--rate", type=float, default=10.0, help="frames per second")
    args = ap.parse_args(argv)
    truth = generate_truth(TruthConfig(scenario=args.scenario), progress=False)
    data = noisy_sensor(truth, 0)
    setup = filter_setup(args.scenario, emulator_for(progress=False))
    ident = OnlineIdentifier(setup)
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "live.csv", Path(tmp) / "estimates.csv"
        flushed = {}

        def writer():
            with open(src, "w") as f:
                f.write("time,sensor_0\n")
                f.flush()
                t0 = time.perf_counter()
                for k, (t, y) in enumerate(zip(truth.times[1:], data, strict=True)):
                    time.sleep(max(0.0, t0 + k / args.rate - time.perf_counter()))
                    f.write(f"{t:.3f},{y:.4f}\n")
                    f.flush()
                    flushed[k + 2] = time.perf_counter()  # line number in the file
                f.write("# end\n")

        out = open(dst, "w")
        out.write("time,mua,mus\n")
        done = {}

        def on_update(est, line):
            out.write(f"{est.time:.3f},{est.param_mean[0]:.6g},{est.param_mean[1]:.6g}\n")
            out.flush()
            done[line] = time.perf_counter()

        th = threading.Thread(target=writer)
        th.start()
        n = follow_csv(src, ident, on_update, idle_timeout_s=5.0)
        th.join()
        out.close()
    lat = np.array([done[k] - flushed[k] for k in sorted(done)])
    period = 1.0 / args.rate
    print(f"{n} frames at {args.rate:g} Hz: latency median {1e3 * np.median(lat):.1f} ms, "
          f"max {1e3 * lat.max():.1f} ms; estimate out before the next frame for "
          f"{int(np.sum(lat < period))} of {lat.size}")
    print(f"final estimate mua {ident.history[-1].param_mean[0]:.4g}, "
          f"mus {ident.history[-1].param_mean[1]:.4g}")


if __name__ == "__main__":
    main()
