"""Make the example data files (a forward run plus sensor noise), as a user's camera would.

    python examples/make_example_data.py            # tiny_data.csv from tiny.toml (seconds)
    python examples/make_example_data.py --paper    # own_data.csv: the paper's block (minutes)
    python examples/make_example_data.py --two-layer  # two_layer_data.csv (about a minute)
    python examples/make_example_data.py --coagulation  # coagulation_data.csv: optics that
                                                      # follow the damage (minutes, cached)

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


def main(paper: bool = False, out_dir: Path = HERE, photons: int | None = None,
         two_layer: bool = False, coagulation: bool = False) -> Path:
    """Write ``tiny_data.csv`` (or with ``paper``, ``own_data.csv``; with ``two_layer``,
    ``two_layer_data.csv``: the epidermis over the dermis of ``two_layer.toml`` at its given
    optics, 10^6 photons) into ``out_dir``.

    ``photons`` overrides the model's ``MC.n_photons_requested``; the file path is
    returned. ``coagulation``: ``coagulation_data.csv``, the fine-grid truth of
    ``enkf.paper.coagulation`` (single pulse) whose voxels' optics follow their damage.
    """
    out_dir = Path(out_dir)
    if coagulation:
        from enkf.paper import emulator_for
        from enkf.paper.coagulation import CoagulationTruthConfig, damage_truth

        truth = damage_truth(CoagulationTruthConfig(), emulator_for(progress=False))
        write_csv(out_dir / "coagulation_data.csv", truth.times[1:], truth.temps[1:, 0])
        return out_dir / "coagulation_data.csv"
    if paper:
        from enkf.paper import TruthConfig, generate_truth

        truth = generate_truth(TruthConfig(scenario="constant"))
        write_csv(out_dir / "own_data.csv", truth.times[1:], truth.temps[1:, 0])
        return out_dir / "own_data.csv"
    from mcmatlab_py.config import load_model

    name = "two_layer" if two_layer else "tiny"
    model = load_model(HERE / f"{name}.toml")
    if two_layer:  # the sensor of [sensors], the Monte Carlo's voxels as the heat mesh
        model.MC.n_photons_requested = 10**6
        model.HS.temp_sensor_positions = [(0.0, 0.0, 0.0)]
        model.HS.theta = 0.5  # Crank-Nicolson: backward Euler at 0.1 s lags the epidermis
    if photons is not None:
        model.MC.n_photons_requested = photons
    model.MC.progress = model.HS.progress = False
    model.run_monte_carlo().simulate_heat_distribution()
    path = out_dir / ("two_layer_data.csv" if two_layer else "tiny_data.csv")
    write_csv(path, model.HS.sensor_times[1:], model.HS.sensor_temps[1:, 0])
    return path


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paper", action="store_true", help="the paper's block (minutes)")
    ap.add_argument("--two-layer", action="store_true",
                    help="two_layer.toml: an epidermis over the dermis (about a minute)")
    ap.add_argument("--coagulation", action="store_true",
                    help="optics that follow the damage, enkf.paper.coagulation (minutes)")
    ap.add_argument("--out-dir", default=str(HERE))
    a = ap.parse_args()
    main(a.paper, a.out_dir, two_layer=a.two_layer, coagulation=a.coagulation)
