"""How precise must the filter's model be for the fine truth? (known epidermis)

One surface sensor determines the dermis's mua and mus under the known epidermis of
``examples/two_layer.toml`` to 0.5% and 1% (Cramér-Rao), along a ridge of correlation
-0.97: the 150 readings pin the trace's level to a few hundredths of a degree, so a model
error of that size moves an estimate along the ridge by more than the bound.

For each case the filter's model (the emulator's layered loads on the FEM) is fitted by
least squares to the noise-free surface trace of a fine truth (direct Monte Carlo and the
heat simulation on the Monte Carlo's voxels, ``validation/layered.py``'s ``fine_data``) at
the truth A = (1, 100) cm^-1: the pseudo-true optics that an efficient estimator with this
model converges to. Its log error is the model's share of the error; ``floor``:
``sqrt(bias^2 + CRB^2) / CRB``, which must stay below 1.3 for the target (an RMS error
within 1.3 times the bound) to be within reach. The cases vary one source of model error
at a time (the report's sections):

1. the emulator's Monte Carlo draw (its seed) and photons, on the example's 20 x 20 x 10 FEM;
2. the fine truth's own Monte Carlo draw and photons;
3. the FEM's divisions, with a precise emulator and fine truth;
4. the emulator's photons on the finest FEM.

    python validation/layered_precision.py [--cache-dir DIR]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from enkf.app.config import load_identify
from enkf.app.suite import load_script, validation_dir

HERE = Path(__file__).parent
#: (part, FEM divisions, emulator photons, emulator seed (None: the config's),
#: fine-truth photons, fine-truth seed)
CASES = [
    *((1, (20, 20, 10), 100_000, s, 10**6, 4242) for s in (None, 0, 1, 2)),
    (1, (20, 20, 10), 1_600_000, 0, 10**6, 4242),
    *((2, (20, 20, 10), 1_600_000, 0, 10**6, s) for s in (1, 2, 3)),
    *((2, (20, 20, 10), 1_600_000, 0, 4 * 10**6, s) for s in (4242, 7)),
    *((3, g, 1_600_000, 0, 4 * 10**6, s) for g in ((30, 30, 15), (40, 40, 20))
      for s in (4242, 7)),
    *((4, (40, 40, 20), p, None, 4 * 10**6, s) for p in (1_600_000, 12_800_000)
      for s in (4242, 7)),
]
PARTS = {1: "the emulator's draw and photons (FEM 20 x 20 x 10, fine truth 10^6 photons)",
         2: "the fine truth's draw and photons (emulator 1,600,000 photons, seed 0)",
         3: "the FEM's divisions (emulator 1,600,000 photons, seed 0; fine truth 4 x 10^6)",
         4: "the emulator's photons on the finest FEM (the config's seed; fine truth 4 x 10^6)"}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache-dir", default=None, help="the emulators' cache (default: the "
                    "project's); the 12,800,000-photon build takes about 10 min on 2 cores")
    ap.add_argument("--out", default=str(HERE / "reports" / "layered_precision.md"))
    args = ap.parse_args(argv)
    layered = load_script(validation_dir(), "layered")
    ident = load_script(validation_dir(), "identifiability")
    base = load_identify(layered.CONFIG)
    truth = layered.TRUTHS["A (centre)"]
    fines, sensors, rows = {}, {}, {p: [] for p in PARTS}
    t0 = time.perf_counter()
    for part, grid, photons, seed, fine_photons, fine_seed in CASES:
        if (fine_photons, fine_seed) not in fines:
            fines[fine_photons, fine_seed] = layered.fine_data(base, truth, fine_photons,
                                                               fine_seed)
        key = (grid, photons, seed)
        if key not in sensors:
            cfg = layered.model_config(base, grid, photons, seed)
            emulator = cfg.emulator(cache_dir=args.cache_dir, progress=False)
            sensor = ident.ConfigSensor(layered.sensor_setup(cfg, emulator, "sensor"),
                                        layered.DT, layered.N_STEPS)
            crb = np.sqrt(np.diag(ident.config_bound(sensor, truth)))
            sensors[key] = (sensor, crb, cfg.emulator_kw.get("seed"))
        sensor, crb, used_seed = sensors[key]
        fit = layered.pseudo_true(sensor, fines[fine_photons, fine_seed], truth)
        bias, floor = layered.pseudo_floor(fit, truth, crb)
        rows[part].append(
            f"| {layered._grid(grid)} | {photons:,} | {used_seed if used_seed is not None else 'config'}"
            f" | {fine_photons:,} | {fine_seed} | {100 * crb[0]:.2f}%, {100 * crb[1]:.2f}% | "
            f"({fit['mua']:.4f}, {fit['mus']:.2f}) | {100 * bias[0]:+.2f}%, "
            f"{100 * bias[1]:+.2f}% | {fit['rms']:.4f} | {floor[0]:.2f}, {floor[1]:.2f} |")
        print(rows[part][-1], f"{time.perf_counter() - t0:.0f} s", flush=True)
    cmd = "python validation/layered_precision.py " + " ".join(
        argv if argv is not None else __import__("sys").argv[1:])
    lines = ["# How precise must the filter's model be for the fine truth? (two layers)", "",
             f"Command: `{cmd.strip()}`", "", __doc__.split("\n\n")[1].replace("\n", " "), "",
             __doc__.split("\n\n")[2].replace("\n", " ").split(" 1. ")[0], ""]
    for part, title in PARTS.items():
        lines += [f"## {part}. {title[0].upper()}{title[1:]}", "",
                  "| FEM | emulator photons | emulator seed | fine photons | fine seed | CRB "
                  "mua, mus | pseudo-true (mua, mus) | bias mua, mus | rms residual (deg C) "
                  "| floor / CRB mua, mus |", "|---|---|---|---|---|---|---|---|---|---|",
                  *rows[part], ""]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
