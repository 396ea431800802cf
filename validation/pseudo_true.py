"""What the filter's model can say about the independent truths: its best fit (issue #18).

The filter's coarse model (examples/own_data.toml: emulator absorption on the 20 x 20 x
10 FEM) is fitted by least squares to the noise-free surface trace of each independent
truth (``validation/independent_models.py``): constant optics (mua, mus), or the paper's
drifting optics with the ramp's shape known (mua and mus linear in time while the laser is
on: four numbers). The best fit is the "pseudo-true" parameter an efficient estimator with
this model converges to; its distance from the truth is the model error's share of the
parameters' error, which no filter setting removes. The Cramér-Rao spread at the fit
(sensor noise variance 0.01) is the noise's share.

    python validation/pseudo_true.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).parent))
from independent_models import MODELS, T_ON, TIMES, independent_truth, optics  # noqa: E402

from enkf.app.config import load_identify  # noqa: E402
from enkf.tissue.forward import TissueForwardModel, observation_operator  # noqa: E402

ROOT = Path(__file__).parents[1]
SIGMA = 0.1  # deg C, the sensor noise's sd


def main(argv=None) -> None:
    out = Path(argv[0]) if argv else ROOT / "validation" / "reports" / "pseudo_true.md"
    cfg = load_identify(ROOT / "examples" / "own_data.toml")
    setup = cfg.setup(cfg.emulator(progress=False), seed=0)
    fm = TissueForwardModel(setup)
    P = observation_operator(setup, fm.mesh)[0]
    n = fm.mesh.p.shape[1]
    mid = 0.5 * (TIMES[:-1] + TIMES[1:])
    on = np.minimum(mid, T_ON)  # the ramps run while the laser is on

    def surface(theta_t):  # (n_steps, 2) -> (n_steps,) deg C
        T = np.full((1, n), float(setup.T_initial))
        y = np.empty(len(mid))
        for k in range(len(mid)):
            T = fm(T, theta_t[k][None], TIMES[k], TIMES[k + 1])
            y[k] = (P @ T[0])[0]
        return y

    def trajectory(p, case):
        if case == "constant":
            return np.tile(np.exp(p), (len(mid), 1))
        a0, a1, b0, b1 = np.exp(p)
        return np.column_stack([a0 + a1 * on, b0 + b1 * on])

    lines = ["# The filter's model fitted to the independent truths (issue #18)", "",
             "Command: `python validation/pseudo_true.py`", "",
             __doc__.split("\n\n")[1].replace("\n", " "), "",
             "| case | truth model | best fit at 15 s: mua | mus | truth | rms residual (deg C) | "
             "Cramér-Rao sd at 15 s: mua | mus |", "|---|---|---|---|---|---|---|---|"]
    for case in ("constant", "time-varying"):
        for model in MODELS:
            t0 = time.perf_counter()
            y = independent_truth(model, case)[1:, 0]
            p0 = np.log([1.0, 100.0] if case == "constant" else [1.0, 0.6, 100.0, 80.0])
            fit = least_squares(lambda p, c=case, y=y: (surface(trajectory(p, c)) - y) / SIGMA, p0,
                                diff_step=1e-3)
            th = trajectory(fit.x, case)[-1]
            # delta method: the end values' sd from the log-parameters' covariance
            cov = np.linalg.inv(fit.jac.T @ fit.jac)
            e = np.exp(fit.x)
            if case == "constant":
                g = np.diag(e)
            else:
                g = np.array([[e[0], T_ON * e[1], 0, 0], [0, 0, e[2], T_ON * e[3]]])
            sd = np.sqrt(np.diag(g @ cov @ g.T))
            true = optics(case, 15.0)
            lines.append(f"| {case} | {model} | {th[0]:.3f} ({100 * (th[0] / true[0] - 1):+.1f}%) | "
                         f"{th[1]:.1f} ({100 * (th[1] / true[1] - 1):+.1f}%) | {true[0]:g}, "
                         f"{true[1]:g} | {SIGMA * np.sqrt(np.mean(fit.fun ** 2)):.3f} | "
                         f"{100 * sd[0] / th[0]:.1f}% | {100 * sd[1] / th[1]:.1f}% |")
            print(lines[-1], f"{time.perf_counter() - t0:.0f} s", flush=True)
    lines += ["", "Read with `model_error_coverage.md`: where the filter's error is far above "
              "the best fit's, the filter (its random walk, not the model) is what limits it."]
    out.write_text("\n".join(lines) + "\n")
    print(f"report written to {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
