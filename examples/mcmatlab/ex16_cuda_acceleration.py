"""MCmatlab Example 16 (CUDAacceleration): the blood-vessel model on the CPU, then on the GPU.

The geometry and media of Example 4 (gel, epidermis, dermis and a blood vessel of radius
100 um along y; a top-hat beam of radius 300 um at 532 nm, every face escaping) on 100^3
voxels. The Monte Carlo runs for the same time first on the CPU (``MC.use_gpu = False``),
then on an NVIDIA GPU (``MC.use_gpu = True``, ``MC.gpu_device = 0``): compare the numbers
of photons each ran. MCmatlab reports 18x on a GeForce GTX 970 over an i5-6600.

    python examples/mcmatlab/ex16_cuda_acceleration.py [--quick] [--out DIR]

Without a GPU (``mcmatlab_py.monte_carlo.gpu_available()`` is False, or the ``gpu`` extra,
numba-cuda, is not installed) the second run falls back to the CPU with a printed note:
the example then compares two CPU runs. Numba's CUDA simulator
(``NUMBA_ENABLE_CUDASIM=1``) runs the GPU kernel on the CPU, but as Python threads, far too
slowly for this grid; ``tests/test_mc_gpu.py`` uses it on 8^3 voxels.

Differences from MCmatlab: the heat half of the example (``HS.useGPU``) is not here, as
the heat solver has no GPU version (``HS.use_gpu`` raises ``NotBuiltError``); Example 4
runs the same heat simulation on the CPU. ``--quick`` runs a fixed photon count on each
device instead of 0.1 min.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from ex04_blood_vessel import geometry, media  # noqa: E402  (Example 4's tissue)

from mcmatlab_py import Model  # noqa: E402
from mcmatlab_py.monte_carlo import gpu_available  # noqa: E402


def build(quick: bool = False, use_gpu: bool = False, seed: int = 16) -> Model:
    """The model of Example 16; ``quick``: 40^3 voxels and 2 x 10^4 photons per run."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 40 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = media()
    G.geom_func = geometry

    MC = model.MC
    if quick:
        MC.n_photons_requested = 20_000
    else:
        MC.simulation_time_requested = 0.1  # min, as MCmatlab
    MC.seed = seed
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    src = MC.light_source
    src.source_type = 4  # radially factorizable beam
    src.focal_plane_intensity_distribution.radial_distr = 0  # top-hat
    src.focal_plane_intensity_distribution.radial_width = 0.03  # cm
    src.angular_intensity_distribution.radial_distr = 0
    src.angular_intensity_distribution.radial_width = 0.0  # collimated
    src.x_focus = src.y_focus = src.z_focus = 0.0
    src.theta = src.phi = 0.0
    MC.use_gpu = use_gpu
    MC.gpu_device = 0  # the first GPU
    return model


def run(quick: bool = False) -> dict:
    """The CPU run, then the GPU run (the CPU again where there is no GPU, with a note).

    Returns ``{"cpu": Model, "gpu": Model, "device": str}``; ``device`` says where the
    second run ran.
    """
    cpu = build(quick, use_gpu=False, seed=16).run_monte_carlo()
    if gpu_available():
        gpu, device = build(quick, use_gpu=True, seed=17).run_monte_carlo(), "GPU"
    else:
        print("note: no CUDA GPU here (numba-cuda missing or numba.cuda.is_available() is "
              "False): the 'GPU' run falls back to the CPU kernel")
        gpu, device = build(quick, use_gpu=False, seed=17).run_monte_carlo(), "CPU (fallback)"
    return {"cpu": cpu, "gpu": gpu, "device": device}


def absorbed_z_score(result: dict) -> float:
    """|difference of the absorbed fractions of the two runs| in standard errors.

    Each packet deposits a fraction a in [0, 1] of its weight, so var(a) <= f (1 - f) for
    the mean f, and the difference of two independent runs of N1 and N2 packets has a
    standard error of at most sqrt(f (1 - f) (1/N1 + 1/N2)).
    """
    a, b = result["cpu"].MC, result["gpu"].MC
    f = 0.5 * (a.absorbed_fraction + b.absorbed_fraction)
    se = math.sqrt(f * (1.0 - f) * (1.0 / a.n_photons + 1.0 / b.n_photons))
    return abs(a.absorbed_fraction - b.absorbed_fraction) / se


def check(result: dict) -> dict:
    """The two devices agree on the absorbed fraction; both balance their energy exactly."""
    return {
        "cpu_gpu_agreement": {
            "value": absorbed_z_score(result), "expected": 0.0, "tol": 4.0,
            "what": f"|absorbed fraction CPU - {result['device']}| in standard errors"},
        "energy_balance_gpu": {
            "value": result["gpu"].MC.energy_balance, "expected": 1.0, "tol": 1e-9,
            "what": f"absorbed + escaped + the rest over launched, {result['device']} run"},
        "absorbed_fraction": {
            "value": result["gpu"].MC.absorbed_fraction, "min": 0.05, "max": 0.95,
            "what": "fraction of the beam absorbed in the cuboid"},
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    result = run(args.quick)
    for name in ("cpu", "gpu"):
        MC = result[name].MC
        where = "CPU" if name == "cpu" else result["device"]
        print(f"{where}: {MC.n_photons:.3g} photons in {MC.simulation_time:.3g} s "
              f"({MC.photons_per_second:.3g} photons/s), {100 * MC.absorbed_fraction:.3g}% "
              "absorbed in the cuboid")
    speed = result["gpu"].MC.photons_per_second / result["cpu"].MC.photons_per_second
    print(f"{result['device']} / CPU photons per second: {speed:.2f}x")
    for name, c in check(result).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    result["gpu"].plot("G", args.out / "ex16")
    result["gpu"].plot("MC", args.out / "ex16")
    print(f"figures in {args.out}")
