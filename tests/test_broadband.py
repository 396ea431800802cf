"""Broadband runs (arrays of ``MC.wavelength`` and ``FMC.wavelength``, MCmatlab's Example 23).

A broadband run is, by construction, monochromatic runs weighted by the spectrum: the
tests check that it is exactly that (same seeds, same photon counts), that every
wavelength's energy is accounted for, the fluorescence emitters' photon balance, and that
bad arrays and spectra are refused with the field named.
"""

import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mcmatlab_py import Medium, Model, NotBuiltError  # noqa: E402
from mcmatlab_py.fluorescence import fluorescence_emitters  # noqa: E402
from mcmatlab_py.heat import heat_source  # noqa: E402
from mcmatlab_py.monte_carlo.broadband import photon_split, wavelength_seeds  # noqa: E402

WL_X = np.array([420.0, 460.0, 500.0])  # nm, excitation
WL_F = np.array([560.0, 600.0, 640.0])  # nm, fluorescence
N_X, N_F = 3001, 2000  # photons in all (the first split unevenly: 1000, 1000, 1001)
SEED_X, SEED_F = 7, 11


def dye_mua(wl):
    return 2.0 + 15.0 * math.exp(-(((wl - 450.0) / 40.0) ** 2))


def dye_qy(wl):
    return 0.4 * math.exp(-(((wl - 460.0) / 60.0) ** 2))


def dye_es(wl):
    return math.exp(-(((wl - 600.0) / 40.0) ** 2))


def spectrum_func(wl):
    return math.exp(-(((wl - 450.0) / 50.0) ** 2))  # not normalised


def build(wavelength=WL_X, n_photons=N_X, fmc_wavelength=WL_F) -> Model:
    """A tissue slab over a dye layer, a top-hat beam; lens, far field, NI maps and MCML bins."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 8, 8, 8
    G.Lx = G.Ly = G.Lz = 0.1
    G.media = [Medium("tissue", mua=lambda wl: 1.0 + wl / 500.0, mus=lambda wl: 8e4 / wl,
                      g=0.9),
               Medium("dye", mua=dye_mua, mus=40.0, g=0.8, QY=dye_qy, ES=dye_es)]
    G.geom_func = lambda X, Y, Z: (Z > 0.05).astype(int)
    MC = model.MC
    MC.wavelength, MC.spectrum_func = wavelength, spectrum_func
    MC.n_photons_requested, MC.seed, MC.progress = n_photons, SEED_X, False
    MC.light_source.source_type, MC.light_source.radius = "tophat", 0.02
    FMC = model.FMC
    FMC.wavelength = fmc_wavelength
    FMC.n_photons_requested, FMC.seed, FMC.progress = N_F, SEED_F, False
    for sim in (MC, FMC):
        sim.calc_normalized_irradiance = True
        sim.far_field_res = 4
        sim.n_radial_bins = 5
        sim.use_light_collector = True
        LC = sim.light_collector
        LC.z, LC.f, LC.field_size, LC.diam, LC.res = -1.0, 1.0, 0.1, 0.5, 4
    return model


@pytest.fixture(scope="module")
def broadband():
    model = build().run_monte_carlo()
    return model.run_monte_carlo("fluorescence")


def _single(model, sim: str, wavelength: float, n: int, seed: int, **extra):
    """The same settings as ``model``'s ``sim`` run, at one wavelength."""
    m = build()
    s = getattr(m, sim)
    s.wavelength, s.n_photons_requested, s.seed = wavelength, int(n), int(seed)
    if sim == "MC":
        m.run_monte_carlo()
    else:
        m.MC = model.MC  # the broadband excitation
        m.run_fluorescence_monte_carlo(**extra)
    return s


MAPS = ("NA", "NFR", "NI_zneg", "NI_xpos", "far_field", "Rd_r", "Tt_a")
FRACTIONS = ("absorbed_fraction", "specular_reflectance", "killed_fraction",
             "roulette_gain_fraction")


def _check_against_monochromatic(run, singles, weights, exact=True):
    for k, (one, w) in enumerate(zip(singles, weights, strict=True)):
        if exact:  # the same floating-point operations
            np.testing.assert_array_equal(run.NA[..., k], one.NA * w)
        for name in MAPS:
            np.testing.assert_allclose(getattr(run, name)[..., k], getattr(one, name) * w,
                                       rtol=1e-12, atol=0, err_msg=name)
        np.testing.assert_allclose(run.light_collector.image[..., k],
                                   one.light_collector.image * w, rtol=1e-12)
        for name in FRACTIONS:
            assert getattr(run, name)[k] == getattr(one, name), name
        for face, v in one.escaped.items():
            assert run.escaped[face][k] == v
        assert run.n_photons_per_wavelength[k] == one.n_photons


def test_excitation_is_the_spectrum_weighted_sum_of_monochromatic_runs(broadband):
    MC = broadband.MC
    s = np.array([spectrum_func(w) for w in WL_X])
    np.testing.assert_allclose(MC.spectrum, s / s.sum(), rtol=1e-15)
    counts = photon_split(N_X, WL_X.size)
    assert counts.tolist() == [1000, 1000, 1001] and MC.n_photons == N_X
    assert MC.NA.shape == (8, 8, 8, 3) and MC.far_field.shape == (4, 4, 3)
    assert MC.light_collector.image.shape == (4, 4, 3) and MC.Rd_r.shape == (5, 3)
    seeds = wavelength_seeds(SEED_X, WL_X.size)
    singles = [_single(broadband, "MC", w, n, sd) for w, n, sd in zip(WL_X, counts, seeds,
                                                                      strict=True)]
    _check_against_monochromatic(MC, singles, MC.spectrum)
    # the media properties per wavelength, as MCmatlab's (n_media, n_wavelengths)
    np.testing.assert_allclose(MC.media_properties.mua[1], [dye_mua(w) for w in WL_X])


def test_fluorescence_is_each_wavelengths_emitters_run_alone(broadband):
    FMC = broadband.FMC
    E = FMC.source_distribution
    assert E.shape == (8, 8, 8, 3) and FMC.NA.shape == (8, 8, 8, 3)
    dV = broadband.G.dx * broadband.G.dy * broadband.G.dz
    np.testing.assert_allclose(FMC.emitted_power, E.sum(axis=(0, 1, 2)) * dV, rtol=1e-12)
    seeds = wavelength_seeds(SEED_F, WL_F.size)
    singles = [_single(broadband, "FMC", w, n, sd, emitters=E[..., j])
               for j, (w, n, sd) in enumerate(zip(WL_F, photon_split(N_F, 3), seeds,
                                                  strict=True))]
    for j, one in enumerate(singles):
        assert one.emitted_power == pytest.approx(FMC.emitted_power[j], rel=1e-12)
    # each single run is normalised to its own emitted power, as the broadband slice
    _check_against_monochromatic(FMC, singles, [1.0] * 3, exact=False)


def test_energy_is_accounted_for_at_every_wavelength(broadband):
    G, MC, FMC = broadband.G, broadband.MC, broadband.FMC
    dV, dA = G.dx * G.dy * G.dz, G.dx * G.dy
    for sim, launched in ((MC, MC.spectrum), (FMC, FMC.emitted_power)):
        np.testing.assert_allclose(sim.energy_balance, 1.0, atol=1e-9)
        # maps per W incident in all: slice k holds wavelength k's launched power's share
        np.testing.assert_allclose(sim.NA.sum(axis=(0, 1, 2)) * dV,
                                   launched * sim.absorbed_fraction, rtol=1e-9)
        np.testing.assert_allclose(sim.NI_zneg.sum(axis=(0, 1)) * dA,
                                   launched * sim.escaped["top"], rtol=1e-9)
    assert float(MC.spectrum @ MC.absorbed_fraction) == pytest.approx(MC.NA.sum() * dV,
                                                                      rel=1e-12)
    # the heat simulation heats with the sum over wavelengths, minus what fluoresces away
    np.testing.assert_allclose(heat_source(broadband), MC.NA.sum(-1) - E_total(FMC)
                               + FMC.NA.sum(-1), rtol=1e-12)


def E_total(FMC):
    return FMC.source_distribution.sum(-1)


def test_emitters_conserve_photons_and_follow_the_emission_spectrum(broadband):
    """Photons emitted = sum over excitation wavelengths of QY x photons absorbed in the dye
    (power x wavelength counts photons), spread over WL_F as ES normalised over them."""
    G, MC, FMC = broadband.G, broadband.MC, broadband.FMC
    dye = G.medium_map() == 1
    dV = G.dx * G.dy * G.dz
    absorbed = MC.NA[dye].sum(axis=0) * dV  # (3,) W per W incident, in the dye
    photons = float(np.sum(absorbed * [dye_qy(w) for w in WL_X] * WL_X))
    es = np.array([dye_es(w) for w in WL_F])
    np.testing.assert_allclose(FMC.emitted_power * WL_F, photons * es / es.sum(), rtol=1e-12)
    # one fluorescence wavelength: no spreading, the whole emission at it (MCmatlab's)
    E = fluorescence_emitters(G, MC, 600.0)
    assert E.shape == (8, 8, 8)
    assert E.sum() * dV * 600.0 == pytest.approx(photons, rel=1e-12)


def test_monochromatic_runs_are_unchanged_after_a_broadband_one(broadband):
    model = build(wavelength=460.0, n_photons=1000, fmc_wavelength=600.0)
    model.MC.seed = 3
    ref = model.run_monte_carlo().MC.NA.copy()
    model.MC.wavelength = WL_X
    model.run_monte_carlo()
    model.MC.wavelength = 460.0
    model.run_monte_carlo()
    np.testing.assert_array_equal(model.MC.NA, ref)
    assert model.MC.spectrum is None and model.MC.n_photons_per_wavelength is None
    assert np.ndim(model.MC.absorbed_fraction) == 0


def test_a_wavelength_without_power_is_not_run():
    model = build(n_photons=900)
    model.MC.spectrum_func = lambda wl: 0.0 if wl > 480 else 1.0
    for sim in (model.MC,):
        sim.use_light_collector = sim.calc_normalized_irradiance = False
        sim.far_field_res = sim.n_radial_bins = 0
    MC = model.run_monte_carlo().MC
    assert MC.spectrum.tolist() == [0.5, 0.5, 0.0]
    assert MC.n_photons_per_wavelength.tolist() == [450, 450, 0] and MC.n_photons == 900
    assert np.all(MC.NA[..., 2] == 0) and np.isnan(MC.absorbed_fraction[2])
    np.testing.assert_allclose(MC.energy_balance[:2], 1.0, atol=1e-9)


def test_broadband_figures(broadband, tmp_path):
    figs = broadband.plot("MC", tmp_path / "mc")
    assert set(figs) == {"media_properties", "NA", "NFR", "spectrum"}
    assert "summed over 3 wavelengths" in figs["NA"]._suptitle.get_text()
    figs = broadband.plot("FMC", tmp_path / "fmc")
    assert {"emitters", "NA", "NFR", "spectrum", "light_collector", "far_field",
            "NI"} <= set(figs)
    # the maps drawn are the sums over the wavelengths
    xz = figs["NFR"].axes[1].images[0].get_array().filled(np.nan)
    nfr = broadband.FMC.NFR.sum(-1)
    np.testing.assert_allclose(xz, np.where(nfr > 0, nfr, np.nan)[:, 4, :].T)
    assert (tmp_path / "fmc_spectrum.png").stat().st_size > 10_000
    plt.close("all")


@pytest.mark.parametrize("value, message", [
    ([], r"MC.wavelength must be a number or a non-empty 1-D array"),
    ([[500.0, 600.0]], r"MC.wavelength must be a number or a non-empty 1-D array"),
    ([500.0, np.nan], r"MC.wavelength\[1\] must be a finite number > 0"),
    ([500.0, -600.0], r"MC.wavelength\[1\] must be a finite number > 0"),
    ([0.0, 600.0], r"MC.wavelength\[0\] must be a finite number > 0"),
    (["red", "blue"], r"MC.wavelength must be a number or a 1-D array of numbers"),
])
def test_bad_wavelength_arrays_name_the_field(value, message):
    model = build(wavelength=value)
    with pytest.raises(ValueError, match=message):
        model.run_monte_carlo()
    model = build(wavelength=460.0, n_photons=200)
    model.run_monte_carlo()
    model.FMC.wavelength = value
    with pytest.raises(ValueError, match=message.replace("MC", "FMC", 1)):
        model.run_monte_carlo("fluorescence")


@pytest.mark.parametrize("func, message", [
    (lambda wl: -1.0, r"MC.spectrum_func\(420\) returned -1.0: the spectral power must be "
                      "finite and >= 0"),
    (lambda wl: math.nan, r"MC.spectrum_func\(420\) returned nan"),
    (lambda wl: 0.0, "MC.spectrum_func is 0 at every MC.wavelength"),
    (lambda wl: [1.0, 2.0], r"MC.spectrum_func\(420\) must return one number"),
    (3.0, "MC.spectrum_func must be a function of the wavelength"),
])
def test_bad_spectra_name_the_field(func, message):
    model = build()
    model.MC.spectrum_func = func
    with pytest.raises(ValueError, match=message):
        model.run_monte_carlo()


def test_other_refusals():
    model = build(n_photons=2)
    with pytest.raises(ValueError, match="MC.n_photons_requested = 2 is fewer than the 3"):
        model.run_monte_carlo()
    model = build()
    model.MC.n_example_paths = 2
    with pytest.raises(ValueError, match="example paths are not kept in broadband runs"):
        model.run_monte_carlo()
    model = build()
    model.G.media[0].mua = lambda wl, FR, T, FD: 1.0 + 0 * T
    with pytest.raises(NotBuiltError, match="optics depend on FR, T or FD"):
        model.run_monte_carlo()
    model = build(n_photons=300)
    model.run_monte_carlo()
    model.FMC.spectrum_func = spectrum_func
    with pytest.raises(ValueError, match="FMC.spectrum_func"):
        model.run_monte_carlo("fluorescence")
    model.FMC.spectrum_func = None
    model.G.media[1].ES = lambda wl: -1.0 if wl > 620 else 1.0
    with pytest.raises(ValueError, match=r"Medium\('dye'\).ES\(wavelength=640.0.*>= 0"):
        model.run_monte_carlo("fluorescence")
    model.G.media[1].ES = lambda wl: 0.0
    with pytest.raises(ValueError, match="ES is 0 at every FMC.wavelength"):
        model.run_monte_carlo("fluorescence")
