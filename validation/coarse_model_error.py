"""How far the filter's coarse heat model is from the fine truth at the true parameters.

The paper's constant case: the fine-grid truth (100 x 100 x 50 voxels, 10^7 photons,
Crank-Nicolson at 0.1 s) against the same absorbed power integrated exactly onto
coarser meshes and stepped with the filter's operator (Crank-Nicolson, its default).
The error at the three tracked points is the model error the filter has to live with;
the 20 x 20 x 10 row is the filter's model. A second table: the time scheme, the fine
grid and the filter's model each stepped at the readings' 0.1 s by backward Euler or
Crank-Nicolson, against the fine grid converged in time (Crank-Nicolson at 0.0125 s).
Writes validation/reports/coarse_model_error.md.

    python validation/coarse_model_error.py [--photons 10000000]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import fem
from enkf.paper import TruthConfig, generate_truth, paper_model
from enkf.tissue.parameters import TRACKED_DEPTHS

SHAPES = [(20, 20, 10), (40, 40, 10), (20, 20, 20), (40, 40, 20), (50, 50, 25)]
TIMES = (1.0, 3.0, 5.0, 6.0, 7.0, 10.0)


def coarse_run(NA: np.ndarray, fine: fem.BoxGrid, shape, times: np.ndarray, power: float = 0.5,
               t_off: float = 5.0, mass: str = "lumped", theta: float = 0.5) -> np.ndarray:
    """Temperatures (len(times), 3) at the tracked points on a coarse mesh of ``shape``,
    one step of the ``theta`` scheme per interval of ``times``."""
    grid = fem.BoxGrid(*shape, fine.Lx, fine.Ly, fine.Lz)
    mesh = grid.mesh()
    load = power * (fem.voxel_load_matrix(mesh, fine) @ NA.ravel())
    stepper = fem.HeatStepper(mesh, 3.76, 0.0037, float(times[1] - times[0]), operator="kronecker",
                              mass=mass, theta=theta)
    probes = fem.probe_matrix(mesh, np.array([[0.0, 0.0, z] for z in TRACKED_DEPTHS]).T)
    T = np.zeros(mesh.p.shape[1])
    out = [probes @ T]
    for t0, t1 in zip(times[:-1], times[1:], strict=True):
        T = stepper.step(T, load if 0.5 * (t0 + t1) < t_off else None)
        out.append(probes @ T)
    return np.array(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=int, default=10**7)
    ap.add_argument("--out", default=str(Path(__file__).parent / "reports" / "coarse_model_error.md"))
    args = ap.parse_args(argv)
    truth = generate_truth(TruthConfig(scenario="constant"))
    model = paper_model((100, 100, 50), args.photons, 1)
    model.run_monte_carlo()  # seed 1, as the truth's map
    fine = fem.BoxGrid(100, 100, 50, 0.5, 0.5, 0.25)
    idx = [int(np.argmin(np.abs(truth.times - t))) for t in TIMES]
    head = " | ".join(f"t = {t:g} s" for t in TIMES)
    lines = ["# Model error of the coarse heat model at the true parameters", "",
             f"Command: `python validation/coarse_model_error.py --photons {args.photons}`", "",
             "Constant case (mua 1, mus 100 cm^-1). Relative error (%) of the coarse model "
             "against the fine-grid truth at z = 0, 0.1, 0.2 cm below the beam centre; the "
             "absorbed power of the truth is integrated exactly onto each coarse mesh, so "
             "the emulator plays no part. 20 x 20 x 10 is the filter's model.", "",
             f"| coarse voxels | mass | {head} |", "|---|---|" + "---|" * len(TIMES)]
    for shape in SHAPES:
        for mass in ("lumped", "averaged"):
            T = coarse_run(model.MC.NA, fine, shape, truth.times, mass=mass)
            rel = 100 * (T[idx] - truth.temps[idx]) / truth.temps[idx]
            cells = " | ".join(", ".join(f"{v:+.2f}" for v in row) for row in rel)
            lines.append(f"| {' x '.join(map(str, shape))} | {mass} | {cells} |")
            print(shape, mass, cells, flush=True)
    lines += ["", "Reading: with the lumped mass the surface of the filter's model runs about 1% "
              "cold while the laser is on; refining laterally (40 x 40) helps as much as "
              "refining in depth, and the error falls roughly as h^2. One sensor reading "
              "carries 0.1 deg C of noise on 10-60 deg C (0.2-1%), so over 50 readings this "
              "bias is well resolved by the data, and the filter moves the weakly identified "
              "mus to absorb it. The averaged mass (fem.fastdiag.one_d_mass) cancels the "
              "leading error term on the same mesh: the 20 x 20 x 10 model is then closer to "
              "the truth than the lumped 50 x 50 x 25 one, and it is the filter's default "
              "(TissueFilterSetup.heat_mass).", ""]
    lines += time_scheme(model, fine, truth.times)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"report written to {args.out}")


def fine_run(model, theta: float, dt: float, times: np.ndarray) -> np.ndarray:
    """Temperatures (len(times), 3) at the tracked points of the fine grid's heat run (its
    Monte Carlo map as it is), steps of ``dt`` s of the ``theta`` scheme."""
    model.HS.reset()
    model.HS.theta, model.HS.dt = theta, dt
    model.simulate_heat_distribution()
    t, T = model.HS.sensor_times, model.HS.sensor_temps
    return np.column_stack([np.interp(times, t, T[:, j]) for j in range(3)])


def time_scheme(model, fine: fem.BoxGrid, times: np.ndarray) -> list[str]:
    """Section 2: backward Euler and Crank-Nicolson at 0.1 s on the fine grid and on the
    filter's model, against the fine grid converged in time; the largest error over the
    15 s at each tracked point, as a share of the surface's peak rise."""
    model.HS.progress = False
    ref = fine_run(model, 0.5, 0.0125, times)
    peak = float(np.max(ref[:, 0]))
    rows = [("fine, backward Euler, 0.1 s", fine_run(model, 1.0, 0.1, times)),
            ("fine, Crank-Nicolson, 0.1 s", fine_run(model, 0.5, 0.1, times)),
            ("fine, backward Euler, 0.0125 s", fine_run(model, 1.0, 0.0125, times))]
    for name, th in (("backward Euler", 1.0), ("Crank-Nicolson", 0.5)):
        rows.append((f"filter's 20 x 20 x 10 (averaged mass), {name}, 0.1 s",
                     coarse_run(model.MC.NA, fine, (20, 20, 10), times, mass="averaged",
                                theta=th)))
    fine_cn = rows[1][1]
    out = ["## The time scheme", "",
           "The largest difference over the 15 s (deg C, and as a share of the surface's peak "
           f"rise, {peak:.2f} deg C) at z = 0, 0.1, 0.2 cm from the fine grid converged in time "
           "(Crank-Nicolson at 0.0125 s; at 0.025 s it differs from it by less than 10^-4 "
           "deg C), the same Monte Carlo map; and the filter's model from the fine grid at "
           "the same scheme (the model error the filter sees in the validation runs). "
           "Backward Euler lags: the rise while heating, the fall while cooling.", "",
           "| heat model | from the converged fine grid (deg C; % of peak) | from the fine "
           "grid's Crank-Nicolson at 0.1 s |", "|---|---|---|"]
    for name, T in rows:
        d = np.abs(T - ref).max(axis=0)
        e = np.abs(T - fine_cn).max(axis=0)
        out.append(f"| {name} | {', '.join(f'{v:.4f}' for v in d)}; "
                   f"{100 * d.max() / peak:.2f}% | {', '.join(f'{v:.4f}' for v in e)} |")
        print(out[-1], flush=True)
    return out + [""]


if __name__ == "__main__":
    main()
