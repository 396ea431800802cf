"""Make the example data files (a forward run plus sensor noise), as a user's camera would.

    python examples/make_example_data.py            # tiny_data.csv from tiny.toml (seconds)
    python examples/make_example_data.py --paper    # own_data.csv: the paper's block (minutes)

The noise (variance 0.01 deg C^2) and a few gaps (empty fields) come from a fixed seed.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent


def write_csv(path: Path, times: np.ndarray, temps: np.ndarray, seed: int = 7) -> None:
    rng = np.random.default_rng(seed)
    noisy = temps + 0.1 * rng.standard_normal(temps.shape)
    gaps = rng.choice(len(times), size=max(1, len(times) // 30), replace=False)
    lines = ["time,sensor_0"]
    for k, (t, v) in enumerate(zip(times, noisy, strict=True)):
        lines.append(f"{t:.2f}," + ("" if k in gaps else f"{v:.4f}"))
    path.write_text("\n".join(lines) + "\n")


def main(paper: bool = False, out_dir: Path = HERE, photons: int | None = None) -> Path:
    """Write ``tiny_data.csv`` (or with ``paper``, ``own_data.csv``) into ``out_dir``.

    ``photons`` overrides the tiny model's ``MC.n_photons_requested``; the file path is
    returned.
    """
    out_dir = Path(out_dir)
    if paper:
        from enkf.paper import TruthConfig, generate_truth

        truth = generate_truth(TruthConfig(scenario="constant"))
        write_csv(out_dir / "own_data.csv", truth.times[1:], truth.temps[1:, 0])
        return out_dir / "own_data.csv"
    from mcmatlab_py.config import load_model

    model = load_model(HERE / "tiny.toml")
    if photons is not None:
        model.MC.n_photons_requested = photons
    model.MC.progress = model.HS.progress = False
    model.run_monte_carlo().simulate_heat_distribution()
    write_csv(out_dir / "tiny_data.csv", model.HS.sensor_times[1:], model.HS.sensor_temps[1:, 0])
    return out_dir / "tiny_data.csv"


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paper", action="store_true", help="the paper's block (minutes)")
    ap.add_argument("--out-dir", default=str(HERE))
    a = ap.parse_args()
    main(a.paper, a.out_dir)
