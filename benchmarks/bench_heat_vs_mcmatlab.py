"""Our heat simulation against MCmatlab's engine on two problems, with the accuracy of each.

``run_heat``: ``run_heat.m`` of ``../shared/tools/mcmatlab-octave`` (MCmatlab's Example 1
reduced to 61 x 61 x 60 voxels, 0.1 x 0.1 x 0.15 cm: water over standard tissue, layered in
z, a pencil beam of 0.1 W for 1 s, then 0.5 s without light, insulating faces, 37 deg C, four
sensors). ``ex04``: MCmatlab's Example 4 (gel, epidermis, dermis and a blood vessel along y,
not layered; five 1 ms pulses of 3 W, 4 ms apart, then 20 ms of cooling) reduced to
``--ex04-n`` cubed voxels by ``validation/mcmatlab_agreement.py``'s edit of MCmatlab's own
script (``--ex04-photons`` photons). MCmatlab's engine (its C MEX under GNU Octave) runs each
first and its absorption map is kept; ours then heats with that same map, so that only the
heat solvers differ:

* ``accuracy``: our default steps (error-controlled, ``HS.rtol``; ``HS.integrator = "auto"``
  picks explicit RKC or implicit TR-BDF2 by cost: RKC on Example 4, TR-BDF2 on run_heat);
* ``implicit``: the same with ``HS.integrator = "implicit"`` (TR-BDF2 on Example 4 too);
* ``stability``: MCmatlab's rule for the step (``HS.step_control = "stability"``);
* the reference: ours on a mesh ``--refine`` times finer in each direction with a tight
  ``rtol`` (``--ref-rtol``), the voxels' absorbed power unchanged (the solution of the same
  heat problem, converged further in space and time).

Each engine's sensor rises are compared with the reference's: run_heat at 1 s (end of the
light) and 1.5 s, Example 4 at 21 ms (end of the last pulse) and 45 ms (the end). The on-axis
sensors of run_heat do not converge in either engine (a pencil beam is a line source,
``validation/reports/mcmatlab_agreement.md``, 'Pencil-beam heat'): there the off-axis sensor
and the rises at 1.5 s are the ones that measure accuracy. One thread each
(``OMP_NUM_THREADS=1`` for Octave, ``NUMBA_NUM_THREADS=1`` and one BLAS thread here). Prints a
table and writes it as JSON with ``--json``.

    python benchmarks/bench_heat_vs_mcmatlab.py --mcm-root /tmp/mcm/mcm --store /tmp/heatref
    python benchmarks/bench_heat_vs_mcmatlab.py --mat /tmp/heatref/heat.mat \
        --ex04-npz /tmp/heatref/ex04_40.npz                      # earlier MCmatlab runs

``--mcm-root`` is the folder ``build.sh`` of ``../shared/tools/mcmatlab-octave`` makes;
``--store`` keeps MCmatlab's outputs (``heat.mat``, ``ex04_<n>.npz``) for ``--mat`` and
``--ex04-npz``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for _v in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TOOL = ROOT.parent / "shared" / "tools" / "mcmatlab-octave"
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
            "rise_a": temps[:, n_on] - T0, "rise_b": temps[:, -1] - T0}


def ours(NA, refine: int = 1, **hs) -> dict:
    """Ours on run_heat with the absorption map ``NA``; ``hs``: HS settings."""
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
    return {"wall_s": wall, "steps": steps + sum(HS.steps_taken), "rise_a": rise_1s,
            "rise_b": HS.sensor_temps[-1] - T0, "integrator": HS.integrator_used}


# ----------------------------------------------------------------------------- Example 4
EX04_TIMES = (0.021, 0.045)  #: s: the end of the last pulse, the end of the run
EX04_T0 = 37.0  #: deg C


def _agreement():
    """validation/mcmatlab_agreement.py (not a package): its edit of MCmatlab's scripts."""
    sys.path.insert(0, str(ROOT / "validation"))
    import mcmatlab_agreement

    return mcmatlab_agreement


def run_mcmatlab_ex04(mcm_root: str, n: int, photons: int, out: Path) -> Path:
    """MCmatlab's own Example 4 on n^3 voxels (its Monte Carlo, then its heat engine, one
    thread); its absorption map, sensor series and heat wall time saved to ``out``."""
    ma = _agreement()
    case = dataclasses.replace(ma.CASES["ex04"], grid=(n, n, n), photons=photons)
    with open(os.devnull, "w") as log:
        recs = ma.run_mcmatlab(case, Path(mcm_root), 0, log)
    mc = next(r for r in recs if r["kind"] == "MC")
    hs = next(r for r in recs if r["kind"] == "HS")
    np.savez_compressed(out, NA=np.asarray(mc["NA"], float),
                        sensor_times=np.asarray(hs["sensorsTimeVector"], float),
                        sensor_temps=np.asarray(hs["sensorTemps"], float),
                        heat_wall_s=float(hs["heat_wall_s"]), n=n, photons=photons)
    return out


def _rises(times, temps) -> tuple[np.ndarray, np.ndarray]:
    """(n_sensors,) K at each of EX04_TIMES; temps (n_times, n_sensors)."""
    return tuple(np.array([np.interp(t, times, temps[:, i]) for i in range(temps.shape[1])])
                 - EX04_T0 for t in EX04_TIMES)


def load_mcmatlab_ex04(npz: Path) -> dict:
    d = np.load(npz)
    times = d["sensor_times"]
    a, b = _rises(times, d["sensor_temps"].T)
    # MCmatlab records the sensors at every step
    return {"NA": d["NA"], "wall_s": float(d["heat_wall_s"]), "steps": times.size - 1,
            "rise_a": a, "rise_b": b}


def ours_ex04(NA, refine: int = 1, **hs) -> dict:
    """Ours on Example 4 (``examples/mcmatlab/ex04_blood_vessel.py``) with the map ``NA``."""
    sys.path.insert(0, str(ROOT / "examples" / "mcmatlab"))
    import ex04_blood_vessel as ex

    n = NA.shape[0]
    m = ex.build(quick=False)
    G = m.G
    G.nx = G.ny = G.nz = n
    m.MC.NA = NA
    HS = m.HS
    HS.progress = False
    if refine > 1:
        HS.mesh_divisions = (n * refine,) * 3
    for k, v in hs.items():
        setattr(HS, k, v)
    t = time.perf_counter()
    m.simulate_heat_distribution()
    wall = time.perf_counter() - t
    a, b = _rises(HS.sensor_times, HS.sensor_temps)
    return {"wall_s": wall, "steps": sum(HS.steps_taken), "rise_a": a, "rise_b": b,
            "integrator": HS.integrator_used}


def _cells(parser, text: str) -> tuple[int, int, int]:
    """``NX,NY,NZ`` as three positive integers (exit 2 naming the value otherwise)."""
    try:
        div = tuple(int(v) for v in text.split(","))
    except ValueError:
        div = ()
    if len(div) != 3 or min(div) < 1:
        parser.error(f"--ex04-mesh: NX,NY,NZ (three positive integers), got {text!r}")
    return div


def table(title: str, labels: tuple[str, str], rows: dict, ref: dict, ref_note: str) -> dict:
    """Print one problem's table; returns it for the JSON."""
    print(f"\n{title}\nreference: {ref_note}: {ref['wall_s']:.0f} s, rises at {labels[0]} "
          f"{np.round(ref['rise_a'], 4)}, at {labels[1]} {np.round(ref['rise_b'], 4)} K")
    print(f"{'engine':18s} {'wall s':>7s} {'steps':>6s}  rise error at {labels[0]} (% of the "
          f"reference's, per sensor)   at {labels[1]}")
    out = []
    for name, r in rows.items():
        e1 = 100 * (r["rise_a"] - ref["rise_a"]) / ref["rise_a"]
        e2 = 100 * (r["rise_b"] - ref["rise_b"]) / ref["rise_b"]
        print(f"{name:18s} {r['wall_s']:7.2f} {r['steps']:6d}  {np.round(e1, 2)}  "
              f"{np.round(e2, 2)}" + (f"  ({r['integrator']})" if r.get("integrator") else ""))
        out.append({"engine": name, "wall_s": r["wall_s"], "steps": r["steps"],
                    "integrator": r.get("integrator"),
                    f"rise_{labels[0]}": r["rise_a"].tolist(),
                    f"rise_{labels[1]}": r["rise_b"].tolist(),
                    f"error_{labels[0]}_percent": e1.tolist(),
                    f"error_{labels[1]}_percent": e2.tolist()})
    speed = rows["MCmatlab"]["wall_s"] / rows["ours, accuracy"]["wall_s"]
    print(f"MCmatlab's wall time / ours (accuracy): {speed:.2f}")
    return {"problem": title, "reference": {"note": ref_note, "wall_s": ref["wall_s"],
            f"rise_{labels[0]}": ref["rise_a"].tolist(),
            f"rise_{labels[1]}": ref["rise_b"].tolist()},
            "rows": out, "mcmatlab_over_ours": speed}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mcm-root", help="MCmatlab built for Octave (build.sh's mcm folder)")
    p.add_argument("--mat", help="heat.mat of an earlier run_heat.m run, instead of running it")
    p.add_argument("--ex04-npz", help="an earlier MCmatlab Example 4 run (--store's ex04_<n>.npz)")
    p.add_argument("--store", help="keep MCmatlab's outputs in this folder")
    p.add_argument("--ex04-n", type=int, default=40, help="Example 4's voxels per axis")
    p.add_argument("--ex04-photons", type=int, default=300_000)
    p.add_argument("--problems", nargs="+", default=["run_heat", "ex04"],
                   choices=["run_heat", "ex04"])
    p.add_argument("--refine", type=int, default=2, help="the reference mesh's refinement")
    p.add_argument("--ref-rtol", type=float, default=1e-5, help="the reference's HS.rtol")
    p.add_argument("--ex04-check-refine", type=int, default=0,
                   help="Example 4: also ours on a mesh this many times finer (rtol 1e-4), "
                        "a row that says how converged the reference is")
    p.add_argument("--ex04-rows", nargs="+",
                   default=["accuracy", "implicit", "rtol 1e-2", "stability", "1x"],
                   choices=["accuracy", "implicit", "rtol 1e-2", "stability", "1x",
                            "mesh 1/2", "mesh 2/3", "mesh 1/2 averaged"],
                   help="Example 4: our runs to time (1x: the reference's rtol on the 1x mesh, "
                        "how converged in time; mesh 1/2, 2/3: a heat mesh coarser than the "
                        "voxels, by that factor per axis, the lumped or the averaged mass)")
    p.add_argument("--ex04-mesh", nargs="+", default=[], metavar="NX,NY,NZ",
                   help="Example 4: also ours on a heat mesh of these cells per axis (e.g. "
                        "50,20,100: coarse along the vessel, the voxels' depth resolution)")
    p.add_argument("--json", help="write the tables here")
    a = p.parse_args(argv)
    meshes = [_cells(p, cells) for cells in a.ex04_mesh]
    need = {"run_heat": a.mat, "ex04": a.ex04_npz}
    if a.mcm_root is None and any(need[k] is None for k in a.problems):
        p.error("give --mcm-root (run MCmatlab's engine) or an earlier run of each problem "
                "(--mat, --ex04-npz)")
    store = Path(a.store or tempfile.mkdtemp(prefix="heat_vs_mcmatlab."))
    store.mkdir(parents=True, exist_ok=True)
    print(f"load before: {os.getloadavg()}")
    out = []
    if "run_heat" in a.problems:
        if a.mat is None:
            tmp = Path(tempfile.mkdtemp(prefix="heat_vs_mcmatlab."))
            run_mcmatlab(a.mcm_root, tmp)
            mat = store / "heat.mat"
            shutil.copy(tmp / "heat.mat", mat)
        else:
            mat = Path(a.mat)
        mcm = load_mcmatlab(mat)
        ours(mcm["NA"])  # numba's compiled kernels loaded before anything is timed
        rows = {"MCmatlab": mcm, "ours, accuracy": ours(mcm["NA"]),
                "ours, stability": ours(mcm["NA"], step_control="stability")}
        ref = ours(mcm["NA"], refine=a.refine, rtol=a.ref_rtol)
        out.append(table("run_heat (61 x 61 x 60, layered)", ("1s", "1.5s"), rows, ref,
                         f"{a.refine}x finer mesh, rtol {a.ref_rtol:g}"))
        print(f"load: {os.getloadavg()}", flush=True)
    if "ex04" in a.problems:
        npz = Path(a.ex04_npz) if a.ex04_npz else run_mcmatlab_ex04(
            a.mcm_root, a.ex04_n, a.ex04_photons, store / f"ex04_{a.ex04_n}.npz")
        mcm = load_mcmatlab_ex04(npz)
        n = mcm["NA"].shape[0]
        ours_ex04(mcm["NA"])  # numba's compiled kernels loaded before anything is timed
        half, two_thirds = (n // 2,) * 3, (round(2 * n / 3),) * 3
        settings = {"accuracy": {}, "implicit": {"integrator": "implicit"},
                    "rtol 1e-2": {"rtol": 1e-2}, "stability": {"step_control": "stability"},
                    f"1x, rtol {a.ref_rtol:g}": {"rtol": a.ref_rtol},
                    "mesh 1/2": {"mesh_divisions": half},
                    "mesh 2/3": {"mesh_divisions": two_thirds},
                    "mesh 1/2 averaged": {"mesh_divisions": half, "mass": "averaged"}}
        rows = {"MCmatlab": mcm}
        for name in settings:
            if name.split(",")[0] in a.ex04_rows:
                rows[f"ours, {name}" if name[0] != "1" else f"ours {name}"] = ours_ex04(
                    mcm["NA"], **settings[name])
        for div in meshes:
            rows[f"ours, mesh {'x'.join(map(str, div))}"] = ours_ex04(mcm["NA"],
                                                                     mesh_divisions=div)
        ref = ours_ex04(mcm["NA"], refine=a.refine, rtol=a.ref_rtol)
        if a.ex04_check_refine:
            rows[f"ours {a.ex04_check_refine}x, rtol 1e-4"] = ours_ex04(
                mcm["NA"], refine=a.ex04_check_refine, rtol=1e-4)
        out.append(table(f"Example 4 ({n}^3, a vessel across the layers)", ("21ms", "45ms"),
                         rows, ref, f"{a.refine}x finer mesh, rtol {a.ref_rtol:g}"))
        print(f"load: {os.getloadavg()}", flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
