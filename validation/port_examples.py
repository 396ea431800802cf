"""Convert MCmatlab's examples with ``tissue-enkf port`` and run what comes out.

For each of MCmatlab's 26 ``Example*.m`` and ``Test1``: convert it
(:func:`mcmatlab_py.port.port_model`), run the converted script unchanged at reduced size
(``MCMATLAB_PY_QUICK=1``: at most 61 voxels a side and 2000 photons a run, in a folder
holding MCmatlab's ``sample.stl`` and ``helperfuncs/`` as its users run from MCmatlab's
folder), and compare its first model with the hand-written port in
``examples/mcmatlab/`` (``build(quick=True)``): the converted model, set to the hand
port's grid, photon count (launched or collected) and seed, must give the same voxel map
of media and the same absorption ``MC.NA`` to rounding (the same kernel, the same seed:
the same numbers). Where the hand port's ``build`` leaves the seed to ``run`` (a sweep's
runs), both get :data:`SEED_IF_NONE`; Example 21 is compared at the grid its fixed voxel
``M(51,51,:)`` needs (:data:`COMPARE_GRID`). Nothing else of the converted model is set:
every other setting is the conversion's.

    python validation/port_examples.py PATH [--only Example4_BloodVessel ...]

``PATH`` (or the environment variable ``MCMATLAB_DIR``): MCmatlab's git directory or a
checkout (``git clone https://github.com/ankrh/MCmatlab``); without either, a report
elsewhere than the default says the study was skipped. MCmatlab's files are read from
there, never copied into this repository (GPL). Writes
``validation/reports/port_examples.md`` (its numbers in ``validation/results/port_examples.json``).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

#: the hand port of each MCmatlab file, and how its first model is built
HAND = {
    "Example1_StandardTissue": "ex01_standard_tissue",
    "Example2_BeamDefinitions": "ex02_beam_definitions",
    "Example3_RefractionReflection": "ex03_refraction_reflection",
    "Example4_BloodVessel": "ex04_blood_vessel",
    "Example5_FluorescenceAndImaging": "ex05_fluorescence_and_imaging",
    "Example6_TimeTagging": "ex06_time_tagging",
    "Example7_FarField": "ex07_far_field",
    "Example8_CollectedFluenceRate": "ex08_collected_fluence_rate",
    "Example9_GeometryParametricSweep": "ex09_geometry_parametric_sweep",
    "Example10_MediaPropertyParametricSweep": "ex10_media_property_parametric_sweep",
    "Example11_MultipleHeatSims": "ex11_multiple_heat_sims",
    "Example12_SaturableAbsorber": "ex12_saturable_absorber",
    "Example13_TdependentVHC": "ex13_t_dependent_vhc",
    "Example14_Thermochromism": "ex14_thermochromism",
    "Example15_ThermallyInducedScattering": "ex15_thermally_induced_scattering",
    "Example16_CUDAacceleration": "ex16_cuda_acceleration",
    "Example17_CurvedRefractionReflection": "ex17_curved_refraction_reflection",
    "Example18_STLimport": "ex18_stl_import",
    "Example19_DepositionCriteria": "ex19_deposition_criteria",
    "Example20_ReflectanceStatisticsAndCyclicBoundaries": "ex20_reflectance_statistics",
    "Example21_CustomPhaseFunctions": "ex21_custom_phase_functions",
    "Example22_CombiningModelObjects": "ex22_combining_model_objects",
    "Example23_BroadbandMonteCarlo": "ex23_broadband_monte_carlo",
    "Example24_AzFzReflectanceTransmittance": "ex24_az_fz_reflectance_transmittance",
    "Example25_DepositionCriteria2": "ex25_deposition_criteria2",
    "Example26_DistributedSource": "ex26_distributed_source",
    "Test1_AllFRTDependences": "test1_all_frt_dependences",
}
#: keyword arguments of build() for the converted script's first model, where not the default
BUILD_ARGS = {"ex10_media_property_parametric_sweep": {"g": -1.0},
              # MCmatlab's tables of Lucifer Yellow, in the folder the scripts run in
              "ex23_broadband_monte_carlo": {"tables": "helperfuncs"}}
#: grids compared at instead of the hand port's quick one: Example 21's scatterer is the
#: fixed voxel column M(51,51,:), the hand port's centre column only at nx, ny = 101
COMPARE_GRID = {"ex21_custom_phase_functions": (101, 101, 30)}
#: the seed of both runs where the hand port's build() leaves it to run() (one per run of a
#: sweep: Examples 10, 20, 22)
SEED_IF_NONE = 1


# ---------------------------------------------------------------------- the parent process
def mcmatlab_files(path: Path) -> dict[str, bytes]:
    """{name: bytes} of the examples, sample.stl and helperfuncs/*.txt at ``path``."""
    names = [*HAND, "sample.stl", "helperfuncs/LuciferYellowCHinWater-abs.txt",
             "helperfuncs/LuciferYellowCHinWater-ems.txt"]
    out = {}
    git = path / "HEAD" if (path / "HEAD").is_file() else None
    for name in names:
        file = name if "." in name else name + ".m"
        if git is not None:
            r = subprocess.run(["git", f"--git-dir={path}", "show", f"HEAD:{file}"],
                               capture_output=True, check=False)
            if r.returncode == 0:
                out[file] = r.stdout
        elif (path / file).is_file():
            out[file] = (path / file).read_bytes()
    missing = [n for n in HAND if n + ".m" not in out]
    if missing:
        raise SystemExit(f"port_examples: {path} lacks {', '.join(missing)}: give MCmatlab's git "
                         "directory or checkout")
    return out


def run_one(name: str, files: dict[str, bytes], timeout: float) -> dict:
    from mcmatlab_py.port import port_model, read_matlab

    row = {"example": name}
    t0 = time.perf_counter()
    try:
        result = port_model(read_matlab(files[name + ".m"]), name + ".m")
    except Exception as err:  # noqa: BLE001 - the report records any failure
        row.update(converted=False, error=f"{type(err).__name__}: {err}")
        return row
    row.update(converted=True, convert_s=round(time.perf_counter() - t0, 3),
               unconverted=[[n, " ".join(t.split()), why] for n, t, why in result.unconverted])
    with tempfile.TemporaryDirectory(prefix="port_") as tmp:
        work = Path(tmp)
        for file, data in files.items():
            if not file.endswith(".m"):
                (work / file).parent.mkdir(parents=True, exist_ok=True)
                (work / file).write_bytes(data)
        script = work / (name + ".py")
        script.write_text(result.script)
        env = {**os.environ, "MCMATLAB_PY_QUICK": "1", "MPLBACKEND": "Agg",
               "PYTHONPATH": str(ROOT)}
        t0 = time.perf_counter()
        try:
            proc = subprocess.run([sys.executable, __file__, "--child", str(script), HAND[name]],
                                  cwd=work, env=env, capture_output=True, text=True,
                                  timeout=timeout, check=False)
            out, err, rc = proc.stdout, proc.stderr, proc.returncode
        except subprocess.TimeoutExpired:
            out, err, rc = "", f"timed out after {timeout:.0f} s", -1
        row["run_s"] = round(time.perf_counter() - t0, 1)
    found = [json.loads(line[len("PORT_RESULT "):]) for line in out.splitlines()
             if line.startswith("PORT_RESULT ")]
    if found:
        row.update(found[-1])
    else:
        row.update(ran=False, error=_last_error(err) or f"exit code {rc}")
    return row


def _last_error(stderr: str) -> str:
    lines = [ln for ln in stderr.strip().splitlines() if ln.strip()]
    errors = [ln for ln in lines if re.match(r"^\w+(Error|Exception)\b", ln)]
    return (errors[-1] if errors else (lines[-1] if lines else "")).strip()


# ---------------------------------------------------------------------- the child process
def child(script: str, hand: str) -> None:
    """Run the converted ``script``; then compare its first model with ``hand``'s."""
    import runpy
    import traceback

    import numpy as np

    from mcmatlab_py import Model

    first: dict = {}
    run, plot = Model.run_monte_carlo, Model.plot

    def keep(model, why):
        if why not in first:
            first[why] = copy.deepcopy(model)

    def recording_run(self, *args, **kwargs):
        if not args or args[0] != "fluorescence":
            keep(self, "run")
        return run(self, *args, **kwargs)

    def recording_plot(self, what=None, *args, **kwargs):
        if what == "G":
            keep(self, "plot")
        return plot(self, what, *args, **kwargs)

    Model.run_monte_carlo, Model.plot = recording_run, recording_plot
    result: dict = {}
    try:
        runpy.run_path(script, run_name="__main__")
        result["ran"] = True
    except BaseException as err:  # noqa: BLE001 - recorded
        result.update(ran=False, error=f"{type(err).__name__}: {err}".strip()[:300])
        traceback.print_exc()
    finally:
        Model.run_monte_carlo, Model.plot = run, plot
    import matplotlib.pyplot as plt

    plt.close("all")
    at = "run" if "run" in first else ("plot" if "plot" in first else None)
    if at is not None:
        try:
            result.update(compare(first[at], at, hand, np))
        except Exception as err:  # noqa: BLE001 - recorded
            result.update(agrees="not compared", detail=f"{type(err).__name__}: {err}"[:300])
    else:
        result.update(agrees="not compared", detail="the script built no model")
    print("PORT_RESULT " + json.dumps(result), flush=True)


def _plain(part) -> None:
    """Undo ``quick``: the hand port's sizes are set as they are."""
    cls = type(part)
    if cls.__name__.startswith("Quick"):
        part.__class__ = cls.__mro__[1]


def compare(conv, at: str, hand_name: str, np) -> dict:
    import importlib.util

    path = ROOT / "examples" / "mcmatlab" / f"{hand_name}.py"
    spec = importlib.util.spec_from_file_location(hand_name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    if hand_name == "ex18_stl_import":
        hand = mod.build("as_is", mod.sample_mesh(), quick=True)
    else:
        hand = mod.build(quick=True, **BUILD_ARGS.get(hand_name, {}))
    for part in ("G", "MC", "FMC", "HS"):
        _plain(getattr(conv, part))
    if hand_name in COMPARE_GRID:
        hand.G.nx, hand.G.ny, hand.G.nz = COMPARE_GRID[hand_name]
    for name in ("nx", "ny", "nz"):
        setattr(conv.G, name, getattr(hand.G, name))
    try:
        same_map = bool(np.array_equal(conv.G.medium_map(), hand.G.medium_map()))
    except Exception as err:  # noqa: BLE001 - recorded
        return {"agrees": "not comparable",
                "detail": f"at the hand port's grid {hand.G.nx}x{hand.G.ny}x{hand.G.nz}: "
                          f"{type(err).__name__}: {err}"[:300]}
    if not same_map:
        return {"agrees": "differs", "detail": "the voxel maps of media differ"}
    if at != "run":
        return {"agrees": "identical", "detail": "the voxel map of media (no Monte Carlo run)"}
    MC = conv.MC
    if hand.MC.seed is None:
        hand.MC.seed = SEED_IF_NONE
    # how many photons: launched, or collected (Example 6's hand port stops at a count of
    # collected packets where MCmatlab's script runs for a time)
    for name in ("n_photons_requested", "request_collected_photons", "seed"):
        setattr(MC, name, getattr(hand.MC, name))
    MC.simulation_time_requested = hand.MC.simulation_time_requested
    if np.ndim(hand.MC.wavelength) and np.ndim(MC.wavelength):
        MC.wavelength = hand.MC.wavelength  # the hand port's quick run has fewer wavelengths
        if MC.source_distribution is not None and hand.MC.source_distribution is not None:
            MC.source_distribution = hand.MC.source_distribution
    for name in ("FR", "T", "FD"):  # voxel states made at the script's grid: the hand port's
        if np.ndim(getattr(MC, name)) == 3 and np.shape(getattr(MC, name)) != (
                hand.G.nx, hand.G.ny, hand.G.nz):
            setattr(MC, name, getattr(hand.MC, name))
    MC.progress = hand.MC.progress = False
    conv.run_monte_carlo()
    hand.run_monte_carlo()
    a, b = np.asarray(conv.MC.NA, float), np.asarray(hand.MC.NA, float)
    scale = max(float(np.abs(b).max()), 1e-300)
    diff = float(np.abs(a - b).max()) / scale
    fa, fb = float(np.sum(conv.MC.absorbed_fraction)), float(np.sum(hand.MC.absorbed_fraction))
    n = hand.MC.n_photons
    detail = (f"max |NA diff| / max NA = {diff:.1e}; absorbed {fa:.5f} vs {fb:.5f} "
              f"({n} photons, seed {hand.MC.seed})")
    if diff <= 1e-9:
        return {"agrees": "identical", "detail": detail, "na_diff": diff}
    se = np.sqrt(max(fb * (1 - fb), 1e-12) / n)
    verdict = "statistically" if abs(fa - fb) <= 4 * se else "differs"
    return {"agrees": verdict, "detail": detail + f", {abs(fa - fb) / se:.1f} standard errors",
            "na_diff": diff}


# ---------------------------------------------------------------------- the report
def report(rows: list[dict], command: str, out: Path) -> None:
    from validation.reporting import write_report

    n = len(rows)
    conv = sum(r.get("converted", False) for r in rows)
    ran = sum(r.get("ran", False) for r in rows)
    same = sum(r.get("agrees") == "identical" for r in rows)
    both = sum(r.get("ran", False) and r.get("agrees") == "identical" for r in rows)
    lines = ["# MCmatlab's examples through `tissue-enkf port`", "",
             f"Command: `{command}`, with MCMATLAB_DIR (MCmatlab's git directory or checkout) in "
             "the environment.",
             "",
             f"**{conv} of {n} convert, {ran} of {n} run unchanged** at reduced size "
             "(`MCMATLAB_PY_QUICK=1`: at most 61 voxels a side, 2000 photons a run, 5 heat "
             f"updates a pulse on a 12^3 mesh); **{same}** give the hand port's numbers "
             "exactly (the converted model at the hand port's grid, photon count and seed: "
             "the same voxel map of media and the same `MC.NA` to 1e-9; seed "
             f"{SEED_IF_NONE} for both where the hand port's build() leaves the seed to its "
             "run(); Example 21 at "
             f"{'x'.join(map(str, COMPARE_GRID['ex21_custom_phase_functions']))} voxels, "
             "where its fixed voxel M(51,51,:) is the hand port's centre column); "
             f"**{both} of {n} both run unchanged and give the hand port's numbers**.", "",
             "| example | converted | ran | agrees with the hand port | what needs a hand |",
             "|---|---|---|---|---|"]
    for r in rows:
        kept = r.get("unconverted", [])
        conv_txt = ("yes" + (f", {len(kept)} line{'s' * (len(kept) != 1)} kept as comments"
                             if kept else "")) if r.get("converted") else "no"
        ran_txt = f"yes ({r.get('run_s', 0):.0f} s)" if r.get("ran") else \
            f"no: {r.get('error', '')}"
        agree = r.get("agrees", "")
        if r.get("detail") and agree != "identical":
            agree += f": {r['detail']}"
        elif agree == "identical" and "no Monte Carlo" in r.get("detail", ""):
            agree += " (the voxel map of media; the script runs no Monte Carlo)"
        needs = "; ".join(sorted({why for _, _, why in kept})) or "nothing"
        cells = [r["example"], conv_txt, ran_txt, agree, needs]
        lines.append("| " + " | ".join(c.replace("|", "\\|").replace("\n", " ") for c in cells)
                     + " |")
    lines += ["", "Lines kept as comments are listed in each converted script's docstring "
              "and by the command (`tissue-enkf port MODEL.m`); `docs/porting.md` says what "
              "converts and what needs a hand."]
    write_report(out, lines, rows)


def main(argv=None) -> int:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[2], sys.argv[3])
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcmatlab", type=Path, nargs="?",
                    default=os.environ.get("MCMATLAB_DIR") or None,
                    help="MCmatlab's git directory or checkout (default: $MCMATLAB_DIR)")
    ap.add_argument("--only", nargs="*", default=None, help="these examples (names without .m)")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per example")
    ap.add_argument("--out", type=Path, default=ROOT / "validation" / "reports" /
                    "port_examples.md")
    args = ap.parse_args(argv)
    default_out = ROOT / "validation" / "reports" / "port_examples.md"
    if args.mcmatlab is None:
        why = ("MCmatlab's files are not given (pass MCmatlab's git directory or checkout, or "
               "set MCMATLAB_DIR); they are GPL and not part of this repository")
        if Path(args.out).resolve() == default_out.resolve():
            ap.error(why)
        Path(args.out).write_text(f"# MCmatlab's examples through `tissue-enkf port`\n\nSkipped: "
                                  f"{why}.\n")
        print(f"skipped: {why}")
        return 0
    files = mcmatlab_files(Path(args.mcmatlab))
    names = args.only or list(HAND)
    bad = [n for n in names if n not in HAND]
    if bad:
        ap.error(f"--only: unknown example {bad[0]!r}")
    rows = []
    for name in names:
        row = run_one(name, files, args.timeout)
        rows.append(row)
        print(f"{name}: converted={row.get('converted')} ran={row.get('ran')} "
              f"agrees={row.get('agrees')} {row.get('error', '')}", flush=True)
    only = f" --only {' '.join(args.only)}" if args.only else ""
    report(rows, f"python validation/port_examples.py{only}", args.out)
    print(f"report: {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
