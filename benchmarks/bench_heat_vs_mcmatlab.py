"""Our heat simulation against MCmatlab's engine on the same problem, with the accuracy of each.

The problem is ``run_heat.m`` of ``../shared/tools/mcmatlab-octave`` (MCmatlab's Example 1
reduced to 61 x 61 x 60 voxels, 0.1 x 0.1 x 0.15 cm: water over standard tissue, a pencil
beam of 0.1 W for 1 s, then 0.5 s without light, insulating faces, 37 deg C, four sensors).
MCmatlab's engine (its C heat solver under GNU Octave) runs it first and saves its absorption
map; ours then heats with that same map, so that only the heat solvers differ:

* ``accuracy``: our default steps (TR-BDF2 with error control, ``HS.rtol``);
* ``stability``: MCmatlab's rule for the step (``HS.step_control = "stability"``);
* the reference: ours on a mesh ``--refine`` times finer in each direction with
  ``rtol = 1e-5``, the voxels' absorbed power unchanged (the solution of the same heat
  problem, converged further in space and time).

Each engine's sensor rises at 1 s and 1.5 s are compared with the reference's. One thread
each (``OMP_NUM_THREADS=1`` for Octave, ``NUMBA_NUM_THREADS=1`` and one BLAS thread here).
Prints a table and writes it as JSON with ``--json``.

    python benchmarks/bench_heat_vs_mcmatlab.py --mcm-root /tmp/mcm/mcm
    python benchmarks/bench_heat_vs_mcmatlab.py --mat /tmp/heatref/heat.mat   # an earlier run

``--mcm-root`` is the folder ``build.sh`` of ``../shared/tools/mcmatlab-octave`` makes.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for _v in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

TOOL = Path(__file__).resolve().parents[1].parent / "shared" / "tools" / "mcmatlab-octave"
SENSORS = [(0, 0, 0.035), (0, 0, 0.05), (0, 0, 0.08), (0.02, 0, 0.05)]  # cm
P, T0 = 0.1, 37.0  # W, deg C


def run_mcmatlab(mcm_root: str, out: Path) -> float:
    """Run MCmatlab's engine on run_heat.m; returns the script's wall time (s)."""
    env = dict(os.environ, MCM_ROOT=mcm_root, OUT_DIR=str(out), MCMATLAB_SEED="1",
               OMP_NUM_THREADS="1")
    t = time.perf_counter()
    subprocess.run(["octave-cli", str(TOOL / "scripts" / "run_heat.m")], cwd=TOOL, env=env,
                   check=True, capture_output=True)
    return time.perf_counter() - t


def load_mcmatlab(mat: Path) -> dict:
    from scipy.io import loadmat

    d = loadmat(mat, squeeze_me=True)
    temps = np.asarray(d["sensorTemps"], float)  # (n_sensors, n_times)
    n_on = int(d["nSteps_on"])
    return {"NA": np.asarray(d["NA"], float), "wall_s": float(d["heat_wall_s"]),
            "steps": int(d["nSteps_on"]) + int(d["nSteps_off"]),
            "rise_1s": temps[:, n_on] - T0, "rise_15s": temps[:, -1] - T0}


def ours(NA, refine: int = 1, **hs) -> dict:
    from mcmatlab_py import Medium, Model

    m = Model()
    G = m.G
    G.nx, G.ny, G.nz, G.Lx, G.Ly, G.Lz = 61, 61, 60, 0.1, 0.1, 0.15
    G.media = [Medium("water", mua=1e-8, mus=1e-8, g=1.0, VHC=4.19, TC=5.8e-3),
               Medium("standard tissue", mua=1.0, mus=100.0, g=0.9, VHC=3391 * 1.109e-3,
                      TC=0.37e-2)]
    G.geom_func = lambda X, Y, Z: np.where(Z > 0.03, 1, 0)
    m.MC.NA = NA
    HS = m.HS
    HS.P, HS.duration_on, HS.duration_off, HS.T_initial, HS.progress = P, 1.0, 0.0, T0, False
    HS.temp_sensor_positions = SENSORS
    if refine > 1:
        HS.mesh_divisions = (61 * refine, 61 * refine, 60 * refine)
    for k, v in hs.items():
        setattr(HS, k, v)
    t = time.perf_counter()
    m.simulate_heat_distribution()
    rise_1s = HS.sensor_temps[-1] - T0
    steps = sum(HS.steps_taken)
    HS.duration_on, HS.duration_off = 0.0, 0.5
    m.simulate_heat_distribution()
    wall = time.perf_counter() - t
    return {"wall_s": wall, "steps": steps + sum(HS.steps_taken), "rise_1s": rise_1s,
            "rise_15s": HS.sensor_temps[-1] - T0}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mcm-root", help="MCmatlab built for Octave (build.sh's mcm folder)")
    p.add_argument("--mat", help="heat.mat of an earlier run_heat.m run, instead of running it")
    p.add_argument("--refine", type=int, default=2, help="the reference mesh's refinement")
    p.add_argument("--json", help="write the table here")
    a = p.parse_args(argv)
    if (a.mcm_root is None) == (a.mat is None):
        p.error("give --mcm-root (run MCmatlab's engine) or --mat (an earlier run's heat.mat)")
    if a.mcm_root is not None:
        out = Path(tempfile.mkdtemp(prefix="heat_vs_mcmatlab."))
        run_mcmatlab(a.mcm_root, out)
        mat = out / "heat.mat"
    else:
        mat = Path(a.mat)
    mcm = load_mcmatlab(mat)
    rows = {"MCmatlab": mcm}
    rows["ours, accuracy"] = ours(mcm["NA"])
    rows["ours, stability"] = ours(mcm["NA"], step_control="stability")
    ref = ours(mcm["NA"], refine=a.refine, rtol=1e-5)
    print(f"reference: {a.refine}x finer mesh, rtol 1e-5: {ref['wall_s']:.0f} s, rises at 1 s "
          f"{np.round(ref['rise_1s'], 4)}, at 1.5 s {np.round(ref['rise_15s'], 4)} K")
    print(f"{'engine':18s} {'wall s':>7s} {'steps':>6s}  rise error at 1 s (4 sensors, % of "
          f"the reference's)   at 1.5 s")
    table = []
    for name, r in rows.items():
        e1 = 100 * (r["rise_1s"] - ref["rise_1s"]) / ref["rise_1s"]
        e2 = 100 * (r["rise_15s"] - ref["rise_15s"]) / ref["rise_15s"]
        print(f"{name:18s} {r['wall_s']:7.1f} {r['steps']:6d}  {np.round(e1, 2)}  "
              f"{np.round(e2, 2)}")
        table.append({"engine": name, "wall_s": r["wall_s"], "steps": r["steps"],
                      "rise_1s": r["rise_1s"].tolist(), "rise_15s": r["rise_15s"].tolist(),
                      "error_1s_percent": e1.tolist(), "error_15s_percent": e2.tolist()})
    speed = rows["MCmatlab"]["wall_s"] / rows["ours, accuracy"]["wall_s"]
    print(f"ours (accuracy) against MCmatlab's engine: {speed:.2f}x")
    if a.json:
        Path(a.json).write_text(json.dumps({"reference": {k: np.asarray(v).tolist() for k, v
                                                          in ref.items()}, "rows": table},
                                           indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
