"""Identification on your own measurements, from Python.

    python examples/identify_own_data.py [CONFIG] [DATA.csv]

The same as ``tissue-enkf identify CONFIG --data DATA.csv``: the config describes the
tissue block, the laser, the sensors and the filter; the CSV holds a ``time`` column (s)
and one column per sensor (deg C, empty for a missing reading).
"""

from __future__ import annotations

import argparse
from pathlib import Path

HERE = Path(__file__).parent


def main(config=HERE / "tiny.toml", data=HERE / "tiny_data.csv", cache_dir=None):
    from enkf.app.config import load_identify
    from enkf.tissue import identify

    cfg = load_identify(config)
    emulator = cfg.emulator(cache_dir=cache_dir, progress=False)  # built once, then cached
    setup = cfg.setup(emulator)
    times, values = cfg.read_data(data)  # checked: sorted times, no Inf, one column per sensor
    est = identify(setup, times, values, param_bounds=cfg.param_bounds)
    for i, name in enumerate(est.names):
        print(f"{name}: {est.param_mean[-1, i]:.4g} +- {est.param_std[-1, i]:.2g}")
    for j, p in enumerate(est.tracked_positions):
        print(f"T at z = {p[2]:g} cm: {est.tracked_mean[-1, j]:.2f} +- "
              f"{est.tracked_std[-1, j]:.2f} deg C")
    return est


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config", nargs="?", default=str(HERE / "tiny.toml"))
    ap.add_argument("data", nargs="?", default=str(HERE / "tiny_data.csv"))
    a = ap.parse_args()
    main(a.config, a.data)
