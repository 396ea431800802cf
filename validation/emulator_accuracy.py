"""Emulator accuracy at off-grid points against direct Monte Carlo with many photons.

Metric: relative L2 error of NA over the voxels that hold 99% of the absorbed
power, on the filter's 20 x 20 x 10 grid and on a finer 40 x 40 x 20 grid. The
reference's own noise is estimated from two independent reference runs and reported
beside the error (it inflates the measured error). Each table is built by the methods
asked for (``table``: direct Monte Carlo per point; ``white``: one perturbation run per
mus column, :mod:`mcmatlab_py.emulator.white`), and their errors are reported side by side. Writes
validation/reports/emulator_accuracy.md.

    python validation/emulator_accuracy.py [--ref-photons 4000000] [--grids 20 40]
        [--methods table white] [--nodal]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from enkf.paper import paper_model
from mcmatlab_py.emulator import AbsorptionEmulator, EmulatorSpec, symmetrize

# off-grid points: between table nodes, across the range the filter visits and beyond
POINTS = [(1.3, 150.0), (0.7, 60.0), (3.0, 400.0), (8.0, 1200.0), (0.15, 15.0), (15.0, 30.0),
          (2.2, 250.0), (4.0, 500.0)]


def top99(ref: np.ndarray) -> np.ndarray:
    order = np.argsort(ref)[::-1]
    cs = np.cumsum(ref[order])
    return order[: np.searchsorted(cs, 0.99 * cs[-1]) + 1]


def rel_l2(a, b, sel):
    return float(np.linalg.norm(a[sel] - b[sel]) / np.linalg.norm(b[sel]))


def build_all(spec, methods) -> tuple[dict, list[str]]:
    """The emulators of ``spec`` by each method, and a line on each build."""
    emus, lines = {}, []
    for method in methods:
        t0 = time.perf_counter()
        emus[method] = AbsorptionEmulator.build(spec, progress=True, method=method,
                                                out_of_range="clamp")
        lines.append(f"`{method}` build (or cache load) {time.perf_counter() - t0:.0f} s "
                     f"(recorded build time {emus[method].build_seconds:.0f} s).")
    return emus, lines


def table_head(methods, what) -> list[str]:
    cols = " | ".join(f"rel. L2 error ({m})" for m in methods)
    return [f"| mua [1/cm] | mus [1/cm] | {cols} | ref noise | {what} |",
            "|---" * (len(methods) + 4) + "|"]


def error_row(emus, mua, mus, ref, noise, sel, worst) -> str:
    errs = []
    for m, emu in emus.items():
        err = rel_l2(emu(mua, mus).ravel(), ref, sel)
        worst[m] = max(worst.get(m, 0.0), err)
        errs.append(f"{100 * err:.2f}%")
    print(mua, mus, " ".join(f"{m} {e}" for m, e in zip(emus, errs, strict=True)),
          f"(ref noise {100 * noise:.2f}%)", flush=True)
    return f"| {mua} | {mus} | {' | '.join(errs)} | {100 * noise:.2f}% | {sel.size} |"


def worst_line(worst) -> str:
    return "Worst: " + ", ".join(f"{m} {100 * w:.2f}%" for m, w in worst.items()) + "."


def nodal_section(args) -> list[str]:
    """The filter's emulator: loads on the coarse mesh's nodes from the fine Monte Carlo."""
    import fem

    spec = EmulatorSpec.from_model(paper_model((100, 100, 50), progress=False),
                                   n_photons=args.emulator_photons, mesh_divisions=(20, 20, 10))
    emus, build_lines = build_all(spec, args.methods)
    L = fem.voxel_load_matrix(fem.BoxGrid(*spec.mesh_divisions, spec.Lx, spec.Ly, spec.Lz).mesh(),
                              fem.BoxGrid(spec.nx, spec.ny, spec.nz, spec.Lx, spec.Ly, spec.Lz))
    lines = ["## The filter's emulator: MC on 100 x 100 x 50, P1 loads on the 20 x 20 x 10 mesh",
             "", *build_lines, "Metric over the nodes holding 99% of the load.", "",
             *table_head(args.methods, "nodes")]
    worst = {}
    for mua, mus in POINTS:
        refs = []
        for seed in (901, 902):
            na = symmetrize(spec.model(mua, mus, n_photons=args.ref_photons, seed=seed)
                            .run_monte_carlo().MC.NA, spec, voxels=True)
            refs.append(symmetrize((L @ na.ravel()).reshape(spec.field_shape), spec).ravel())
        ref = 0.5 * (refs[0] + refs[1])
        sel = top99(ref)
        noise = rel_l2(refs[0], refs[1], sel) / 2
        lines.append(error_row(emus, mua, mus, ref, noise, sel, worst))
    return lines + ["", worst_line(worst), ""]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref-photons", type=int, default=4_000_000)
    ap.add_argument("--grids", type=int, nargs="*", default=[20, 40])
    ap.add_argument("--emulator-photons", type=int, default=250_000)
    ap.add_argument("--methods", nargs="+", default=["table", "white"],
                    choices=["table", "white"])
    ap.add_argument("--nodal", action="store_true",
                    help="also check the filter's emulator: Monte Carlo on 100 x 100 x 50 voxels, "
                         "nodal loads on the 20 x 20 x 10 mesh")
    ap.add_argument("--out", default=str(Path(__file__).parent / "reports" / "emulator_accuracy.md"))
    args = ap.parse_args(argv)
    lines = ["# Emulator accuracy against direct Monte Carlo", "",
             f"Command: `python validation/emulator_accuracy.py --ref-photons {args.ref_photons} "
             f"--grids {' '.join(map(str, args.grids))} --methods {' '.join(args.methods)}"
             f"{' --nodal' if args.nodal else ''}`", "",
             "Relative L2 error of NA over the voxels holding 99% of the absorbed power. "
             "The reference is the mean of two independent runs (each with the reference photon "
             "count); `ref noise` is the metric between the two runs divided by 2, the noise "
             "of their mean: the part of the error that is the reference's own.", ""]
    for n in args.grids:
        grid = (n, n, n // 2)
        spec = EmulatorSpec.from_model(paper_model(grid, progress=False),
                                       n_photons=args.emulator_photons)
        emus, build_lines = build_all(spec, args.methods)
        lines += [f"## Grid {grid[0]} x {grid[1]} x {grid[2]}", "",
                  f"Table {spec.n_mua} x {spec.n_mus}, {spec.n_photons} photons per point at "
                  "mus = 100.", *build_lines, "", *table_head(args.methods, "voxels")]
        worst = {}
        for mua, mus in POINTS:
            refs = [symmetrize(spec.model(mua, mus, n_photons=args.ref_photons, seed=s)
                               .run_monte_carlo().MC.NA, spec).ravel() for s in (901, 902)]
            ref = 0.5 * (refs[0] + refs[1])
            sel = top99(ref)
            noise = rel_l2(refs[0], refs[1], sel) / np.sqrt(2) / np.sqrt(2)
            lines.append(error_row(emus, mua, mus, ref, noise, sel, worst))
        lines += ["", worst_line(worst), ""]
    if args.nodal:
        lines += nodal_section(args)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"report written to {args.out}")


if __name__ == "__main__":
    main()
