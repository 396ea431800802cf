"""MCmatlab Example 23 (BroadbandMonteCarlo): broadband excitation and fluorescence.

The blood-vessel geometry of example 4 (air, epidermis, dermis, a blood vessel along y)
with a sphere of stained cancerous tissue in the dermis and a droplet of Lucifer Yellow
CH in water on the skin; the tissues' mua and mus follow Jacques' spectra (``calc_mua``,
``calc_mus``). A Gaussian beam (1/e^2 radius 0.3 mm) with a Gaussian spectrum (400 nm,
1/e half-width 40 nm) over 300..550 nm excites both fluorescers: the stain (QY a Gaussian
of the excitation wavelength around 450 nm, emission around 650 nm) and Lucifer Yellow
(QY = 0.21). The fluorescence is followed over 450..750 nm.

    python examples/mcmatlab/ex23_broadband_monte_carlo.py [--quick] [--out DIR]

Differences from MCmatlab: arrays of wavelengths (``MC.wavelength``, ``FMC.wavelength``)
are not built in ``mcmatlab_py``; light transport being linear, the script sums
monochromatic runs, as MCmatlab does inside: one excitation run per wavelength weighted by
the normalised spectrum, the fluorescence emitters of each run (``fluorescence_emitters``)
summed with each medium's emission spectrum normalised over the fluorescence wavelengths,
then one fluorescence run per fluorescence wavelength (``run_fluorescence_monte_carlo(
emitters=...)``). Full size: 11 excitation and 7 fluorescence wavelengths (MCmatlab: 51 and
61) and fixed photon counts instead of one minute each. Lucifer Yellow's absorption and
emission, which MCmatlab reads from omlc.org tables, are Gaussians here (absorption peak
428 nm, 1/e half-width 48 nm, 110 cm^-1 at 10 mM; emission peak 536 nm, half-width 54 nm).
The figures show the sums over wavelengths and the emitted fluorescence spectrum.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mcmatlab_py import Medium, Model, calc_mua, calc_mus
from mcmatlab_py.fluorescence import fluorescence_emitters

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


def spectrum(wavelength):
    """Spectral power of the excitation (not normalised): a Gaussian at 400 nm."""
    return np.exp(-((np.asarray(wavelength) - 400.0) / 40.0) ** 2)


def _gauss(centre: float, width: float, height: float = 1.0):
    return lambda wavelength: height * math.exp(-(((wavelength - centre) / width) ** 2))


def media() -> list[Medium]:
    """MCmatlab's six media; blood content B, saturation S, water W, fat F, melanin M."""
    def tissue(B, S, W, M, a_prime, f_ray, extra=None):
        def mua(wl):
            base = calc_mua(wl, S, B, W, 0.0, M)
            return base + (extra(wl) if extra else 0.0)

        return mua, (lambda wl: calc_mus(wl, a_prime, f_ray, 1.0, 0.9))

    epi = tissue(0.0, 0.75, 0.75, 0.03, 40.0, 0.0)
    derm = tissue(0.002, 0.67, 0.65, 0.0, 42.4, 0.62)
    blood = tissue(1.0, 0.75, 0.95, 0.0, 10.0, 0.0)
    stained = tissue(0.002, 0.67, 0.65, 0.0, 42.4, 0.62, extra=_gauss(450.0, 50.0, 100.0))
    ly_abs = _gauss(428.0, 48.0, 110.0)
    return [
        Medium("air", mua=1e-8, mus=1e-8, g=1.0),
        Medium("epidermis", mua=epi[0], mus=epi[1], g=0.9),
        Medium("dermis", mua=derm[0], mus=derm[1], g=0.9),
        Medium("blood", mua=blood[0], mus=blood[1], g=0.9),
        Medium("stained cancerous tissue", mua=stained[0], mus=stained[1], g=0.9,
               QY=_gauss(450.0, 50.0, 0.1), ES=_gauss(650.0, 50.0)),
        Medium("Lucifer Yellow CH in water", mua=lambda wl: max(1e-8, ly_abs(wl)), mus=10.0,
               g=0.9, QY=0.21, ES=_gauss(536.0, 54.0)),
    ]


def wavelengths(quick: bool) -> tuple[np.ndarray, np.ndarray]:
    """nm: the excitation and the fluorescence wavelengths simulated."""
    if quick:
        return np.array([380.0, 430.0]), np.array([540.0, 650.0])
    return np.linspace(300.0, 550.0, 11), np.linspace(450.0, 750.0, 7)


def build(quick: bool = False) -> Model:
    """The model of Example 23 (wavelengths set by ``run``); ``quick``: 24^3 voxels."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 24 if quick else 100
    G.Lx = G.Ly = G.Lz = 0.1  # cm
    G.media = media()
    G.geom_func = geometry
    for sim, seed in ((model.MC, 1), (model.FMC, 1001)):
        sim.n_photons_requested = 4_000 if quick else 200_000  # per wavelength
        sim.seed = seed
        sim.progress = not quick
        sim.matched_interfaces = True
        sim.boundary_type = 1
    src = model.MC.light_source
    src.source_type = 4  # radial-factorizable beam
    src.focal_plane_intensity_distribution.radial_distr = 1  # Gaussian
    src.focal_plane_intensity_distribution.radial_width = 0.03  # cm, 1/e^2 radius
    src.angular_intensity_distribution.radial_distr = 0  # top-hat of zero width: collimated
    src.angular_intensity_distribution.radial_width = 0.0
    src.x_focus = src.y_focus = src.z_focus = 0.0
    src.theta = src.phi = 0.0
    return model


def _es_weights(model, wl_f: np.ndarray) -> np.ndarray:
    """(n_media, n_f) each medium's emission spectrum normalised over ``wl_f`` (no ES: flat)."""
    out = np.full((len(model.G.media), wl_f.size), 1.0 / wl_f.size)
    for i, m in enumerate(model.G.media):
        if m.ES is not None:
            es = np.array([m.value("ES", w) for w in wl_f])
            out[i] = es / es.sum()
    return out


def run(quick: bool = False) -> dict:
    """Excitation runs over the spectrum, then fluorescence runs over the emission band."""
    model = build(quick)
    G, M = model.G, model.G.medium_map()
    wl_x, wl_f = wavelengths(quick)
    s = spectrum(wl_x) / spectrum(wl_x).sum()  # W per W incident at each wavelength
    es_map = _es_weights(model, wl_f)[M]  # (nx, ny, nz, n_f)
    NA = np.zeros(M.shape)
    emitters = np.zeros((*M.shape, wl_f.size))
    balances, absorbed = [], []
    emitter_var = 0.0  # bound on the variance of the emitters' x-imbalance, see mirror_z_score
    for k, (wl, weight) in enumerate(zip(wl_x, s, strict=True)):
        model.MC.wavelength = wl
        model.MC.seed = 1 + k
        model.run_monte_carlo()
        balances.append(model.MC.energy_balance)
        absorbed.append(model.MC.absorbed_fraction)
        NA += weight * model.MC.NA
        c_max = max(m.value("QY", wl) for m in G.media if m.QY is not None) * wl / wl_f.min()
        emitted = 0.0  # W of fluorescence per W of this run
        for j, wf in enumerate(wl_f):
            E = fluorescence_emitters(G, model.MC, wf, M) * es_map[..., j]
            emitted += E.sum() * G.dx * G.dy * G.dz
            emitters[..., j] += weight * E
        emitter_var += weight**2 * c_max * emitted / model.MC.n_photons
    fmc = []
    for j, wf in enumerate(wl_f):
        model.FMC.wavelength = wf
        model.FMC.seed = 1001 + j
        model.run_fluorescence_monte_carlo(emitters=emitters[..., j])
        F = model.FMC
        fmc.append({"wavelength": wf, "emitted_power": F.emitted_power, "NA": F.NA,
                    "NFR": F.NFR, "absorbed_fraction": F.absorbed_fraction,
                    "n_photons": F.n_photons, "energy_balance": F.energy_balance})
        balances.append(F.energy_balance)
    return {"model": model, "excitation_wavelengths": wl_x, "spectrum": s, "NA": NA,
            "absorbed_fractions": np.array(absorbed), "emitters": emitters.sum(axis=-1),
            "fluorescence": fmc, "energy_balances": np.array(balances),
            "emitter_var": emitter_var}


def mirror_z_score(result) -> float:
    """|fluorescence absorbed at x > 0 - at x < 0|, summed over the fluorescence runs, in
    standard errors. Geometry and beam are symmetric under x -> -x. Each run launching P
    (W per W incident) adds a difference with standard error at most P sqrt(f / N) (a
    packet's share on either side lies in [0, 1]). The excitation runs' imbalance of the
    emitters adds its own: a packet of run k makes fluorescence d in [0, c_k], c_k = max
    QY(lambda_k) lambda_k / min lambda_f, so E[d^2] <= c_k E[d] = c_k e_k (e_k: emitted per
    W of run k), and the variance is at most the sum of s_k^2 c_k e_k / N (``emitter_var``);
    at most all of the imbalance is absorbed again."""
    G = result["model"].G
    dV = G.dx * G.dy * G.dz
    diff, var = 0.0, 0.0
    for r in result["fluorescence"]:
        a = r["NA"] * dV
        diff += a[G.x > 1e-12].sum() - a[G.x < -1e-12].sum()
        var += r["emitted_power"] ** 2 * r["absorbed_fraction"] / r["n_photons"]
    var += result["emitter_var"]
    return abs(diff) / math.sqrt(var)


def check(result) -> dict:
    """Every run's energy balance, and the x-mirror symmetry of the summed fluorescence."""
    return {
        "energy_balance": {
            "value": float(np.max(np.abs(result["energy_balances"] - 1.0))), "expected": 0.0,
            "tol": 1e-9, "what": "largest |balance - 1| over all excitation and fluorescence runs"},
        "fluorescence_mirror_symmetry": {
            "value": mirror_z_score(result), "expected": 0.0, "tol": 4.0,
            "what": "|fluorescence absorbed x > 0 - x < 0| in standard errors (bound)"},
    }


def spectra_figure(result):
    """The excitation spectrum and the emitted fluorescence spectrum (W per W incident)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.6), layout="constrained")
    wl_x = result["excitation_wavelengths"]
    ax.plot(wl_x, result["spectrum"], "o-", label="excitation (incident, W/W)")
    ax.plot(wl_x, result["spectrum"] * result["absorbed_fractions"], "s-",
            label="excitation absorbed in the cuboid (W/W)")
    fl = result["fluorescence"]
    ax.plot([r["wavelength"] for r in fl], [r["emitted_power"] for r in fl], "^-",
            label="fluorescence emitted (W/W incident)")
    ax.set(xlabel="wavelength [nm]", ylabel="power per simulated wavelength", yscale="log",
           title="Broadband excitation and fluorescence")
    ax.grid(True, alpha=0.4)
    ax.legend(loc="best", fontsize=8)
    return fig


def sums_figure(result):
    """Slices of the broadband NFR of the excitation and of the fluorescence."""
    import matplotlib.pyplot as plt

    from mcmatlab_py.plotting.figures import positive_log_norm
    from mcmatlab_py.plotting.slices import orthogonal_slices

    G = result["model"].G
    fig = plt.figure(figsize=(10, 6.6), layout="constrained")
    top, bottom = fig.subfigures(2, 1)
    for sub, data, title in (
            (top, result["NA"], "Excitation: NA summed over wavelengths [W/cm$^3$/W]"),
            (bottom, sum(r["NA"] for r in result["fluorescence"]),
             "Fluorescence: NA summed over wavelengths [W/cm$^3$/W incident]")):
        orthogonal_slices(sub, np.where(data > 0, data, np.nan), G, (0.5, 0.2, 0.4),
                          cmap="inferno", norm=positive_log_norm(data), label="NA",
                          title=title)
    return fig


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid, few photons (seconds)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out",
                    help="folder for the figures (default: examples/mcmatlab/out)")
    args = ap.parse_args()
    result = run(args.quick)
    s, f = result["spectrum"], result["absorbed_fractions"]
    print(f"{100 * float(s @ f):.3g}% of the incident light was absorbed within the cuboid")
    emitted = sum(r["emitted_power"] for r in result["fluorescence"])
    print(f"{100 * emitted / float(s @ f):.3g}% of the absorbed incident light was re-emitted "
          "as fluorescence")
    for name, c in check(result).items():
        print(f"{name}: {c['value']:.6g} ({c['what']})")
    args.out.mkdir(parents=True, exist_ok=True)
    model = result["model"]
    model.plot("G", args.out / "ex23")
    spectra_figure(result).savefig(args.out / "ex23_spectra.png", dpi=100)
    sums_figure(result).savefig(args.out / "ex23_NA.png", dpi=100)
    print(f"figures in {args.out}")
