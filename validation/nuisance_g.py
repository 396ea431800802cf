"""The anisotropy g and the beam radius as nuisance inputs: what the filter
identifies when the tissue's g, or the beam's radius, is not the model's.

The filter's model has g = 0.9 (Table 1). The truths come from the independent forward
models of ``validation/independent_models.py`` (no code shared with the filter), run with
another g and with mus chosen so that the reduced scattering ``mus (1 - g)`` stays at
Table 1's 10 cm^-1 (mua 1 cm^-1, constant optics). If the thermal data see only the
reduced scattering (the similarity relation of diffusion theory), the filter returns the
same mua and ``mus (1 - 0.9)`` whatever the truth's g, and its temperature bands hold; its
mus is then the truth's mus times (1 - g) / (1 - 0.9), not the truth's mus.

    python validation/nuisance_g.py [--g 0.8 0.85 0.9 0.95] [--models B A] [--seeds 10]
    python validation/nuisance_g.py --beam-radius 0.09 0.095 0.105 0.11 --out runs/radius.md

With ``--beam-radius`` the truths keep g = 0.9 and mus = 100 and their top-hat beam has
the radius given (cm; the filter's model: 0.1 cm, the same power), to measure how well
the radius must be known. With ``--estimate-radius`` too, the filter carries the radius
as an uncertain input (``filter.estimate = ["mua", "mus", "beam_radius"]``, its prior
0.09-0.11 cm; ``validation/beam_radius.py``):

    python validation/nuisance_g.py --beam-radius 0.09 0.095 0.1 0.105 0.11 \
        --estimate-radius --out runs/radius_estimated.md

The filter: ``examples/own_data.toml`` (the config a user starts from), the default variant
of ``validation/model_error_coverage.py``. Each g's truths are cached beside the standard
ones (``independent/g<g>/``); g = 0.9 is the standard truth itself.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "validation"))

import independent_models as im  # noqa: E402
import model_error_coverage as mec  # noqa: E402

MODEL_G = 0.9  #: the filter's g (Table 1)
MODEL_RADIUS = 0.1  #: cm, the filter's beam radius
MUS_REDUCED = 10.0  #: cm^-1, Table 1's mus (1 - g)


@contextlib.contextmanager
def truth_tissue(g: float, radius: float = MODEL_RADIUS):
    """The independent models with anisotropy ``g`` and mus = 10 / (1 - g), constant mua 1,
    lit by a top-hat of ``radius`` (cm); their cache in a folder of its own (the standard
    one for g = 0.9 and radius 0.1)."""
    saved = (im.G_ANISO, im.optics, mec.optics, im.CACHE, im.BEAM_RADIUS)
    mus = MUS_REDUCED / (1.0 - g)

    def optics(case: str, t: float) -> tuple[float, float]:
        return 1.0, mus

    im.G_ANISO = g
    im.BEAM_RADIUS = radius
    im.optics = mec.optics = optics
    if (g, radius) != (MODEL_G, MODEL_RADIUS):
        im.CACHE = saved[3] / (f"g{g:g}" + (f"-r{radius:g}" if radius != MODEL_RADIUS else ""))
    try:
        yield mus
    finally:
        im.G_ANISO, im.optics, mec.optics, im.CACHE, im.BEAM_RADIUS = saved


#: ``--camera``: the commented camera of ``examples/own_data.toml`` in place of the sensor
CAMERA = {"x_range": [-0.2, 0.2], "y_range": [-0.2, 0.2], "shape": [16, 16], "noise_var": 0.01}


def study(tissues, models, seeds: int, estimate_radius: bool = False,
          camera: bool = False) -> list[dict]:
    """``tissues``: (g, beam radius) pairs of the truths; ``estimate_radius``: the filter
    carries the radius (``validation/beam_radius.radius_config``); ``camera``: it reads a
    16 x 16 camera's frames instead of the point sensor."""
    from beam_radius import radius_config

    sensors = {"positions": [], "camera": CAMERA} if camera else None
    cfg = radius_config(estimate=("mua", "mus", "beam_radius") if estimate_radius
                        else ("mua", "mus"), sensors=sensors)
    emulator = cfg.emulator(progress=False)
    rows = []
    for model in models:
        for g, radius in tissues:
            t0 = time.perf_counter()
            with truth_tissue(g, radius) as mus:
                runs = [mec.run_one(cfg, emulator, model, "constant", s, "default",
                                    extra_truth=(radius,) if estimate_radius else (),
                                    camera=camera)
                        for s in range(seeds)]
            fin = np.array([r["final"] for r in runs])
            sd = np.array([r["final_sd"] for r in runs])
            cool = np.array([r["cov_cool"] for r in runs])
            heat = np.array([r["cov_heat"] for r in runs])
            reduced = fin[:, 1] * (1.0 - MODEL_G)
            row = {"model": model, "g": g, "radius": radius, "mus": mus, "seeds": seeds,
                   "camera": camera,
                   "mua": fin[:, 0].mean(), "mua_sd": sd[:, 0].mean(),
                   "mus_est": fin[:, 1].mean(), "mus_sd": sd[:, 1].mean(),
                   "reduced": reduced.mean(),
                   "mua_ok": int((np.abs(fin[:, 0] - 1.0) <= 0.05).sum()),
                   "reduced_ok": int((np.abs(reduced - MUS_REDUCED) <= 0.25 * MUS_REDUCED).sum()),
                   "mus_ok": int((np.abs(fin[:, 1] - mus) <= 25.0).sum()),
                   "heat": heat.mean(0), "cool": cool.mean(0), "cool_worst": cool.min(0),
                   "seconds": time.perf_counter() - t0}
            if estimate_radius:
                row.update(radius_est=fin[:, 2].mean(), radius_sd=sd[:, 2].mean(),
                           radius_covered=int(sum(r["param_cov_final"][2] for r in runs)),
                           mua_covered=int(sum(r["param_cov_final"][0] for r in runs)),
                           mus_covered=int(sum(r["param_cov_final"][1] for r in runs)))
            rows.append(row)
            print(f"{model} g {g:g}, beam radius {radius:g}: mua {row['mua']:.3f}, mus "
                  f"{row['mus_est']:.1f} (truth {mus:.1f}), mus (1 - 0.9) {row['reduced']:.2f}; "
                  f"cooling coverage {np.round(row['cool'], 2)} ({row['seconds']:.0f} s)",
                  flush=True)
    return rows


def report(rows: list[dict], command: str) -> str:
    def triple(v):
        return ", ".join(f"{x:.2f}" for x in v)

    lines = ["# Nuisance inputs: the anisotropy g and the beam radius", "",
             f"Command: `{command}`", "",
             "Truths from the independent models with the tissue's g and the beam's radius below, "
             "mus = 10 / (1 - g) (reduced scattering 10 cm^-1, mua 1 cm^-1, constant); the "
             "filter's model has g = 0.9 and a radius of 0.1 cm (`examples/own_data.toml`"
             + (", with `filter.estimate = [\"mua\", \"mus\", \"beam_radius\"]`: the radius "
                "carried by the ensemble, its prior uniform over 0.09-0.11 cm"
                if any("radius_est" in r for r in rows) else "")
             + ("; read through a 16 x 16 camera over +-0.2 cm (its default model error) "
                "instead of the point sensor" if any(r.get("camera") for r in rows) else "")
             + "). Means "
             "over seeds; coverage: fraction of steps whose +-2 sd band holds the temperature at "
             "z = 0, 0.1, 0.2 cm (mean, and the worst seed while cooling).", "",
             "| truth | g | beam radius (cm) | truth mus | filter mua (sd) | filter mus (sd) | "
             "filter mus (1 - 0.9) | "
             "mua within 5% | filter mus (1 - 0.9) within 25% of 10 | mus within 25 cm^-1 | "
             "coverage heating | coverage cooling (worst) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        n = r["seeds"]
        lines.append(
            f"| {r['model']} | {r['g']:g} | {r['radius']:g} | {r['mus']:.1f} | "
            f"{r['mua']:.3f} ({r['mua_sd']:.3f}) | "
            f"{r['mus_est']:.1f} ({r['mus_sd']:.1f}) | {r['reduced']:.2f} | {r['mua_ok']}/{n} | "
            f"{r['reduced_ok']}/{n} | {r['mus_ok']}/{n} | {triple(r['heat'])} | "
            f"{triple(r['cool'])} ({triple(r['cool_worst'])}) |")
    est = [r for r in rows if "radius_est" in r]
    if est:
        lines += ["", "The filter with the radius estimated (prior 0.09-0.11 cm, uniform): its "
                  "estimate at 15 s (mean over seeds, mean sd), and the seeds whose +-2 sd band "
                  "holds each truth at 15 s.", "",
                  "| truth | beam radius (cm) | filter radius (sd) | radius covered | mua covered "
                  "| mus covered |", "|---|---|---|---|---|---|"]
        lines += [f"| {r['model']} | {r['radius']:g} | {r['radius_est']:.4f} ({r['radius_sd']:.4f})"
                  f" | {r['radius_covered']}/{r['seeds']} | {r['mua_covered']}/{r['seeds']} | "
                  f"{r['mus_covered']}/{r['seeds']} |" for r in est]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--g", type=float, nargs="+", default=[0.8, 0.85, 0.9, 0.95])
    ap.add_argument("--beam-radius", type=float, nargs="+", default=None,
                    help="truths with these beam radii (cm) and g = 0.9 instead of --g")
    ap.add_argument("--estimate-radius", action="store_true",
                    help="the filter carries the beam radius (estimate = mua, mus, beam_radius)")
    ap.add_argument("--camera", action="store_true",
                    help="the filter reads a 16 x 16 camera over +-0.2 cm instead of the sensor")
    ap.add_argument("--models", nargs="+", default=["B", "A"], choices=list(im.MODELS))
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--out", type=Path, default=ROOT / "validation" / "reports" / "nuisance_g.md")
    a = ap.parse_args(argv)
    for g in a.g:
        if not 0.0 <= g < 1.0:
            ap.error(f"--g must lie in [0, 1) (got {g})")
    if a.seeds < 1:
        ap.error(f"--seeds must be >= 1 (got {a.seeds})")
    for r in a.beam_radius or []:
        if not 0.0 < r < 0.25:
            ap.error(f"--beam-radius must lie in (0, 0.25) cm (got {r})")
    tissues = ([(MODEL_G, r) for r in a.beam_radius] if a.beam_radius
               else [(g, MODEL_RADIUS) for g in a.g])
    if a.estimate_radius and not a.beam_radius:
        ap.error("--estimate-radius needs --beam-radius")
    rows = study(tissues, a.models, a.seeds, a.estimate_radius, a.camera)
    command = "python validation/nuisance_g.py " + " ".join(argv or sys.argv[1:])
    a.out.write_text(report(rows, command.strip()))
    from reporting import results_path

    results_path(a.out).write_text(json.dumps(
        [{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()}
         for r in rows], indent=1))
    print(f"report written to {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
