"""The whole thermal image against one surface point, on the paper's scenarios.

The fine-grid truth is run once more with a camera (``enkf.paper.CAMERA``: 16 x 16
pixels of 250 um over the beam, each the mean of 4 x 4 probes of the fine surface
field). The same filter (N = 50, ETKF, the paper's priors and walks) then assimilates
either the paper's single sensor at (0, 0, 0) or the whole image (256 pixels, noise
variance 0.01 each, independent), on the same seeds. Reported over the seeds: the
error and spread of mua and mus at t = 15 s, and the RMSE, spread and coverage of the
temperatures 1 and 2 mm below the sensor that nothing observes. Writes
validation/reports/image_vs_point.md.

    python validation/image_vs_point.py [--seeds 0 1 2 3 4] [--scenarios constant time-varying]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from enkf.paper import (
    CAMERA,
    TruthConfig,
    camera_image,
    emulator_for,
    filter_setup,
    generate_truth,
    noisy_sensor,
)
from enkf.tissue import TRACKED_DEPTHS, identify


def noisy_images(images: np.ndarray, seed: int, variance: float = 0.01) -> np.ndarray:
    """Frames for t > 0 plus independent N(0, variance) per pixel."""
    rng = np.random.default_rng([seed, 20230102])
    return images[1:] + np.sqrt(variance) * rng.standard_normal(images[1:].shape)


def metrics(est, truth) -> dict:
    out = {}
    for i, name in enumerate(est.names):
        t = truth.params[name][-1]
        out[f"{name} error"] = abs(est.param_mean[-1, i] - t) / t
        out[f"{name} spread"] = est.param_std[-1, i] / t
    for j, z in enumerate(TRACKED_DEPTHS[1:], start=1):
        err = est.tracked_mean[:, j] - truth.temps[: len(est.times), j]
        sd = est.tracked_std[:, j]
        out[f"T(z={z}) rmse"] = float(np.sqrt(np.mean(err[1:] ** 2)))
        out[f"T(z={z}) spread"] = float(np.mean(sd[1:]))
        out[f"T(z={z}) coverage"] = float(np.mean(np.abs(err[1:]) <= 2 * sd[1:]))
    out["median step ms"] = 1e3 * float(np.median(est.step_latency_s))
    out["stopped"] = est.diverged is not None
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--scenarios", nargs="+", default=["constant", "time-varying"])
    ap.add_argument("--model-error", choices=["white", "structured"], default="white",
                    help="the filters' model error (white: the paper's C; structured: issue #18)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "reports" / "image_vs_point.md"))
    args = ap.parse_args(argv)
    me = {"model_error": args.model_error}
    emu = emulator_for(progress=False)
    camera = camera_image(CAMERA)
    lines = ["# The whole thermal image against one surface point", "",
             f"Command: `python validation/image_vs_point.py --seeds "
             f"{' '.join(map(str, args.seeds))} --scenarios {' '.join(args.scenarios)} "
             f"--model-error {args.model_error}`", "",
             f"Camera: {camera.shape[0]} x {camera.shape[1]} pixels over x, y in "
             f"[{CAMERA[0]}, {CAMERA[1]}] cm (fine-grid truth averaged over each footprint), "
             "noise variance 0.01 per pixel. Filter: N = 50, ETKF, the paper's priors and "
             f"walks, model error {args.model_error!r}, on the 20 x 20 x 10 model. Mean over "
             "the seeds; errors and spreads of the parameters relative to the truth at t = 15 s.",
             ""]
    for sc in args.scenarios:
        truth = generate_truth(TruthConfig(scenario=sc, camera=CAMERA))
        rows = {"point": [], "image": []}
        for seed in args.seeds:
            point = filter_setup(sc, emu, seed=seed, **me)
            est = identify(point, truth.times[1:], noisy_sensor(truth, seed)[:, None])
            rows["point"].append(metrics(est, truth))
            image = filter_setup(sc, emu, seed=seed, sensor_positions=np.zeros((0, 3)),
                                 image=camera, **me)
            est = identify(image, truth.times[1:], noisy_images(truth.images, seed))
            rows["image"].append(metrics(est, truth))
            print(sc, seed, {k: {m: round(float(v), 4) for m, v in r[-1].items()}
                             for k, r in rows.items()}, flush=True)
        keys = list(rows["point"][0])
        lines += [f"## {sc}", "", "| quantity | one point | whole image | image / point |",
                  "|---|---|---|---|"]
        for k in keys:
            a = np.mean([r[k] for r in rows["point"]])
            b = np.mean([r[k] for r in rows["image"]])
            ratio = f"{b / a:.2f}" if a else "-"
            pct = "error" in k or "spread" in k and "T(" not in k
            fmt = (lambda v: f"{100 * v:.1f}%") if pct else (lambda v: f"{v:.3g}")
            lines.append(f"| {k} | {fmt(a)} | {fmt(b)} | {ratio} |")
        lines.append("")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"report written to {args.out}")


if __name__ == "__main__":
    main()
