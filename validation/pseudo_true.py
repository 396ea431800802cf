"""What the filter's model can say about the independent truths: its best fit.

The filter's coarse model (examples/own_data.toml: emulator absorption on the 20 x 20 x 10
FEM) is fitted by least squares to the noise-free surface trace of each independent truth
(``validation/independent_models.py``): constant optics (mua, mus), or the paper's
drifting optics with the ramp's shape known (mua and mus linear in time while the laser is
on: four numbers), and, as the smoother and its restarts write the drift
(``smooth_drifting``), piecewise linear in heated time through K = 3 and 5 knots (2K
numbers; 2 knots are the ramp). The other drifts of ``independent_models.py`` (a step at
the onset of coagulation, a saturating rise, mua alone) are fitted with their shape known:
mua = a0 + (a1 - a0) s(t), mus = b0 + (b1 - b0) s(t), s the truth's own curve from 0 to 1,
four numbers (truths A and C, which run these drifts). The best fit is the "pseudo-true"
parameter an efficient estimator with this model converges to; its distance from the truth
is the model error's share of the parameters' error, which no filter setting removes. The
Cramér-Rao spread at the fit (sensor noise variance 0.01) is the noise's share. An
identical twin (the model's own trace at the true optics) checks the fit: it must return
the truth.

``--until T`` fits the readings up to T s only (a restart's window), and ``--discrepancy
D`` weighs them as the smoother does: noise plus a model discrepancy of relative sd D of
the rise, correlated over ``--discrepancy-time`` s (generalised least squares).

    python validation/pseudo_true.py [--until 7.5 --discrepancy 0.01 --out FILE]
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from pathlib import Path

import numpy as np
from scipy.linalg import cholesky, solve_triangular
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).parent))
from independent_models import MODELS, T_ON, TIMES, independent_truth, optics  # noqa: E402

from enkf.app.config import load_identify  # noqa: E402
from enkf.tissue.forward import TissueForwardModel, observation_operator  # noqa: E402

ROOT = Path(__file__).parents[1]
SIGMA = 0.1  # deg C, the sensor noise's sd


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--until", type=float, default=float(TIMES[-1]),
                    help="s, the last reading fitted (default all: 15 s)")
    ap.add_argument("--discrepancy", type=float, default=0.0,
                    help="relative sd of the model's error of the rise (0: noise only)")
    ap.add_argument("--discrepancy-time", type=float, default=2.0, help="s")
    ap.add_argument("--out", default=str(ROOT / "validation" / "reports" / "pseudo_true.md"))
    args = ap.parse_args(argv)
    if not (0 < args.until <= TIMES[-1] and args.discrepancy >= 0 and args.discrepancy_time > 0):
        raise SystemExit(f"pseudo_true.py: --until must be in (0, {TIMES[-1]:g}] s, --discrepancy "
                         f">= 0 and --discrepancy-time > 0; got {args.until!r}, "
                         f"{args.discrepancy!r}, {args.discrepancy_time!r}")
    out = Path(args.out)
    m = int(np.searchsorted(TIMES[1:], args.until + 1e-9))  # readings fitted
    cfg = load_identify(ROOT / "examples" / "own_data.toml")
    setup = cfg.setup(cfg.emulator(progress=False), seed=0)
    fm = TissueForwardModel(setup)
    P = observation_operator(setup, fm.mesh)[0]
    n = fm.mesh.p.shape[1]
    mid = 0.5 * (TIMES[:-1] + TIMES[1:])
    on = np.minimum(mid, T_ON)  # the ramps run while the laser is on

    def surface(theta_t, steps=None):  # (n_steps, 2) -> (steps,) deg C: the first steps
        steps = len(mid) if steps is None else steps
        T = np.full((1, n), float(setup.T_initial))
        y = np.empty(steps)
        for k in range(steps):
            T = fm(T, theta_t[k][None], TIMES[k], TIMES[k + 1])
            y[k] = (P @ T[0])[0]
        return y

    def weights(y):  # the readings' covariance's Cholesky factor: noise and discrepancy
        t = TIMES[1:y.size + 1]
        rise = np.abs(y - float(setup.T_initial))
        R = SIGMA ** 2 * np.eye(y.size) + args.discrepancy ** 2 * np.outer(rise, rise) * \
            np.exp(-np.abs(t[:, None] - t[None, :]) / args.discrepancy_time)
        return cholesky(R, lower=True)

    @functools.cache
    def shape(case):  # the truth's own curve of the drift, 0 at the start, 1 at the end
        a = np.array([optics(case, float(t))[0] for t in mid])
        return (a - a[0]) / (optics(case, float(TIMES[-1]))[0] - optics(case, 0.0)[0])

    def trajectory(p, case, knots=2):
        if case == "constant":
            return np.tile(np.exp(p), (len(mid), 1))
        if knots == "shape":
            a0, a1, b0, b1 = np.exp(p)
            sh = shape(case)
            return np.column_stack([a0 + (a1 - a0) * sh, b0 + (b1 - b0) * sh])
        if knots == 2:
            a0, a1, b0, b1 = np.exp(p)
            return np.column_stack([a0 + a1 * on, b0 + b1 * on])
        v = np.exp(p).reshape(knots, 2)  # the knots' values, linear between them
        tk = np.linspace(0.0, T_ON, knots)
        return np.column_stack([np.interp(on, tk, v[:, 0]), np.interp(on, tk, v[:, 1])])

    def start(case, knots):
        if case == "constant":
            return np.log([1.0, 100.0])
        if knots == "shape":
            return np.log([1.0, 2.0, 100.0, 200.0])
        if knots == 2:
            return np.log([1.0, 0.6, 100.0, 80.0])
        tk = np.linspace(0.0, T_ON, knots)
        return np.log(np.column_stack([1.0 + 0.6 * tk, 100.0 + 80.0 * tk])).ravel()

    lines = ["# The filter's model fitted to the independent truths", "",
             "Command: `python validation/pseudo_true.py" + "".join(f" {a}" for a in
                                                                 (argv or sys.argv[1:])) + "`",
             "", f"Readings fitted: up to {TIMES[m]:g} s; discrepancy {args.discrepancy:g} (the "
             "Cramér-Rao sds below are under the same covariance).", "",
             __doc__.split("\n\n")[1].replace("\n", " "), "",
             "| case | drift | truth model | best fit at 15 s: mua | mus | truth | rms residual "
             "(deg C) | Cramér-Rao sd at 15 s: mua | mus |", "|---|---|---|---|---|---|---|---|---|"]
    rows = [("constant", 1), ("time-varying", 2), ("time-varying", 3), ("time-varying", 5),
            ("step", "shape"), ("saturating", "shape"), ("mua-only", "shape")]
    for case, knots in rows:
        true_path = np.array([optics(case, float(t)) for t in mid])
        for model in ("twin", *(MODELS if knots != "shape" else ("A", "C"))):
            t0 = time.perf_counter()
            y = surface(true_path) if model == "twin" else independent_truth(model, case)[1:, 0]
            L = weights(y[:m])
            fit = least_squares(lambda p, c=case, y=y, k=knots, L=L: solve_triangular(
                L, surface(trajectory(p, c, k), m) - y[:m], lower=True), start(case, knots),
                diff_step=1e-3)
            th = trajectory(fit.x, case, knots)[-1]
            rms = float(np.sqrt(np.mean((L @ fit.fun) ** 2)))  # the residual, deg C
            # delta method: the end values' sd from the log-parameters' covariance
            cov = np.linalg.inv(fit.jac.T @ fit.jac)
            e = np.exp(fit.x)
            if case == "constant":
                g = np.diag(e)
            elif knots == "shape":  # the end values a1, b1
                g = np.array([[0, e[1], 0, 0], [0, 0, 0, e[3]]])
            elif knots == 2:
                g = np.array([[e[0], T_ON * e[1], 0, 0], [0, 0, e[2], T_ON * e[3]]])
            else:  # the last knot's values
                g = np.zeros((2, e.size))
                g[0, -2], g[1, -1] = e[-2], e[-1]
            sd = np.sqrt(np.diag(g @ cov @ g.T))
            true = optics(case, 15.0)
            drift = "constant" if case == "constant" else (
                "linear ramp" if knots == 2 else "shape known" if knots == "shape" else
                f"{knots} knots")
            lines.append(f"| {case} | {drift} | {model} | {th[0]:.3f} "
                         f"({100 * (th[0] / true[0] - 1):+.1f}%) | "
                         f"{th[1]:.1f} ({100 * (th[1] / true[1] - 1):+.1f}%) | {true[0]:g}, "
                         f"{true[1]:g} | {rms:.3f} | "
                         f"{100 * sd[0] / th[0]:.1f}% | {100 * sd[1] / th[1]:.1f}% |")
            print(lines[-1], f"{time.perf_counter() - t0:.0f} s", flush=True)
    lines += ["", "Read with `model_error_coverage.md`: where the filter's error is far above "
              "the best fit's, the filter (its random walk, not the model) is what limits it. "
              "The drifting rows differ with the form the drift is given: the same model error "
              "moves the fitted end of mus by several percent between 2, 3 and 5 knots, so no "
              "one form puts both truths' mus near 500 (the filter's restarts through 3 knots "
              "and through 2: `python validation/model_error_coverage.py --variant restarts "
              "restarts-linear`). With their shape known, the step's, the saturating rise's and "
              "mua alone's fits leave mus's end within 10% of the truth on A and C: where the "
              "drift bank misses mus by more on them (`drift_bank.md`), the forms it gives "
              "the drift (knots, a logistic), not the model, set the miss."]
    out.write_text("\n".join(lines) + "\n")
    print(f"report written to {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
