"""MCmatlab Example 23 (BroadbandMonteCarlo): broadband excitation and fluorescence.

The blood-vessel geometry of example 4 (air, epidermis, dermis, a blood vessel along y)
with a sphere of stained cancerous tissue in the dermis and a droplet of Lucifer Yellow
CH in water on the skin; the tissues' mua and mus follow Jacques' spectra (``calc_mua``,
``calc_mus``). A Gaussian beam (1/e^2 radius 0.3 mm) with a Gaussian spectrum
(``MC.spectrum_func``: 400 nm, 1/e half-width 40 nm) at 51 wavelengths over 300..550 nm
(``MC.wavelength`` an array) excites both fluorescers: the stain (QY a Gaussian of the
excitation wavelength around 450 nm, emission around 650 nm) and Lucifer Yellow (QY =
0.21). The fluorescence is followed at 61 wavelengths over 450..750 nm (``FMC.wavelength``).
Each wavelength's maps are a slice of ``NA`` and ``NFR`` (nx, ny, nz, n_wavelengths);
``model.plot`` draws their sums over the wavelengths and the power per wavelength.

    python examples/mcmatlab/ex23_broadband_monte_carlo.py [--quick] [--out DIR]
        [--tables MCMATLAB_DIR/helperfuncs]

Lucifer Yellow's absorption and emission are MCmatlab's omlc.org tables (PhotochemCAD
data, ``LuciferYellowCHinWater-abs.txt`` and ``-ems.txt`` in MCmatlab's ``helperfuncs``
folder, which ``tables`` names; they are not copied here), interpolated as MCmatlab's
script does. Without them, Gaussian fits stand in (absorption peak 428 nm, 1/e half-width
48 nm, 110 cm^-1 at 10 mM; emission peak 536 nm, half-width 54 nm): the excitation then
differs from MCmatlab's where Lucifer Yellow absorbs.

Differences from MCmatlab: fixed photon counts (3.06 x 10^6 excitation and 2.44 x 10^6
fluorescence packets, split over the wavelengths as MCmatlab splits them) instead of one
minute each; no lambda slider on the figures (sums over wavelengths, and a spectrum
figure).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model, calc_mua, calc_mus

Z_SURFACE = 0.02  #: cm
EPIDERMIS = 0.006  #: cm, thickness
VESSEL_RADIUS, VESSEL_DEPTH = 0.01, 0.04  #: cm (depth below the surface)
SPHERE_RADIUS = 0.01  #: cm, the stained tissue and the droplet


def geometry(X, Y, Z):
    """0 air, 1 epidermis, 2 dermis, 3 blood, 4 stained cancerous tissue, 5 Lucifer Yellow."""
    M = np.zeros(X.shape, dtype=int)
    M[Z > Z_SURFACE] = 1
    M[Z > Z_SURFACE + EPIDERMIS] = 2
    M[X**2 + (Z - (Z_SURFACE + VESSEL_DEPTH)) ** 2 < VESSEL_RADIUS**2] = 3
    M[X**2 + (Y - 0.03) ** 2 + (Z - 0.038) ** 2 < SPHERE_RADIUS**2] = 4
    M[(X**2 + (Y + 0.03) ** 2 + (Z - Z_SURFACE) ** 2 < SPHERE_RADIUS**2) & (Z < Z_SURFACE)] = 5
    return M


def spectrum(wavelength: float) -> float:
    """Spectral power of the excitation (``MC.spectrum_func``, not normalised): a Gaussian."""
    return math.exp(-(((wavelength - 400.0) / 40.0) ** 2))


def _gauss(centre: float, width: float, height: float = 1.0):
    return lambda wavelength: height * math.exp(-(((wavelength - centre) / width) ** 2))


#: MCmatlab's tables of Lucifer Yellow CH in water (in its helperfuncs folder)
ABSORPTION_TABLE = "LuciferYellowCHinWater-abs.txt"  #: nm, molar extinction cm^-1 M^-1
EMISSION_TABLE = "LuciferYellowCHinWater-ems.txt"  #: nm, emission (arbitrary units)


def lucifer_yellow(tables: str | Path | None = None):
    """(mua, ES) of Lucifer Yellow CH, functions of the wavelength (nm).

    ``tables``: the folder of MCmatlab's omlc.org tables; mua (cm^-1) is the molar
    extinction at 10 mM (divided by 100) interpolated linearly, 1e-8 outside the table and
    at least 1e-8, ES the emission interpolated, 0 outside (MCmatlab's ``interp1`` calls).
    Without ``tables``: Gaussian fits of the two.
    """
    if tables is None:
        ly_abs = _gauss(428.0, 48.0, 110.0)
        return (lambda wl: max(1e-8, ly_abs(wl))), _gauss(536.0, 54.0)
    wl_a, eps = np.loadtxt(Path(tables) / ABSORPTION_TABLE, comments="#", unpack=True)
    wl_e, em = np.loadtxt(Path(tables) / EMISSION_TABLE, comments="#", unpack=True)

    def mua(wl):
        return np.maximum(1e-8, np.interp(wl, wl_a, eps, left=1e-8, right=1e-8) / 100)

    def ES(wl):
        return np.interp(wl, wl_e, em, left=0.0, right=0.0)

    return mua, ES


def media(tables: str | Path | None = None) -> list[Medium]:
    """MCmatlab's six media; blood content B, saturation S, water W, fat F, melanin M.
    ``tables``: see :func:`lucifer_yellow`."""
    def tissue(B, S, W, M, a_prime, f_ray, extra=None):
        def mua(wl):
            base = calc_mua(wl, S, B, W, 0.0, M)
            return base + (extra(wl) if extra else 0.0)

        return mua, (lambda wl: calc_mus(wl, a_prime, f_ray, 1.0, 0.9))

    epi = tissue(0.0, 0.75, 0.75, 0.03, 40.0, 0.0)
    derm = tissue(0.002, 0.67, 0.65, 0.0, 42.4, 0.62)
    blood = tissue(1.0, 0.75, 0.95, 0.0, 10.0, 0.0)
    stained = tissue(0.002, 0.67, 0.65, 0.0, 42.4, 0.62, extra=_gauss(450.0, 50.0, 100.0))
    ly_mua, ly_es = lucifer_yellow(tables)
    return [
        Medium("air", mua=1e-8, mus=1e-8, g=1.0),
        Medium("epidermis", mua=epi[0], mus=epi[1], g=0.9),
        Medium("dermis", mua=derm[0], mus=derm[1], g=0.9),
        Medium("blood", mua=blood[0], mus=blood[1], g=0.9),
        Medium("stained cancerous tissue", mua=stained[0], mus=stained[1], g=0.9,
               QY=_gauss(450.0, 50.0, 0.1), ES=_gauss(650.0, 50.0)),
        Medium("Lucifer Yellow CH in water", mua=ly_mua, mus=10.0, g=0.9, QY=0.21, ES=ly_es),
    ]


def wavelengths(quick: bool) -> tuple[np.ndarray, np.ndarray]:
    """nm: the excitation and the fluorescence wavelengths (MCmatlab's 51 and 61)."""
    if quick:
        return np.linspace(300.0, 550.0, 3), np.linspace(450.0, 750.0, 4)
    return np.linspace(300.0, 550.0, 51), np.linspace(450.0, 750.0, 61)


def build(quick: bool = False, tables: str | Path | None = None) -> Model:
    """The model of Example 23; ``quick``: 24^3 voxels, 3 and 4 wavelengths, few photons.
    ``tables``: MCmatlab's helperfuncs folder (:func:`lucifer_yellow`)."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 24 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = media(tables)
    G.geom_func = geometry
    wl_x, wl_f = wavelengths(quick)
    MC, FMC = model.MC, model.FMC
    MC.wavelength, MC.spectrum_func = wl_x, spectrum
    FMC.wavelength = wl_f
    # photons in all, split equally over the wavelengths (60000 and 40000 each at full size)
    MC.n_photons_requested = 12_000 if quick else 60_000 * wl_x.size
    FMC.n_photons_requested = 12_000 if quick else 40_000 * wl_f.size
    for sim, seed in ((MC, 1), (FMC, 1001)):
        sim.seed = seed
        sim.progress = not quick
        sim.matched_interfaces = True
        sim.boundary_type = 1
    src = MC.light_source
    src.source_type = 4  # radial-factorizable beam
    src.focal_plane_intensity_distribution.radial_distr = 1  # Gaussian
    src.focal_plane_intensity_distribution.radial_width = 0.03  # cm, 1/e^2 radius
    src.angular_intensity_distribution.radial_distr = 0  # top-hat of zero width: collimated
    src.angular_intensity_distribution.radial_width = 0.0
    src.x_focus = src.y_focus = src.z_focus = 0.0
    src.theta = src.phi = 0.0
    return model


def run(quick: bool = False, tables: str | Path | None = None) -> Model:
    """The broadband excitation, then the broadband fluorescence (MCmatlab's two calls)."""
    model = build(quick, tables).run_monte_carlo()
    return model.run_monte_carlo("fluorescence")


def mirror_z_score(model) -> float:
    """|fluorescence absorbed at x > 0 - at x < 0|, summed over the fluorescence wavelengths,
    in standard errors. Geometry and beam are symmetric under x -> -x.

    Fluorescence wavelength j launches P_j (W per W incident) in N_j packets: its difference
    has standard error at most P_j sqrt(A_j / N_j) (a packet's share on either side lies in
    [0, 1], A_j its absorbed fraction). The excitation adds the emitters' own imbalance: a
    packet of excitation wavelength k (share s_k, N_k packets) absorbs a_p in [0, 1] in the
    fluorescers and emits at most c_k a_p there, c_k = max QY(lambda_k) lambda_k / min
    lambda_f, so that imbalance has variance at most s_k c_k^2 F_k / N_k (F_k = s_k E[a_p],
    the absorbed power in the fluorescers, W/W incident); at most all of it is absorbed
    again."""
    G, MC, FMC = model.G, model.MC, model.FMC
    dV = G.dx * G.dy * G.dz
    right, left = G.x > 1e-12, G.x < -1e-12
    diff, var = 0.0, 0.0
    for j in range(FMC.wavelength.size):
        a = FMC.NA[..., j] * dV
        diff += a[right].sum() - a[left].sum()
        var += (FMC.emitted_power[j] ** 2 * FMC.absorbed_fraction[j]
                / FMC.n_photons_per_wavelength[j])
    M = G.medium_map()
    fluorescers = [i for i, m in enumerate(G.media) if m.QY is not None]
    in_fl = np.isin(M, fluorescers)
    for k, wl in enumerate(MC.wavelength):
        c = max(G.media[i].value("QY", wl) for i in fluorescers) * wl / FMC.wavelength.min()
        F = MC.NA[..., k][in_fl].sum() * dV
        var += MC.spectrum[k] * c**2 * F / MC.n_photons_per_wavelength[k]
    return abs(diff) / math.sqrt(var)


def check(model) -> dict:
    """Every wavelength's energy balance, and the x-mirror symmetry of the fluorescence."""
    balances = np.concatenate([model.MC.energy_balance, model.FMC.energy_balance])
    return {
        "energy_balance": {
            "value": float(np.max(np.abs(balances - 1.0))), "expected": 0.0, "tol": 1e-9,
            "what": "largest |balance - 1| over the excitation and fluorescence wavelengths"},
        "fluorescence_mirror_symmetry": {
            "value": mirror_z_score(model), "expected": 0.0, "tol": 4.0,
            "what": "|fluorescence absorbed x > 0 - x < 0| in standard errors (bound)"},
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    ap.add_argument("--tables", type=Path, default=None,
                    help="MCmatlab's helperfuncs folder, for Lucifer Yellow's omlc.org tables "
                         "(default: Gaussian fits)")
    args = ap.parse_args()
    model = run(args.quick, args.tables)
    G, MC, FMC = model.G, model.MC, model.FMC
    dV = G.dx * G.dy * G.dz
    absorbed = MC.NA.sum() * dV  # W per W incident, all wavelengths
    emitted = FMC.source_distribution.sum() * dV
    print(f"{100 * absorbed:.3g}% of incident light was absorbed within the cuboid")
    print(f"{100 * emitted / absorbed:.3g}% of absorbed incident light was re-emitted as "
          "fluorescence")
    print(f"{100 * FMC.NA.sum() * dV / emitted:.3g}% of fluorescence light was absorbed "
          "within the cuboid")
    print(f"{MC.n_photons} excitation packets in {MC.simulation_time:.1f} s, "
          f"{FMC.n_photons} fluorescence packets in {FMC.simulation_time:.1f} s")
    for name, c in check(model).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model.plot("G", args.out / "ex23")
    model.plot("MC", args.out / "ex23")  # media properties over wavelength, NA, NFR, spectrum
    model.plot("FMC", args.out / "ex23_FMC")  # emitters, NA, NFR, spectrum
    print(f"figures in {args.out}")
