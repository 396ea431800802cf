"""MCmatlab Example 19 (DepositionCriteria): the absorption of light scattered exactly once.

A pencil beam along +z through the middle of a 1 x 1 x 1.5 mm block: 0.3 mm of air on a
tissue with mua = 1, mus = 10 cm^-1, g = 0 (isotropic scattering), 532 nm, every face
escaping. ``deposition_criteria`` with min = max = 1 scatterings, judged at every deposit
(``evaluate_only_at_end_of_life = False``), keeps in ``NA`` and ``NFR`` only what the
packets lose between their first and second scattering: a halo about one mean free
path (0.9 mm) wide around the beam, densest next to it. 25 example paths are drawn.

    python examples/mcmatlab/ex19_deposition_criteria.py [--quick] [--out DIR]

The check compares the absorbed fraction with an independent calculation of the same
quantity (:func:`single_scattering_absorption`).

Differences from MCmatlab: a fixed photon count instead of
``simulationTimeRequested = 0.1`` min; the example paths are drawn by matplotlib.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model
from mcmatlab_py.light.collector import DepositionCriteria

Z_SURFACE = 0.03  #: cm, the tissue surface under the air
MUA, MUS = 1.0, 10.0  #: cm^-1, the tissue


def geometry(X, Y, Z):
    """0: air above ``Z_SURFACE``, 1: the tissue below."""
    return np.where(Z > Z_SURFACE, 1, 0)


def build(quick: bool = False) -> Model:
    """The model of Example 19; ``quick``: 21 x 21 x 30 voxels and 10^5 photons."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = (21, 21, 30) if quick else (101, 101, 150)
    G.Lx, G.Ly, G.Lz = 0.1, 0.1, 0.15  # cm
    G.media = [Medium("air", mua=1e-8, mus=1e-8, g=1.0),
               Medium("standard tissue", mua=MUA, mus=MUS, g=0.0)]
    G.geom_func = geometry

    MC = model.MC
    MC.n_photons_requested = 100_000 if quick else 3_000_000
    MC.seed = 19
    MC.progress = not quick
    MC.matched_interfaces = True
    MC.boundary_type = 1
    MC.wavelength = 532  # nm
    src = MC.light_source
    src.source_type = 0  # pencil beam
    src.x_focus, src.y_focus, src.z_focus = 0.0, 0.0, G.Lz / 2
    MC.n_example_paths = 25
    MC.deposition_criteria = DepositionCriteria(min_scatterings=1, max_scatterings=1,
                                                evaluate_only_at_end_of_life=False)
    return model


def run(quick: bool = False) -> Model:
    """Build and run the Monte Carlo of Example 19."""
    return build(quick).run_monte_carlo()


def single_scattering_absorption(G, n: int = 1_000_000, seed: int = 0) -> tuple[float, float]:
    """The absorbed fraction between the first and second scattering, and its error.

    The kernel removes ``w mua / mut`` at each interaction (implicit capture) and then
    scatters, so the weight that deposits with exactly one scattering so far is that of
    the second interaction, ``a (1 - a)`` with albedo complement ``a = mua / mut``,
    provided the packet's first interaction lies in the tissue (depth ``Z_SURFACE + s1``,
    ``s1 ~ Exp(mut)``, on the axis) and its second one too: after an isotropic
    scattering it flies a distance ``Exp(mut)``, which must stay inside the tissue box
    (air above has no interactions to speak of). Given the first point and the
    direction, that probability is ``1 - exp(-mut L)``, L the distance to the box's
    boundary: averaged here over ``n`` sampled first points and directions (numpy,
    independent of the kernel). Returns (fraction, its standard error).
    """
    rng = np.random.default_rng(seed)
    mut = MUA + MUS
    a = MUA / mut
    z1 = Z_SURFACE + rng.exponential(1 / mut, n)
    inside = z1 < G.Lz
    cos_t = rng.uniform(-1, 1, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    sin_t = np.sqrt(1 - cos_t**2)
    u = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t])
    with np.errstate(divide="ignore"):
        dx = np.where(u[0] != 0, (G.Lx / 2) / np.abs(u[0]), np.inf)
        dy = np.where(u[1] != 0, (G.Ly / 2) / np.abs(u[1]), np.inf)
        dz = np.where(u[2] > 0, (G.Lz - z1) / u[2], np.where(u[2] < 0, (Z_SURFACE - z1) / u[2], np.inf))
    L = np.minimum(np.minimum(dx, dy), dz)
    p = np.where(inside, 1 - np.exp(-mut * np.maximum(L, 0)), 0.0)
    return a * (1 - a) * float(p.mean()), a * (1 - a) * float(p.std() / math.sqrt(n))


def check(model) -> dict:
    """The absorbed fraction under the criteria against :func:`single_scattering_absorption`.

    A packet deposits either 0 or ``a (1 - a)`` under these criteria, so the standard error
    of the kernel's fraction F over N packets is ``sqrt(F (a (1 - a) - F) / N)``; with that of
    the independent calculation in quadrature, within 4 of them. Depositing the first
    interaction's weight too (no criteria) would double-count about 0.08 of the incident
    power; depositing along the path instead of at interactions would change F as well.
    """
    G, MC = model.G, model.MC
    expected, se_ref = single_scattering_absorption(model.G)
    w = (MUA / (MUA + MUS)) * (MUS / (MUA + MUS))
    F = float(MC.NA.sum() * G.dx * G.dy * G.dz)  # absorbed_fraction also holds the excluded
    se = math.hypot(math.sqrt(max(F * (w - F), 0.0) / MC.n_photons), se_ref)
    return {
        "single_scattering_absorption": {
            "value": F, "expected": expected, "tol": 4 * se,
            "what": "absorbed fraction with exactly one scattering, against the independent "
                    "calculation (4 standard errors)"},
        "energy_balance": {
            "value": MC.energy_balance, "expected": 1.0, "tol": 1e-9,
            "what": "absorbed (deposited or not) + escaped + the rest (exact per packet)"},
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    from mcmatlab_py.plotting.outputs import plot_example_paths

    model = run(args.quick)
    G = model.G
    print(f"{100 * model.MC.NA.sum() * G.dx * G.dy * G.dz:.3g}% of the incident light was "
          "absorbed between the first and second scattering")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex19")
    model.plot("MC", args.out / "ex19")
    plot_example_paths(model).savefig(args.out / "ex19_paths.png", dpi=100)
    print(f"figures in {args.out}")
