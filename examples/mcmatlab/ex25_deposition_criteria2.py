"""MCmatlab Example 25 (DepositionCriteria2): the light that has been in a blood vessel.

The skin of Example 4 under water: water (mua = 3.6e-4, mus = 10 cm^-1, g = 1) down to
0.1 mm, 60 um of epidermis, dermis below, and a blood vessel of radius 0.1 mm along y,
0.4 mm below the water surface; their optical properties at 532 nm come from MCmatlab's
spectral functions (:func:`mcmatlab_py.calc_mua`, :func:`mcmatlab_py.calc_mus`, with
the chromophore fractions of MCmatlab's script). A top-hat beam of radius 0.3 mm falls
straight down. ``deposition_criteria`` with at least one interface transition into the
blood (medium 3 here, 4 in MCmatlab's 1-based count), judged at every deposit
(``evaluate_only_at_end_of_life = False``), keeps in ``NA`` only what packets lose
after they have entered the vessel: the light "coming out of" the vessel. 100
example paths are drawn.

    python examples/mcmatlab/ex25_deposition_criteria2.py [--quick] [--out DIR]

The check runs the model again with the same seed and criteria that every deposit meets
(no transition required): the criteria draw no random numbers, and any criteria make each
medium its own kind for the kernel's navigation (no delta tracking across the transitions
they count), so the packets take the same paths.

Differences from MCmatlab: a fixed photon count instead of
``simulationTimeRequested = 0.1`` min; medium indices are 0-based
(``min_medium_idx_to_consider = 3``); the thermal properties (VHC, TC, E, A) of
MCmatlab's media are left out, as this example runs no heat simulation.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mcmatlab_py import IntensityDistribution, Medium, Model, calc_mua, calc_mus
from mcmatlab_py.light.collector import DepositionCriteria

Z_SURFACE = 0.01  #: cm, the skin surface under the water
EPIDERMIS = 0.006  #: cm, epidermis thickness
VESSEL_RADIUS = 0.01  #: cm
VESSEL_DEPTH = 0.04  #: cm, of the vessel axis below Z_SURFACE
BLOOD = 3  #: index of blood in G.media


def geometry(X, Y, Z):
    """0: water, 1: epidermis, 2: dermis, 3: the blood vessel along y."""
    M = np.zeros(X.shape, dtype=int)
    M[Z > Z_SURFACE] = 1
    M[Z > Z_SURFACE + EPIDERMIS] = 2
    M[X**2 + (Z - (Z_SURFACE + VESSEL_DEPTH)) ** 2 < VESSEL_RADIUS**2] = BLOOD
    return M


def media() -> list[Medium]:
    """MCmatlab's water, epidermis, dermis and blood, functions of the wavelength (nm)."""
    return [
        Medium("water", mua=0.00036, mus=10.0, g=1.0),
        Medium("epidermis", mua=lambda wl: calc_mua(wl, S=0.75, B=0, W=0.75, F=0, M=0.03),
               mus=lambda wl: calc_mus(wl, 40, 0, 1, 0.9), g=0.9),
        Medium("dermis", mua=lambda wl: calc_mua(wl, S=0.67, B=0.002, W=0.65, F=0, M=0),
               mus=lambda wl: calc_mus(wl, 42.4, 0.62, 1, 0.9), g=0.9),
        Medium("blood", mua=lambda wl: calc_mua(wl, S=0.75, B=1, W=0.95, F=0, M=0),
               mus=lambda wl: calc_mus(wl, 10, 0, 1, 0.9), g=0.9),
    ]


def build(quick: bool = False) -> Model:
    """The model of Example 25; ``quick``: 40^3 voxels and 2 x 10^4 photons."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 40 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = media()
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 20_000 if quick else 1_000_000
    MC.seed = 25
    MC.progress = not quick
    MC.n_example_paths = 100
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    src = MC.light_source
    src.source_type = 4  # radial-factorizable beam
    src.focal_plane_intensity_distribution = IntensityDistribution(radial_distr=0,
                                                                   radial_width=0.03)
    src.angular_intensity_distribution = IntensityDistribution(radial_distr=0, radial_width=0.0)
    src.x_focus = src.y_focus = src.z_focus = 0.0
    MC.deposition_criteria = DepositionCriteria(
        min_interface_transitions=1, min_medium_idx_to_consider=BLOOD,
        max_medium_idx_to_consider=BLOOD, evaluate_only_at_end_of_life=False)
    return model


def run(quick: bool = False) -> dict:
    """``{"model": with the criteria, "all": the same run with criteria every deposit
    meets}``."""
    model = build(quick).run_monte_carlo()
    plain = build(quick)
    plain.MC.deposition_criteria = DepositionCriteria(
        min_medium_idx_to_consider=BLOOD, max_medium_idx_to_consider=BLOOD,
        evaluate_only_at_end_of_life=False)
    plain.MC.n_example_paths = 0
    return {"model": model, "all": plain.run_monte_carlo()}


def check(result: dict) -> dict:
    """Against the run whose criteria keep every deposit (same seed, same paths):

    * inside the vessel every deposit comes from a packet that entered it (packets start
      in the water), so the two ``NA`` agree there: largest relative difference < 1e-9;
    * outside the vessel they keep only what packets lose after leaving it: some, but
      a small part, as most of the beam never reaches the vessel (0.2 mm wide, 0.4 mm
      deep, under a beam 0.6 mm wide): the kept fraction of the absorption outside the
      vessel lies in [1e-4, 0.5] (0.65% in the quick run;
      1 would mean the criteria were ignored, 0 that nothing is kept after leaving).
    """
    model, plain = result["model"], result["all"]
    blood = model.MC.M == BLOOD
    a, b = model.MC.NA, plain.MC.NA
    inside = float(np.max(np.abs(a[blood] - b[blood])) / np.max(b[blood]))
    kept = float(a[~blood].sum() / b[~blood].sum())
    return {
        "vessel_unchanged": {
            "value": inside, "expected": 0.0, "tol": 1e-9,
            "what": "max |NA(criteria) - NA(all)| in the vessel, over max NA there"},
        "kept_outside": {
            "value": kept, "min": 1e-4, "max": 0.5,
            "what": "absorption outside the vessel kept by the criteria, fraction"},
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    from mcmatlab_py.plotting.outputs import plot_example_paths

    result = run(args.quick)
    for name, c in check(result).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    model = result["model"]
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex25")
    model.plot("MC", args.out / "ex25")
    plot_example_paths(model).savefig(args.out / "ex25_paths.png", dpi=100)
    print(f"figures in {args.out}")
