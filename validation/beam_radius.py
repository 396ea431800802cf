"""The beam radius as an input the ensemble carries: the emulator over the
radius against direct Monte Carlo, and the filter on truths lit by another radius.

Part 1, the emulator. ``filter.estimate = ["mua", "mus", "beam_radius"]`` reads the
absorbed power from a :class:`~mcmatlab_py.emulator.media.BeamRadiusEmulator`: one table
over (mua, mus) per node radius, ``log(load + offset)`` interpolated in ``log radius``.
At radii between and beyond the nodes it is compared with a table built directly at that
radius (the same photons and seed, so the two share most of their Monte Carlo noise and
the difference is the interpolation's), on the filter's nodal loads, as the relative L2
error over the nodes that hold 99% of the load (``validation/emulator_accuracy.py``'s
metric), at the optics of the prior's centre and two off-grid points. The Monte Carlo
noise of one table is measured beside it (the same radius, another seed).

Part 2, the filter (``--filter``): ``validation/nuisance_g.py --beam-radius ...
--estimate-radius`` runs ``examples/own_data.toml`` with the radius estimated on the
independent models' truths.

    python validation/beam_radius.py [--nodes 3 4 5] [--out validation/reports/beam_radius.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "validation"))

from emulator_accuracy import rel_l2, top99  # noqa: E402

from enkf.app.config import identify_config_from_dict  # noqa: E402
from mcmatlab_py.config import read_toml  # noqa: E402
from mcmatlab_py.emulator import AbsorptionEmulator  # noqa: E402
from mcmatlab_py.emulator.media import BeamRadiusEmulator  # noqa: E402

#: cm: radii between the nodes, at the prior's edges (+-10%) and beyond them
RADII = (0.085, 0.09, 0.095, 0.1, 0.105, 0.11, 0.115)
#: cm^-1: the prior's centre and two off-grid points inside the prior
OPTICS = ((1.0, 100.0), (0.7, 60.0), (1.6, 180.0))


def radius_config(path: Path = ROOT / "examples" / "own_data.toml",
                  estimate=("mua", "mus", "beam_radius"), sensors: dict | None = None):
    """``examples/own_data.toml`` with the beam radius estimated (``estimate``), and
    ``sensors`` in place of its ``[sensors]`` table if given."""
    cfg = read_toml(path)
    cfg["filter"]["estimate"] = list(estimate)
    if sensors is not None:
        cfg["sensors"] = {**sensors, "tracked": cfg["sensors"]["tracked"]}
        cfg["data"].pop("columns", None)  # the frames are not the sensor's column
    cfg.setdefault("data", {})["file"] = str(path.parent / cfg["data"]["file"])
    return identify_config_from_dict(cfg)


def study(node_counts, cache_dir=None) -> tuple[list[str], dict]:
    cfg = radius_config()
    base = cfg.emulator(progress=False, cache_dir=cache_dir)  # the config's nodes
    spec, rng = base.spec, cfg.beam_nodes["radius_range"]
    kw = dict(cache_dir=cache_dir, progress=False, out_of_range="clamp", on_demand=True)
    emus = {n: BeamRadiusEmulator.build(spec, rng, n_nodes=n, **kw) for n in node_counts}
    lines, worst = [], {}
    t0 = time.perf_counter()
    for r in RADII:
        direct = AbsorptionEmulator.build(dataclasses.replace(spec, radius=r,
                                                              medium_map=spec.medium_map), **kw)
        for mua, mus in OPTICS:
            ref = direct(np.array([mua]), np.array([mus]))[0].ravel()
            sel = top99(ref)
            errs = []
            for n, emu in emus.items():
                e = rel_l2(emu(np.array([mua]), np.array([mus]), np.array([r]))[0].ravel(), ref,
                           sel)
                worst[n] = max(worst.get(n, 0.0), e) if rng[0] <= r <= rng[1] else worst.get(n, 0.0)
                errs.append(f"{100 * e:.3f}%")
            lines.append(f"| {r:g} | {mua:g} | {mus:g} | " + " | ".join(errs) + " |")
            print(lines[-1], flush=True)
    # the Monte Carlo noise of one table: the same radius and optics, another seed
    noise = []
    for seed in (1, 2):
        other = AbsorptionEmulator.build(dataclasses.replace(spec, radius=0.1, seed=seed,
                                                             medium_map=spec.medium_map), **kw)
        noise.append(other(np.array([1.0]), np.array([100.0]))[0].ravel())
    sel = top99(noise[0])
    mc_noise = rel_l2(noise[1], noise[0], sel) / np.sqrt(2)
    return lines, dict(worst=worst, noise=mc_noise, nodes={n: e.radius_nodes for n, e in
                                                           emus.items()},
                       seconds=time.perf_counter() - t0, photons=spec.n_photons, range=rng)



def report(lines, info, node_counts, command: str) -> str:
    nodes = "; ".join(f"{n} nodes: {', '.join(f'{v:.4f}' for v in info['nodes'][n])} cm"
                      for n in node_counts)
    out = ["# The beam radius in the emulator", "", f"Command: `{command}`", "",
           "`examples/own_data.toml` with `filter.estimate = [\"mua\", \"mus\", \"beam_radius\"]`: "
           f"the emulator's node radii span {info['range'][0]:.4f}-{info['range'][1]:.4f} cm (the "
           "prior, 0.09-0.11 cm, widened 1.1 times each way), log-spaced ("
           f"{nodes}); {info['photons']:,} photons per table point. Each row: relative L2 error of "
           "the filter's nodal loads, interpolated in the radius, against a table built directly at "
           "that radius with the same photons and seed, over the nodes that hold 99% of the load.",
           "", "| radius (cm) | mua (cm^-1) | mus (cm^-1) | "
           + " | ".join(f"{n} nodes" for n in node_counts) + " |",
           "|---" * (3 + len(node_counts)) + "|", *lines, "",
           "Worst inside the nodes' range: " + ", ".join(
               f"{n} nodes {100 * info['worst'][n]:.3f}%" for n in node_counts)
           + f". The Monte Carlo noise of one table (radius 0.1 cm, mua 1, mus 100, two other "
           f"seeds): {100 * info['noise']:.3f}%. Every radius above lies inside the nodes' range; "
           "the filter clamps a member beyond it to the last node and counts it "
           "(`summary.json`'s `emulator_clamped`, with the advice to widen "
           "`filter.emulator.radius_range`).", ""]
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[3, 4, 5])
    ap.add_argument("--cache-dir", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=ROOT / "validation" / "reports" / "beam_radius.md")
    a = ap.parse_args(argv)
    if any(n < 2 for n in a.nodes):
        ap.error(f"--nodes must be >= 2 (got {a.nodes})")
    lines, info = study(a.nodes, a.cache_dir)
    command = "python validation/beam_radius.py " + " ".join(argv or sys.argv[1:])
    a.out.write_text(report(lines, info, a.nodes, command.strip()))
    print(f"report written to {a.out} ({info['seconds']:.0f} s with the tables cached or built)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
