"""A forward run from Python: Monte Carlo, then heat, then the sensor series and a VTU.

    python examples/forward_run.py [CONFIG] [--out DIR]

The same as ``tissue-enkf heat CONFIG``, written out so that the steps are visible
(MCmatlab's order: model.run_monte_carlo(), then model.simulate_heat_distribution()).
"""

from __future__ import annotations

import argparse
from pathlib import Path

HERE = Path(__file__).parent


def main(config=HERE / "tiny.toml", out="runs/forward", photons=None) -> dict:
    import fem
    from mcmatlab_py.config import load_model

    model = load_model(config)
    if photons is not None:
        model.MC.n_photons_requested = photons
    model.MC.progress = model.HS.progress = False
    model.run_monte_carlo()
    model.simulate_heat_distribution()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fem.write_vtu(out / "temperature.vtu", model.HS.mesh, point_data={"T": model.HS.T_nodes})
    peak = float(model.HS.sensor_temps[:, 0].max())
    print(f"absorbed {model.MC.absorbed_fraction:.3f} of the beam; sensor 0 peaks at "
          f"{peak:.2f} deg C; {out / 'temperature.vtu'} opens in ParaView or pyvista")
    return {"absorbed_fraction": model.MC.absorbed_fraction, "peak": peak,
            "vtu": out / "temperature.vtu"}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config", nargs="?", default=str(HERE / "tiny.toml"))
    ap.add_argument("--out", default="runs/forward")
    a = ap.parse_args()
    main(a.config, a.out)
