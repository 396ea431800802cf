"""What can a random-walk filter know about drifting optics? A Bayesian bound.

The filter follows drifting optics with a random walk: log mua and log mus take a step of
sd ``q`` (per 0.1 s reading) while the laser is on. That walk is a prior on the whole
curve: the 51 values over the pulse (t = 0, 0.1, ..., 5 s; held after it, as in the
paper) have the precision ``J = D^T D / q^2`` (``D`` the differences) plus the prior on the
first value (log-sd 0.38, centred on the truth's start). An estimator that uses this
prior, however well it does its sums, has at best the error of the linear-Gaussian
smoother about the truth (the Bayesian Cramér-Rao bound, Van Trees 1968):

    error = (F + J)^-1 [S^T r / sigma^2 - J (x_true - x_prior)] + noise,
    noise ~ N(0, (F + J)^-1 F (F + J)^-1),   F = S^T S / sigma^2,

with ``S`` the sensitivities of the 150 surface readings (sigma^2 = 0.01) to the 102 log
values, by central differences of the filter's own coarse model at the truth
(``examples/own_data.toml``, as ``validation/model_error_coverage.py`` sets it up), and
``r`` what the truth's noise-free trace differs from that model's trace at the true
optics: zero for an identical twin, the model error for the independent truths A and B
(``validation/independent_models.py``). The ``J`` term is the walk's lag: it pulls the
curve towards a constant, and the paper's ramps (mua 1 -> 4, mus 100 -> 500 cm^-1 over the
pulse) are not constant. From the error's mean and covariance at t = 5 s (= 15 s) we
compute the chance that one seed ends with mus within 10% and has mua's RMS error over the
run within 0.3 cm^-1 (the targets for drifting optics), for several walk sizes.
Writes ``validation/reports/walk_bound.md``.

    python validation/walk_bound.py [--draws 200000]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from identifiability import PRIOR_LOG_SD  # noqa: E402
from independent_models import MODELS, T_ON, TIMES, independent_truth, optics  # noqa: E402

from enkf.app.config import load_identify  # noqa: E402
from enkf.tissue.forward import TissueForwardModel, observation_operator  # noqa: E402

ROOT = Path(__file__).parents[1]
SIGMA = 0.1  # deg C, the sensor noise's sd
#: walk sizes (log units per reading) for (mua, mus); the first is the one that
#: examples/own_data.toml documents for drifting optics
WALKS = [(0.03, 0.10), (0.03, 0.05), (0.03, 0.03), (0.02, 0.02), (0.01, 0.01),
         (0.05, 0.20), (0.01, 0.05), (0.05, 0.05)]


class Traces:
    """Surface traces (150,) of the config's coarse model for batches of optics curves
    given at the 51 knots of the pulse (linear in between, held after it)."""

    def __init__(self):
        cfg = load_identify(ROOT / "examples" / "own_data.toml")
        self.setup = cfg.setup(cfg.emulator(progress=False), seed=0)
        self.model = TissueForwardModel(self.setup)
        self.P = observation_operator(self.setup, self.model.mesh)[0]
        self.knots = np.round(np.linspace(0.0, T_ON, 51), 10)
        self.mid = np.minimum(0.5 * (TIMES[:-1] + TIMES[1:]), T_ON)

    def __call__(self, logx: np.ndarray) -> np.ndarray:
        """(M, 102) log knot values (mua's 51, then mus's) -> (150, M) deg C."""
        k = self.knots.size
        vals = np.exp(logx)
        T = np.full((len(logx), self.model.mesh.p.shape[1]), float(self.setup.T_initial))
        out = np.empty((self.mid.size, len(logx)))
        for i, tm in enumerate(self.mid):
            j = min(int(np.searchsorted(self.knots, tm)), k - 1)
            w = 0.0 if j == 0 else (tm - self.knots[j - 1]) / (self.knots[j] - self.knots[j - 1])
            lo = max(j - 1, 0)
            theta = np.column_stack([(1 - w) * vals[:, lo] + w * vals[:, j],
                                     (1 - w) * vals[:, k + lo] + w * vals[:, k + j]])
            T = self.model(T, theta, float(TIMES[i]), float(TIMES[i + 1]))
            out[i] = self.P @ T.T
        return out


def sensitivities(traces: Traces, x: np.ndarray, h: float = 0.01) -> np.ndarray:
    """(150, n) d reading / d log value, central differences in one batch."""
    n = x.size
    batch = np.vstack([x + s * h * np.eye(n)[i] for i in range(n) for s in (1.0, -1.0)])
    Y = traces(batch)
    return (Y[:, 0::2] - Y[:, 1::2]) / (2 * h)


def walk_precision(n_knots: int, q: float, prior_sd: float) -> np.ndarray:
    """(n_knots, n_knots) precision of a random walk of step sd ``q`` started from a
    Gaussian of sd ``prior_sd``."""
    D = np.diff(np.eye(n_knots), axis=0)
    J = D.T @ D / q**2
    J[0, 0] += 1.0 / prior_sd**2
    return J


def smoother_error(S: np.ndarray, r: np.ndarray, J: np.ndarray, x_true: np.ndarray,
                   prior_mean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mean, covariance) of the linear-Gaussian smoother's error about the truth, for
    sensitivities ``S`` and a model-error residual ``r`` (data minus model at the truth)."""
    F = S.T @ S / SIGMA**2
    A = np.linalg.inv(F + J)
    return A @ (S.T @ r / SIGMA**2 - J @ (x_true - prior_mean)), A @ F @ A


def chances(bias, cov, idx_mus_end, idx_mua, mua_true, draws: int, seed: int = 0):
    """P(mus(5 s) within 10%), P(RMS error of mua over the pulse <= 0.3 cm^-1), both."""
    rng = np.random.default_rng(seed)
    L = np.linalg.cholesky(cov + 1e-14 * np.eye(len(cov)))
    e = bias + rng.standard_normal((draws, len(bias))) @ L.T
    mus_ok = np.abs(np.expm1(e[:, idx_mus_end])) < 0.10
    # mua's RMSE over the run: the pulse's 50 readings and the 100 after it at the end value
    mua_err = mua_true * np.expm1(e[:, idx_mua])  # (draws, knots)
    sq = np.concatenate([mua_err[:, 1:] ** 2, np.repeat(mua_err[:, -1:] ** 2, 100, axis=1)],
                        axis=1)
    mua_ok = np.sqrt(sq.mean(axis=1)) <= 0.3
    return float(mus_ok.mean()), float(mua_ok.mean()), float((mus_ok & mua_ok).mean())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=200_000)
    ap.add_argument("--out", default=str(Path(__file__).parent / "reports" / "walk_bound.md"))
    args = ap.parse_args(argv)
    traces = Traces()
    tk = traces.knots
    k = tk.size
    truth = np.array([optics("time-varying", float(t)) for t in tk])  # (51, 2)
    x_true = np.log(np.concatenate([truth[:, 0], truth[:, 1]]))
    prior_mean = np.concatenate([np.full(k, x_true[0]), np.full(k, x_true[k])])
    S = sensitivities(traces, x_true)
    model_trace = traces(x_true[None])[:, 0]
    residuals = {"twin": np.zeros_like(model_trace)}
    for m in MODELS:
        residuals[m] = independent_truth(m, "time-varying")[1:, 0] - model_trace
    rows = []
    for q_mua, q_mus in WALKS:
        J = np.zeros((2 * k, 2 * k))
        J[:k, :k] = walk_precision(k, q_mua, PRIOR_LOG_SD)
        J[k:, k:] = walk_precision(k, q_mus, PRIOR_LOG_SD)
        for name, r in residuals.items():
            mean, cov = smoother_error(S, r, J, x_true, prior_mean)
            sd = np.sqrt(np.diag(cov))
            p = chances(mean, cov, 2 * k - 1, np.arange(k), truth[:, 0], args.draws)
            rows.append((q_mua, q_mus, name, mean[k - 1], sd[k - 1], mean[-1], sd[-1], *p))
            print(rows[-1][:3], np.round(rows[-1][3:], 3), flush=True)
    lines = ["# What a random-walk filter can know about drifting optics", "",
             f"Command: `python validation/walk_bound.py --draws {args.draws}`", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "    error = (F + J)^-1 [S^T r / sigma^2 - J (x_true - x_prior)] + noise,",
             "    noise ~ N(0, (F + J)^-1 F (F + J)^-1),   F = S^T S / sigma^2,", "",
             " ".join(__doc__.split("\n\n")[3].split()), "",
             "The smoother's error at the end of the pulse (= 15 s), log units (0.10 is about "
             "10%): the mean (the walk's lag and the model error) and the sd (the sensor "
             "noise). No estimator with this prior does better on average; 18 of 20 seeds "
             "needs a chance near 0.9 or more. The residual r is 0 for the twin; for A and B "
             "its rms is " + ", ".join(f"{m} {np.sqrt(np.mean(residuals[m] ** 2)):.3f}"
                                        for m in MODELS) + " deg C.", "",
             "| walk sd per reading (mua, mus) | truth | mua(5 s): mean, sd | mus(5 s): mean, "
             "sd | P(mus within 10%) | P(mua RMSE <= 0.3) | P(both) |",
             "|---|---|---|---|---|---|---|"]
    for q_mua, q_mus, name, b_a, s_a, b_s, s_s, p_mus, p_mua, p_both in rows:
        lines.append(f"| {q_mua:g}, {q_mus:g} | {name} | {b_a:+.3f}, {s_a:.3f} | {b_s:+.3f}, "
                     f"{s_s:.3f} | {p_mus:.2f} | {p_mua:.2f} | {p_both:.2f} |")
    lines.append("")
    for name in residuals:
        best = max((r for r in rows if r[2] == name), key=lambda r: r[-1])
        lines.append(f"- {name}: the best of these walks, ({best[0]:g}, {best[1]:g}), meets "
                     f"both targets on one seed with chance {best[-1]:.2f}.")
    worst = {w: min(r[-1] for r in rows if (r[0], r[1]) == w) for w in WALKS}
    w = max(worst, key=worst.get)
    lines += ["", f"One walk for all three truths (a user does not know which model made the "
              f"data): the best is ({w[0]:g}, {w[1]:g}), and its chance on the truth where it "
              f"does worst is {worst[w]:.2f}. Where a walk small enough to meet the target on "
              "B exists, it does so because its lag happens to cancel B's model error, and it "
              "then fails on the twin."]
    lines += ["", "The first walk is the one `examples/own_data.toml` documents. Read with "
              "`validation/reports/identifiability.md` (the ramp's shape known: mus to 0.7%), "
              "`validation/reports/pseudo_true.md` (the model's best fit to A and B) and "
              "`validation/reports/model_error_coverage.md` (the filter itself on A and B)."]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
