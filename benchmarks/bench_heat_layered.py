"""The layered direct solver against the P1 PCG path on run_heat's problem, one thread.

``run_heat.m`` of ``../shared/tools/mcmatlab-octave``: MCmatlab's Example 1 reduced to
61 x 61 x 60 voxels, 0.1 x 0.1 x 0.15 cm, water (z < 0.03 cm: VHC 4.19, TC 5.8e-3) over
standard tissue (VHC 3391 * 1.109e-3, TC 0.37e-2), a pencil beam of 0.1 W for 1 s then
0.5 s off, insulating faces, 37 deg C. The media vary only with depth, so the heat front
end could use

* ``layered``: ``HeatStepper(operator="kronecker", mass="averaged")`` with per-element VHC
  and TC: the tensor-product operator, solved directly (:class:`fem.LayeredKroneckerSolver`);

instead of what it uses today for several media,

* ``pcg``: ``HeatStepper(mass="averaged")``: P1 tetrahedra, the mean of the lumped and
  consistent mass, PCG preconditioned by the fast diagonalization of the volume-averaged
  operator.

Both take the same backward Euler steps (the stages of the front end's TR-BDF2 are such
steps) with MCmatlab's absorption map (``--mat``, a ``heat.mat`` written by run_heat.m) or,
without one, a synthetic pencil beam. Prints the time per step (right-hand side and
solve), the sensors' rises of each and their difference relative to the rise (the
difference of the two discretisations, tetrahedra against the tensor product); with
``--refine r`` each one's error against the layered solver on a mesh r times finer in each
direction (the voxels' power density unchanged, the same steps: the spatial error alone);
with ``--mcm-root`` MCmatlab's engine's wall time on this machine (run once).

    NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_heat_layered.py
    python benchmarks/bench_heat_layered.py --mat /tmp/heatref/heat.mat --dt 0.03125 --refine 2
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

for _v in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

SENSORS = [(0, 0, 0.035), (0, 0, 0.05), (0, 0, 0.08), (0.02, 0, 0.05)]  # cm
P, T0 = 0.1, 37.0  # W, deg C
WATER, TISSUE = (4.19, 5.8e-3), (3391 * 1.109e-3, 0.37e-2)  # VHC, TC


def absorption(grid, mat: str | None) -> tuple[np.ndarray, str]:
    """W/cm^3 per W: MCmatlab's NA from ``mat`` or a pencil beam in the tissue."""
    if mat and Path(mat).exists():
        from scipy.io import loadmat

        return np.asarray(loadmat(mat, squeeze_me=True)["NA"], float), f"MCmatlab's NA ({mat})"
    X, Y, Z = np.meshgrid(grid.x, grid.y, grid.z, indexing="ij")
    mua, w = 1.0, 0.003  # cm^-1, cm
    NA = np.where(Z > 0.03, mua * np.exp(-(Z - 0.03) * 20.0) / (np.pi * w**2)
                  * np.exp(-(X**2 + Y**2) / w**2), 0.0)
    return NA, "a synthetic pencil beam"


def run(stepper, f, n_on: int, n_off: int, probes) -> dict:
    T = np.full(stepper.npoints, T0)
    times = []
    rises = {}
    for i in range(n_on + n_off):
        t = time.perf_counter()
        T = stepper.step(T, f if i < n_on else None)
        times.append(time.perf_counter() - t)
        if i + 1 == n_on:
            rises["1s"] = probes @ T - T0
    rises["1.5s"] = probes @ T - T0
    return {"step_s": times, "rise": rises, "T": T}


def mcmatlab_wall(mcm_root: str) -> tuple[float, float]:
    """MCmatlab's heat engine and the whole run_heat.m on this machine, wall s."""
    import tempfile

    sys.path.insert(0, str(Path(__file__).parent))
    from bench_heat_vs_mcmatlab import load_mcmatlab, run_mcmatlab

    out = Path(tempfile.mkdtemp(prefix="heat_layered."))
    total = run_mcmatlab(mcm_root, out)
    return load_mcmatlab(out / "heat.mat")["wall_s"], total


def layered_media(grid) -> tuple[np.ndarray, np.ndarray]:
    """Per-element VHC and TC of box_mesh(grid): water above z = 0.03 cm, tissue below."""
    layer = np.where(grid.z < 0.03, 0, 1)
    out = []
    for a in range(2):
        v = np.array([WATER[a], TISSUE[a]])[layer]
        out.append(np.repeat(np.broadcast_to(v, grid.shape).ravel(), 6))
    return out[0], out[1]


def reference(NA, r: int, dt: float, n_on: int, n_off: int) -> dict:
    """The layered solver on a mesh r times finer, the voxels' power density repeated."""
    import fem

    grid = fem.BoxGrid(61 * r, 61 * r, 60 * r, 0.1, 0.1, 0.15)
    mesh = grid.mesh()
    vhc, tc = layered_media(grid)
    NA_r = np.repeat(np.repeat(np.repeat(NA, r, 0), r, 1), r, 2)
    f = P * (fem.voxel_load_matrix(mesh, grid) @ NA_r.ravel())
    st = fem.HeatStepper(mesh, vhc, tc, dt, operator="kronecker", mass="averaged")
    return run(st, f, n_on, n_off, fem.probe_matrix(mesh, np.array(SENSORS, float).T))


def main(argv=None) -> int:
    import fem

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mat", default="/tmp/heatref/heat.mat",
                   help="heat.mat of run_heat.m (its NA); a synthetic beam if absent")
    p.add_argument("--dt", type=float, default=1 / 32, help="s, the backward Euler step")
    p.add_argument("--refine", type=int, default=0,
                   help="also the reference on a mesh this many times finer (0: none)")
    p.add_argument("--mcm-root", help="also run MCmatlab's engine once (build.sh's mcm folder)")
    p.add_argument("--json", help="write the numbers here")
    a = p.parse_args(argv)

    grid = fem.BoxGrid(61, 61, 60, 0.1, 0.1, 0.15)
    mesh = grid.mesh()
    vhc, tc = layered_media(grid)
    NA, source = absorption(grid, a.mat)
    f = P * (fem.voxel_load_matrix(mesh, grid) @ NA.ravel())  # W per node
    probes = fem.probe_matrix(mesh, np.array(SENSORS, float).T)
    n_on, n_off = round(1.0 / a.dt), round(0.5 / a.dt)
    print(f"run_heat: {grid.node_shape} nodes, {source}, {n_on} + {n_off} backward Euler "
          f"steps of {a.dt:g} s, one thread; load: {os.getloadavg()[0]:.2f}")

    rows = {}
    for name, kw in (("layered", {"operator": "kronecker", "mass": "averaged"}),
                     ("pcg", {"mass": "averaged"})):
        t = time.perf_counter()
        st = fem.HeatStepper(mesh, vhc, tc, a.dt, **kw)
        setup = time.perf_counter() - t
        st.step(np.full(st.npoints, T0), f)  # numba compiled, caches warm
        r = run(st, f, n_on, n_off, probes)
        r["setup_s"], r["method"] = setup, st.method
        rows[name] = r
        s = np.array(r["step_s"])
        print(f"{name:8s} method={st.method:5s} setup {setup:5.2f} s, per step median "
              f"{1e3 * np.median(s):7.1f} ms (min {1e3 * s.min():.1f}), total {s.sum():6.2f} s; "
              f"rises at 1 s {np.round(r['rise']['1s'], 4)} K, at 1.5 s "
              f"{np.round(r['rise']['1.5s'], 4)} K")
    lay, pcg = rows["layered"], rows["pcg"]
    ratio = np.median(pcg["step_s"]) / np.median(lay["step_s"])
    print(f"per step: layered {ratio:.1f}x faster than pcg")
    diff = {}
    for t in ("1s", "1.5s"):
        diff[t] = 100 * (lay["rise"][t] - pcg["rise"][t]) / pcg["rise"][t]
        print(f"layered - pcg at {t:4s}, % of the rise, sensors {SENSORS}: "
              f"{np.round(diff[t], 3)}")
    dT = np.abs(lay["T"] - pcg["T"]).max()
    print(f"max |T_layered - T_pcg| at 1.5 s over the mesh: {dT:.4f} K")
    out = {"load": os.getloadavg()[0], "dt": a.dt, "source": source,
           "diff_percent": {t: v.tolist() for t, v in diff.items()}, "speedup": ratio}
    for name, r in rows.items():
        out[name] = {"median_step_s": float(np.median(r["step_s"])),
                     "total_s": float(np.sum(r["step_s"])), "setup_s": r["setup_s"],
                     "rise": {t: v.tolist() for t, v in r["rise"].items()}}
    if a.refine > 1:
        t = time.perf_counter()
        ref = reference(NA, a.refine, a.dt, n_on, n_off)
        print(f"reference: layered on a {a.refine}x finer mesh, {time.perf_counter() - t:.0f} s "
              f"({1e3 * np.median(ref['step_s']):.0f} ms per step); rises at 1 s "
              f"{np.round(ref['rise']['1s'], 4)} K, at 1.5 s {np.round(ref['rise']['1.5s'], 4)} K")
        out["reference_rise"] = {t: v.tolist() for t, v in ref["rise"].items()}
        for name, r in rows.items():
            err = {t: 100 * (r["rise"][t] - ref["rise"][t]) / ref["rise"][t] for t in ref["rise"]}
            print(f"{name:8s} error against the reference, % of its rise: at 1 s "
                  f"{np.round(err['1s'], 3)}, at 1.5 s {np.round(err['1.5s'], 3)}")
            out[name]["error_percent"] = {t: v.tolist() for t, v in err.items()}
    if a.mcm_root:
        heat_s, script_s = mcmatlab_wall(a.mcm_root)
        print(f"MCmatlab's engine: heat {heat_s:.1f} s (run_heat.m {script_s:.1f} s, with its "
              f"Monte Carlo); load now {os.getloadavg()[0]:.2f}")
        out["mcmatlab_heat_s"] = heat_s
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
