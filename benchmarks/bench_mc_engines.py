"""Monte Carlo engines side by side: the general voxel kernel, the one-medium kernel, MCmatlab's.

One thread each, photons per CPU-second, in one run:

* ``block``: the paper's tissue (100 x 100 x 50 voxels, 0.5 x 0.5 x 0.25 cm, mua 1, mus 100,
  g 0.9, 1 mm top-hat) with one corner voxel of a second, identical medium, which sends the
  run to the general kernel; the yardstick is the same block of one medium, which takes the
  one-medium kernel (``mcmatlab_py/monte_carlo/_uniform.py``).
* ``ex01``, ``ex04``, ``ex05``: MCmatlab's Examples 1, 4 and 5 (the gallery's scripts in
  ``examples/mcmatlab/``) reduced to 61 x 61 x 60, 50^3 and 50^3 voxels; Example 5 is its
  excitation run, with the lens imaging and 100 example paths. The yardstick is the same
  grid and beam filled with the example's tissue (one medium, no optional outputs: the
  one-medium kernel).
  With ``--mcmatlab DIR`` (or ``MCM_ROOT``; a MCmatlab checkout built for GNU Octave by
  ``../shared/tools/mcmatlab-octave``, e.g. ``/tmp/mcm/mcm``) MCmatlab's own C engine runs
  the same model (same grid, optics, beam and outputs) through ``octave-cli``, one thread.

Run::

    python benchmarks/bench_mc_engines.py [--photons N] [--rounds K] [--mcmatlab DIR]
                                          [--problems block,ex01,ex04,ex05] [--breakdown]

``--breakdown`` instead times the general kernel against itself with a part switched off:
walking every packet face by face (a safety map of zeros, the kernel before its free
moves), without delta tracking next to similar media, and without the track-length tally
of thin media.

A rate is marginal: each engine runs N/5 and N photons and the rate is 4N/5 over the
difference of the CPU times (ours: this process's CPU time around ``run_monte_carlo``,
with the safety map and everything else a run does; MCmatlab: Octave's ``cputime`` around
``runMonteCarlo``), so neither start-up counts and the CPU time does not depend on how
busy a shared machine is. The runs of a round are interleaved; the table gives the best
rate of each engine over the rounds and the median of the rounds' ratios.
"""

from __future__ import annotations

import argparse
import copy
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples" / "mcmatlab"))


def _finish(model, n: int, seed: int = 1):
    MC = model.MC
    MC.n_photons_requested = n
    MC.seed = seed
    MC.progress = False
    MC.n_threads = 1
    return model


def block(n: int, one_medium: bool = False):
    """The paper's block; a corner voxel of a second, identical medium unless ``one_medium``."""
    from enkf.paper import paper_model

    model = paper_model((100, 100, 50), n_photons=n, seed=1, progress=False)
    if not one_medium:
        med = model.G.media[0]
        twin = copy.deepcopy(med)
        twin.name = "the same tissue"
        model.G.media = [med, twin]

        def corner(X, Y, Z):
            M = np.zeros(X.shape, dtype=int)
            M[0, 0, -1] = 1
            return M

        model.G.geom_func = corner
    return _finish(model, n)


def example(name: str, grid: tuple[int, int, int], tissue: int):
    """``build(n, one_medium)`` of a gallery example on ``grid``; ``one_medium`` fills the grid
    with the example's medium ``tissue`` and asks for no optional output (the one-medium
    kernel runs only plain runs)."""
    module = __import__({"ex01": "ex01_standard_tissue", "ex04": "ex04_blood_vessel",
                         "ex05": "ex05_fluorescence_and_imaging"}[name])

    def build(n: int, one_medium: bool = False):
        model = module.build(quick=False)
        model.G.nx, model.G.ny, model.G.nz = grid
        if one_medium:
            model.G.media = [model.G.media[tissue]]
            model.G.geom_func = None
            model.MC.use_light_collector = False
            model.MC.n_example_paths = 0
        return _finish(model, n)

    return build


#: MCmatlab's geometry functions of the examples (their own code), for the Octave side
GEOMETRY = {
    "ex01": "M = ones(size(X)); M(Z > 0.03) = 2;",
    "ex04": ("M = ones(size(X)); M(Z > 0.01) = 2; M(Z > 0.016) = 3;\n"
             "  M(X.^2 + (Z - 0.05).^2 < 0.01^2) = 4;"),
    "ex05": "M = ones(size(X)); M(Y.^2 + (Z - 0.03).^2 < 0.01^2) = 2;",
}

PROBLEMS = {
    "block": block,
    "ex01": example("ex01", (61, 61, 60), 1),  # standard tissue
    "ex04": example("ex04", (50, 50, 50), 2),  # dermis
    "ex05": example("ex05", (50, 50, 50), 0),  # the fluorescence absorber
}


def cpu_of_run(model) -> float:
    c0 = time.process_time()
    model.run_monte_carlo()
    return time.process_time() - c0


def ours(build, n: int, one_medium: bool = False) -> tuple[float, float]:
    """Marginal photons per CPU-second of ``run_monte_carlo`` on one thread, and the fraction
    of the power absorbed in the long run."""
    small = n // 5
    t1 = cpu_of_run(build(small, one_medium))
    model = build(n, one_medium)
    t2 = cpu_of_run(model)
    return _marginal(small, t1, n, t2), model.MC.absorbed_fraction


def _marginal(n1: int, t1: float, n2: int, t2: float) -> float:
    """(n2 - n1) / (t2 - t1); where the difference drowns in the clock's noise (too few
    photons), the long run's n2 / t2 (start-up included: a lower bound)."""
    if t2 - t1 < 0.2 * t2:
        return n2 / t2
    return (n2 - n1) / (t2 - t1)


# ----------------------------------------------------------------------------- MCmatlab
def _octave_model(name: str, model) -> str:
    """Octave lines that set up MCmatlab's model as ``model`` (ours) is set up."""
    from mcmatlab_py.monte_carlo import optical_arrays

    G, MC = model.G, model.MC
    src = MC.light_source
    mua, mus, g, nref = optical_arrays(G.media, MC.wavelength)
    media = "\n".join(
        f"  mp({k + 1}).name = 'm{k + 1}'; "
        + " ".join(f"mp({k + 1}).{f} = {float(v[k])!r};"
                   for f, v in (("mua", mua), ("mus", mus), ("g", g), ("n", nref)))
        for k in range(len(mua)))
    lines = [
        f"model.G.nx = {G.nx}; model.G.ny = {G.ny}; model.G.nz = {G.nz};",
        f"model.G.Lx = {float(G.Lx)!r}; model.G.Ly = {float(G.Ly)!r}; model.G.Lz = {float(G.Lz)!r};",
        "model.G.mediaPropertiesFunc = @mediaPropertiesFunc;",
        "model.G.geomFunc = @geometryDefinition;",
        f"model.MC.matchedInterfaces = {'true' if MC.matched_interfaces else 'false'};",
        f"model.MC.boundaryType = {MC.boundary_type};",
        f"model.MC.wavelength = {float(MC.wavelength)!r};",
        f"model.MC.nExamplePaths = {MC.n_example_paths or 0};",
    ]
    if name == "ex01":
        lines += ["model.MC.lightSource.sourceType = 0;",
                  f"model.MC.lightSource.zFocus = {float(src.z_focus)!r};"]
    elif name == "ex04":
        lines += ["model.MC.lightSource.sourceType = 4;",
                  "model.MC.lightSource.focalPlaneIntensityDistribution.radialDistr = 0;",
                  "model.MC.lightSource.focalPlaneIntensityDistribution.radialWidth = 0.03;",
                  "model.MC.lightSource.angularIntensityDistribution.radialDistr = 0;",
                  "model.MC.lightSource.angularIntensityDistribution.radialWidth = 0;"]
    else:
        LC = MC.light_collector
        lines += ["model.MC.lightSource.sourceType = 2;", "model.MC.useLightCollector = true;",
                  f"model.MC.lightCollector.z = {float(LC.z)!r}; model.MC.lightCollector.phi = pi/2;",
                  f"model.MC.lightCollector.f = {float(LC.f)!r};",
                  f"model.MC.lightCollector.diam = {float(LC.diam)!r};",
                  f"model.MC.lightCollector.fieldSize = {float(LC.field_size)!r};",
                  f"model.MC.lightCollector.NA = {float(LC.NA)!r}; model.MC.lightCollector.res = {LC.res};"]
    head = ("1;\nfunction M = geometryDefinition(X,Y,Z,parameters)\n  " + GEOMETRY[name]
            + "\nend\nfunction mp = mediaPropertiesFunc(parameters)\n"
            "  mp = MCmatlab.mediumProperties;\n" + media + "\nend\n")
    return head, "\n".join("  " + ln for ln in lines)


def mcmatlab(name: str, build, n: int, mcm_root: Path) -> tuple[float, float]:
    """Marginal photons per CPU-second of MCmatlab's engine under Octave, one thread, and
    the fraction of the power absorbed in its long run."""
    head, setup = _octave_model(name, build(n))
    small = n // 5
    script = (head + "mcmRoot = getenv('MCM_ROOT'); cd(mcmRoot);\n"
              "addpath(fullfile(mcmRoot, 'octave_compat')); mcmatlab_octave_setup(mcmRoot);\n"
              f"for count = [{small} {n}]\n  model = MCmatlab.model;\n{setup}\n"
              "  model.MC.nPhotonsRequested = count; model.MC.useAllCPUs = false;\n"
              "  model.MC.silentMode = true;\n"
              "  t0 = cputime; model = runMonteCarlo(model); t1 = cputime;\n"
              "  absorbed = sum(double(model.MC.NA(:))) * model.G.dx * model.G.dy * model.G.dz;\n"
              "  printf('MCMBENCH %d %.6f %d %.6f\\n', model.MC.nPhotons, t1 - t0, "
              "model.MC.nThreads, absorbed);\n"
              "end\n")
    with tempfile.TemporaryDirectory(prefix="bench_mcm_") as tmp:
        path = Path(tmp) / "bench_case.m"
        path.write_text(script)
        env = {**os.environ, "MCM_ROOT": str(mcm_root), "MCMATLAB_SEED": "1",
               "OMP_NUM_THREADS": "1"}
        p = subprocess.run(["octave-cli", "--norc", str(path)], env=env, capture_output=True,
                           text=True, timeout=3600)
    rows = [ln.split()[1:] for ln in p.stdout.splitlines() if ln.startswith("MCMBENCH")]
    if len(rows) != 2:
        raise RuntimeError(f"MCmatlab under Octave failed on {name}:\n{p.stdout[-2000:]}"
                           f"\n{p.stderr[-2000:]}")
    (n1, t1, th1, _), (n2, t2, th2, absorbed) = (
        (int(a), float(b), int(c), float(f)) for a, b, c, f in rows)
    if max(th1, th2) != 1:
        raise RuntimeError(f"MCmatlab ran {max(th1, th2)} threads, not 1")
    return _marginal(n1, t1, n2, t2), absorbed


# ----------------------------------------------------------------------------- breakdown
def breakdown(names: list[str], n: int, rounds: int) -> None:
    """Where the general kernel's time goes, by switching its parts off in turn (one
    thread, this process): the free moves (a safety map of zeros walks every packet face by
    face, as the kernel did before them), delta tracking next to similar media
    (``safety.DELTA_RATIO`` above 1: no groups, those voxels walked face by face) and the
    track-length tally of thin media (``MC.calc_normalized_fluence_rate = False``)."""
    from mcmatlab_py.monte_carlo import host as mc
    from mcmatlab_py.monte_carlo import safety

    real, ratio = mc.kernel_safety, safety.DELTA_RATIO

    def walk(args, *_):
        return np.zeros(args[0].size, dtype=np.float32)

    def no_track(build):
        def without(k, one=False):
            model = build(k, one)
            model.MC.calc_normalized_fluence_rate = False
            return model
        return without

    print("| problem | as run | walking face by face | without delta tracking "
          "| without the track-length tally |")
    print("|---|---|---|---|---|")
    for name in names:
        build = PROBLEMS[name]
        for b in (build, no_track(build)):  # compile or load the kernels outside the timing
            b(2000).run_monte_carlo()
        best = {"as run": 0.0, "walk": 0.0, "no delta": 0.0, "no track": 0.0}
        for _ in range(rounds):
            best["as run"] = max(best["as run"], ours(build, n)[0])
            mc.kernel_safety = walk
            try:
                best["walk"] = max(best["walk"], ours(build, n)[0])
            finally:
                mc.kernel_safety = real
            safety.DELTA_RATIO = 2.0
            try:
                best["no delta"] = max(best["no delta"], ours(build, n)[0])
            finally:
                safety.DELTA_RATIO = ratio
            best["no track"] = max(best["no track"], ours(no_track(build), n)[0])
        r = best["as run"]
        tally = (f"{best['no track']:.3g} (the tally: {1 - r / best['no track']:.0%} of the time)"
                 if _has_thin_media(build(1000)) else "no thin medium: nothing to switch off")
        print(f"| {name} | {r:.3g} | {best['walk']:.3g} ({r / best['walk']:.2f}x slower) | "
              f"{best['no delta']:.3g} ({r / best['no delta']:.2f}x slower) | {tally} |",
              flush=True)


def _has_thin_media(model) -> bool:
    """Whether a medium of the grid gets the track-length tally (``monte_carlo.THIN``)."""
    from mcmatlab_py.monte_carlo import THIN, optical_arrays

    G = model.G
    mua, mus, _, _ = optical_arrays(G.media, model.MC.wavelength)
    present = np.unique(G.medium_map())
    dmin = min(G.dx, G.dy, G.dz)
    return bool(np.any((mua[present] <= 0.0) | ((mua + mus)[present] * dmin < THIN)))


# ----------------------------------------------------------------------------- the table
def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photons", type=int, default=200_000, help="photons of a long run")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--problems", default="block,ex01,ex04,ex05")
    parser.add_argument("--mcmatlab", default=os.environ.get("MCM_ROOT"),
                        help="MCmatlab built for Octave (../shared/tools/mcmatlab-octave)")
    parser.add_argument("--breakdown", action="store_true",
                        help="instead: the general kernel with its parts switched off in turn")
    args = parser.parse_args(argv)
    names = args.problems.split(",")
    if args.breakdown:
        numba.set_num_threads(1)
        breakdown(names, args.photons, args.rounds)
        return
    mcm = Path(args.mcmatlab) if args.mcmatlab else None
    if mcm is not None and not (shutil.which("octave-cli") and (mcm / "+MCmatlab").is_dir()):
        print(f"MCmatlab: no octave-cli or no MCmatlab at {mcm}; its column is left out")
        mcm = None
    numba.set_num_threads(1)
    for name in names:  # compile or load the kernels outside the timing
        for one in (False, True):
            PROBLEMS[name](2000, one).run_monte_carlo()
    rates: dict[tuple[str, str], list[float]] = {}
    for r in range(args.rounds):
        for name in names:
            build = PROBLEMS[name]
            got = {"ours": ours(build, args.photons), "one medium": ours(build, args.photons, True)}
            if mcm is not None and name != "block":
                got["MCmatlab"] = mcmatlab(name, build, args.photons, mcm)
            for k, (v, _) in got.items():
                rates.setdefault((name, k), []).append(v)
            # the absorbed fractions show that ours and MCmatlab's ran the same model
            print(f"round {r + 1} {name}: " + ", ".join(
                f"{k} {v:.3g} photons/CPU-s (absorbed {a:.4f})" for k, (v, a) in got.items()),
                  flush=True)
    print(f"\nphotons per CPU-second, one thread, best of {args.rounds} rounds of "
          f"{args.photons} photons (ratio: best rates; median of the rounds' ratios)")
    print("| problem | ours (general kernel) | one-medium kernel, same grid | ours / one-medium "
          "| MCmatlab's engine | ours / MCmatlab |")
    print("|---|---|---|---|---|---|")
    for name in names:
        o, u = rates[(name, "ours")], rates[(name, "one medium")]
        m = rates.get((name, "MCmatlab"))

        def ratio(a, b):
            med = statistics.median(x / y for x, y in zip(a, b, strict=True))
            return f"{max(a) / max(b):.2f}x ({med:.2f}x)"

        cells = [f"{max(o):.3g}", f"{max(u):.3g}", ratio(o, u),
                 f"{max(m):.3g}" if m else "-", ratio(o, m) if m else "-"]
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
