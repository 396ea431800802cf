"""A camera tilted and off-centre by a few pixels: registered, it does not bias the optics.

The truth is independent model A of ``independent_models.py`` (analog Monte Carlo and a
finite-difference box, constant optics mua 1, mus 100 cm^-1), seen by a 24 x 24 camera of
150 um pixels (each the mean of 4 x 4 probes of the truth's surface, noise variance
0.01 deg C^2), written as a TIFF stack (ImageJ's frame interval 0.1 s) and read back
through ``IdentifyConfig.read_data`` as ``tissue-enkf identify`` reads it. The filter is
``examples/own_data.toml``'s with the camera instead of the point sensor. Runs:

- ``centred``: the camera centred on the beam, its rows along x, the spot's centre given;
- ``shifted, registered``: the camera moved by 3 pixels along its rows and columns and
  turned by 2 degrees, ``spot_center = "auto"`` (estimated from the first frames) and
  ``rotation = 2``;
- ``shifted, rotation ignored``: the same frames, the centre estimated, the rotation
  left at 0;
- ``shifted, not registered``: the same frames taken as centred (the control: what the
  registration prevents).

For each seed (the camera's noise and the filter's draws) the optics at 15 s and whether
the registered runs' estimates lie within the centred run's +-2 sd bands. Writes
``validation/reports/camera_registration.md``.

    python validation/camera_registration.py [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from independent_models import TIMES, independent_surface  # noqa: E402

from enkf.app.config import identify_config_from_dict  # noqa: E402
from enkf.tissue import identify  # noqa: E402
from enkf.tissue.image import ThermalImage  # noqa: E402
from mcmatlab_py.config import read_toml  # noqa: E402

ROOT = Path(__file__).parents[1]
SHAPE, PIXEL = (24, 24), 0.015  # pixels, cm
CENTRE = ((SHAPE[1] - 1) / 2, (SHAPE[0] - 1) / 2)  # the image's centre, (column, row)
SHIFT, TURN = 3.0, 2.0  # pixels, degrees


def camera_config(spot_center, rotation: float = 0.0):
    raw = read_toml(ROOT / "examples" / "own_data.toml")
    raw = copy.deepcopy(raw)
    raw["sensors"]["positions"] = []
    raw.pop("data", None)  # the CSV's columns
    # the drift bank's restarts from the smoother: no discrepancy (its dense covariance over
    # every pixel and reading would not fit), as for a camera's smoother
    raw["filter"].setdefault("drift", {})["restart_discrepancy"] = 0.0
    raw["sensors"]["camera"] = {"shape": list(SHAPE), "pixel_size": PIXEL,
                                "spot_center": spot_center, "rotation": rotation,
                                "noise_var": 0.01}
    return identify_config_from_dict(raw)


def frames_of(camera: ThermalImage, seed: int) -> np.ndarray:
    """(151, ny, nx) deg C: the truth's surface averaged over each pixel, with noise."""
    surf = independent_surface("A", "constant", camera.sample_points()[:, :2])
    clean = camera.average(surf)
    rng = np.random.default_rng([seed, 52])
    return (clean + 0.1 * rng.standard_normal(clean.shape)).reshape(len(TIMES), *SHAPE)


def write_tiff(path: Path, frames: np.ndarray) -> None:
    import tifffile

    tifffile.imwrite(path, frames.astype("f4"), imagej=True,
                     metadata={"finterval": float(TIMES[1] - TIMES[0]), "axes": "TYX"})


def run(cfg, emulator, path: Path, seed: int) -> dict:
    times, data = cfg.read_data(path)
    setup = cfg.setup(emulator, seed=seed)
    tic = time.perf_counter()
    est = identify(setup, times, data, param_bounds=cfg.param_bounds)
    reg = cfg.camera_registration
    return {"mean": est.param_mean[-1], "std": est.param_std[-1],
            "centre": None if reg is None else reg.spot_center,
            "stopped": est.diverged, "wall": time.perf_counter() - tic}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--work", default="/tmp/camera_registration")
    ap.add_argument("--out", default=str(ROOT / "validation" / "reports" /
                                         "camera_registration.md"))
    args = ap.parse_args(argv)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    true_centre = (CENTRE[0] + SHIFT, CENTRE[1] + SHIFT)
    truth_cams = {"centred": ThermalImage.registered(SHAPE, PIXEL, CENTRE, subsamples=4),
                  "shifted": ThermalImage.registered(SHAPE, PIXEL, true_centre, rotation=TURN,
                                                     subsamples=4)}
    variants = [("centred", "centred", lambda: camera_config(list(CENTRE))),
                ("shifted, registered", "shifted", lambda: camera_config("auto", TURN)),
                ("shifted, rotation ignored", "shifted", lambda: camera_config("auto", 0.0)),
                ("shifted, not registered", "shifted", lambda: camera_config(list(CENTRE)))]
    emulator = camera_config(list(CENTRE)).emulator(progress=False)
    results = {}
    for seed in args.seeds:
        for cam_name, cam in truth_cams.items():
            write_tiff(work / f"{cam_name}-{seed}.tif", frames_of(cam, seed))
        for name, cam_name, make in variants:
            r = run(make(), emulator, work / f"{cam_name}-{seed}.tif", seed)
            results[name, seed] = r
            print(name, seed, np.round(r["mean"], 4), np.round(r["std"], 4), r["centre"],
                  f"{r['wall']:.0f} s", flush=True)
    lines = ["# Camera registration: a tilted, off-centre camera and the optics", "",
             f"Command: `python validation/camera_registration.py --seeds "
             f"{' '.join(map(str, args.seeds))}`", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             *[f"- {' '.join(item.split())}" for item in
               __doc__.split("\n\n")[2].split("- ")[1:]], "",
             " ".join(__doc__.split("\n\n")[3].split()), "",
             f"The shifted camera sees the spot's centre at column {true_centre[0]:g}, row "
             f"{true_centre[1]:g} (the image's centre is {CENTRE[0]:g}, {CENTRE[1]:g}), turned by "
             f"{TURN:g} degrees.", "",
             "| run | seed | mua (cm^-1) | mus (cm^-1) | spot's centre found (column, row) | "
             "within the centred run's +-2 sd bands |", "|---|---|---|---|---|---|"]
    inside = {}
    for seed in args.seeds:
        ref = results["centred", seed]
        for name, _, _ in variants:
            r = results[name, seed]
            ok = np.abs(r["mean"] - ref["mean"]) <= 2 * ref["std"]
            inside.setdefault(name, []).append(bool(ok.all()))
            c = "given" if r["centre"] is None else f"{r['centre'][0]:.2f}, {r['centre'][1]:.2f}"
            lines.append(f"| {name} | {seed} | {r['mean'][0]:.4f} +- {2 * r['std'][0]:.4f} | "
                         f"{r['mean'][1]:.2f} +- {2 * r['std'][1]:.2f} | {c} | "
                         f"{'-' if name == 'centred' else ('yes' if ok.all() else 'no')} |")
    lines += ["", "Bands are +-2 sd. Over the seeds, the runs within the centred run's bands: "
              + ", ".join(f"{n} {sum(v)}/{len(v)}" for n, v in inside.items() if n != "centred")
              + ".", "",
              "Target (issue 52): the registered camera's optics within the unshifted run's bands. "
              "The camera's rows and columns are set by `sensors.camera.rotation` (and `mirror`); "
              "the spot's centre is found to a few hundredths of a pixel from the first frames "
              "that rise 20 noise sds above the first (`enkf.tissue.image.estimate_spot_center`). "
              "Taking the moved camera as centred puts the hot spot 3 pixels away from where the "
              "model heats; the control rows show what that does to the optics."]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
