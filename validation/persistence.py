"""Does the filter know when its model misses the truth's physics?

The whole-image filter's bands below the surface fail against independent model B (a
finite-volume cylinder for the box, docs/beyond.md) and hold against model A and the
fine grid. This script asks whether the filter's own innovations tell the two apart,
online and without the truth: the lag-1 correlation of the normalized innovations from
reading to reading while the laser is off (``TissueEstimates.innovation_persistence``;
white when the model is right), against the coverage of the +-2 sd bands, for the camera
and for one point sensor, constant and drifting optics, the three truths of
``image_vs_point.py``, the filter with the structured model error.

    python validation/persistence.py --seeds $(seq -s ' ' 0 19)
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from enkf.adaptive import PERSISTENCE_THRESHOLD, persistence_flagged
from enkf.paper import CAMERA, camera_image, emulator_for, filter_setup, noisy_sensor
from enkf.tissue import TRACKED_DEPTHS, identify

sys.path.insert(0, str(Path(__file__).parent))
from image_vs_point import camera_truth, metrics, noisy_images  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "validation" / "reports" / "persistence.md"
TRUTHS = {"fine": "the paper's fine grid (our Monte Carlo and FEM on 100 x 100 x 50)",
          "A": "model A (analog Monte Carlo, finite-difference box)",
          "B": "model B (attenuation Monte Carlo, finite-volume cylinder)",
          "C": "model C (B's attenuation Monte Carlo, spectral solution on the box)"}
#: the truths of the report's default run (C, model B's light on the box: --truths C)
DEFAULT_TRUTHS = ["fine", "A", "B"]


def run_one(kind: str, truth, scenario: str, emu, camera, seed: int) -> dict:
    """One filter run's persistence (laser off, on), its flag, and its coverage metrics."""
    # rtps 0, the report's setting, where the paper's drifting scenario relaxes its spread
    # by 0.1 (validation/rtps.py): the innovations' persistence without it
    if kind == "image":
        setup = filter_setup(scenario, emu, seed=seed, sensor_positions=np.zeros((0, 3)),
                             image=camera, model_error="structured", rtps=0.0)
        data = noisy_images(truth.images, seed)
    else:
        setup = filter_setup(scenario, emu, seed=seed, model_error="structured", rtps=0.0)
        data = noisy_sensor(truth, seed)[:, None]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        est = identify(setup, truth.times[1:], data)
    r_off, n_off = est.innovation_persistence("off")
    r_on, _ = est.innovation_persistence("on")
    out = metrics(est, truth)
    out.update({"lag1 off": r_off, "lag1 on": r_on, "pairs off": n_off,
                "flagged": float(persistence_flagged(r_off, n_off)),
                "warned": float(any("persist" in str(w.message) for w in caught))})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--truths", nargs="+", default=DEFAULT_TRUTHS, choices=list(TRUTHS))
    ap.add_argument("--scenarios", nargs="+", default=["constant", "time-varying"])
    ap.add_argument("--kinds", nargs="+", default=["image", "point"], choices=["image", "point"])
    ap.add_argument("--out", default=str(DEFAULT_OUT))
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    emu = emulator_for(progress=False)
    camera = camera_image(CAMERA)
    rows = []
    for tn in args.truths:
        for sc in args.scenarios:
            truth = camera_truth(tn, sc, camera, CAMERA)
            for kind in args.kinds:
                runs = [run_one(kind, truth, sc, emu, camera, s) for s in args.seeds]
                rows.append((tn, sc, kind, runs))
                lag = [r["lag1 off"] for r in runs]
                print(tn, sc, kind, f"lag1 off {min(lag):.2f}..{max(lag):.2f}",
                      f"flagged {sum(r['flagged'] for r in runs):.0f}/{len(runs)}", flush=True)
    write_report(Path(args.out), args, rows, time.perf_counter() - t0)
    plot(Path(args.out).with_suffix(".png"), rows)
    print(f"report written to {args.out}")


def _command(args) -> str:
    out = Path(args.out).resolve()
    parts = ["python validation/persistence.py", "--seeds", *map(str, args.seeds)]
    if list(args.truths) != DEFAULT_TRUTHS:
        parts += ["--truths", *args.truths]
    if list(args.scenarios) != ["constant", "time-varying"]:
        parts += ["--scenarios", *args.scenarios]
    if list(args.kinds) != ["image", "point"]:
        parts += ["--kinds", *args.kinds]
    if out != DEFAULT_OUT:
        parts += ["--out", str(out.relative_to(ROOT) if out.is_relative_to(ROOT) else out)]
    return " ".join(parts)


def write_report(path: Path, args, rows, wall: float) -> None:
    n = len(args.seeds)
    lines = [
        "# Does the filter know when its model misses the truth's physics?", "",
        f"Command: `{_command(args)}` ({wall / 60:.1f} min)", "",
        "Filter: the paper's (N = 50, ETKF, the paper's priors and walks), with the "
        "structured model error, on the 20 x 20 x 10 model; the camera: 16 x 16 pixels over "
        "x, y in [-0.2, 0.2] cm with its 4% model error; the point sensor at (0, 0, 0). "
        "Truths: " + "; ".join(f"{k}: {v}" for k, v in TRUTHS.items() if k in args.truths)
        + f". {n} seeds each. 'lag-1 (off)': the lag-1 correlation of the normalized "
        "innovations from reading to reading while the laser is off "
        "(`TissueEstimates.innovation_persistence()`), its mean and range over the seeds; "
        "'on': the same while it is on. 'flagged': runs above "
        f"{PERSISTENCE_THRESHOLD} and 3 sd of white innovations "
        "(`enkf.adaptive.persistence_flagged`; `identify` then warns and summary.json's "
        "`innovation_persistence.flagged` is true). Coverage: the share of steps whose "
        "+-2 sd band holds the truth, while heating / cooling; 'optics covered': the share of "
        "seeds whose bands hold mua, mus at 15 s.", "",
        "| truth | optics | observed | lag-1 (off) | lag-1 (on) | flagged | "
        + " | ".join(f"{z} cm" for z in TRACKED_DEPTHS) + " | optics covered |",
        "|---|---|---|---|---|---|" + "---|" * len(TRACKED_DEPTHS) + "---|"]
    for tn, sc, kind, runs in rows:
        lag = np.array([r["lag1 off"] for r in runs])
        on = np.array([r["lag1 on"] for r in runs])
        cov = " | ".join(
            f"{np.mean([r[f'T(z={z}) coverage heating'] for r in runs]):.2f} / "
            f"{np.mean([r[f'T(z={z}) coverage cooling'] for r in runs]):.2f}"
            for z in TRACKED_DEPTHS)
        lines.append(
            f"| {tn} | {sc} | {kind} | {lag.mean():.2f} ({lag.min():.2f}..{lag.max():.2f}) | "
            f"{on.mean():.2f} | {sum(r['flagged'] for r in runs):.0f} of {len(runs)} | {cov} | "
            f"{sum(r['mua covered'] for r in runs):.0f}, "
            f"{sum(r['mus covered'] for r in runs):.0f} of {len(runs)} |")
    # does the flag separate the runs whose bands fail below the surface?
    flat = [r for *_, runs in rows for r in runs]
    bad = [r["T(z=0.2) coverage"] < 0.9 or r["T(z=0.1) coverage"] < 0.9 for r in flat]
    flag = [bool(r["flagged"]) for r in flat]
    both = sum(f and b for f, b in zip(flag, bad, strict=True))
    lines += ["", f"Of {len(flat)} runs, {sum(bad)} have a band below the surface (0.1 or 0.2 "
              f"cm) that holds the truth on less than 90% of the steps; {sum(flag)} are "
              f"flagged; {both} are both. Flagged with good bands: {sum(flag) - both}; "
              f"failing without a flag: {sum(bad) - both}.",
              "", f"Figure: `{path.with_suffix('.png').name}` (each run's lag-1 while the "
              "laser is off against its coverage at 0.2 cm).", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".md.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(path)


def plot(path: Path, rows) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4), constrained_layout=True)
    marks = {"fine": "o", "A": "s", "B": "^", "C": "D"}
    colours = {("image", "constant"): "C0", ("image", "time-varying"): "C1",
               ("point", "constant"): "C2", ("point", "time-varying"): "C3"}
    for tn, sc, kind, runs in rows:
        ax.scatter([r["lag1 off"] for r in runs], [r["T(z=0.2) coverage"] for r in runs],
                   marker=marks[tn], color=colours[(kind, sc)], alpha=0.7, s=22,
                   label=f"{tn}, {kind}, {sc}")
    ax.axvline(PERSISTENCE_THRESHOLD, color="k", ls="--", lw=1, label="flag threshold")
    ax.axhline(0.9, color="0.5", ls=":", lw=1)
    ax.set(xlabel="lag-1 correlation of the innovations, laser off",
           ylabel="coverage of the +-2 sd band at 0.2 cm",
           title="persistence of the innovations, laser off, and the coverage at 0.2 cm")
    ax.legend(fontsize=7, ncol=2)
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)


if __name__ == "__main__":
    main()
