"""Media as MCmatlab defines them: numbers or functions of wavelength and of (FR, T, FD),
the binning into sub-media, and the spectral library against its published sources."""

import math

import numpy as np
import pytest

from mcmatlab_py import Medium, Model, NotBuiltError
from mcmatlab_py.geometry import spectra
from mcmatlab_py.geometry.media_bins import (
    farthest_point_bins,
    optical_media_properties,
    thermal_media_properties,
)
from mcmatlab_py.monte_carlo import optical_arrays

# ------------------------------------------------------------------ spectral library

# S. Prahl's tabulated molar extinction coefficients (cm^-1/M) of haemoglobin in water
PRAHL = {  # nm: (HbO2, Hb)
    550: (43016.0, 53412.0),
    660: (319.6, 3226.56),
    800: (816.0, 761.72),
}

# G. M. Hale and M. R. Querry, Appl. Opt. 12, 555 (1973), Table I: imaginary index k of water
HALE_QUERRY_K = {400: 1.86e-9, 500: 1.00e-9, 600: 1.09e-8, 700: 3.35e-8, 800: 1.25e-7,
                 900: 4.86e-7, 950: 2.93e-6, 975: 3.48e-6, 1000: 2.89e-6}


@pytest.mark.parametrize("wavelength", sorted(PRAHL))
def test_haemoglobin_is_prahls_compilation(wavelength):
    oxy, deoxy = PRAHL[wavelength]
    # the table holds ln(10) e 150 / 64500 in double precision: e comes back to rounding
    assert spectra.hb_molar_extinction(wavelength) == pytest.approx(oxy, rel=1e-12)
    assert spectra.hb_molar_extinction(wavelength, oxygenated=False) == pytest.approx(deoxy,
                                                                                      rel=1e-12)
    assert spectra.absorption("oxy_blood", wavelength) == pytest.approx(
        math.log(10) * oxy * 150 / 64500, rel=1e-12)


@pytest.mark.parametrize("wavelength", sorted(HALE_QUERRY_K))
def test_water_is_hale_and_querry_to_two_digits(wavelength):
    expected = 4 * math.pi * HALE_QUERRY_K[wavelength] / (wavelength * 1e-7)  # cm^-1
    # the library keeps two significant digits: half a unit of the second digit
    bound = 0.5 * 10 ** (math.floor(math.log10(expected)) - 1)
    assert abs(spectra.absorption("water", wavelength) - expected) <= bound


def test_melanin_column_is_jacques_power_law_and_interpolation_is_linear():
    t = spectra.spectral_table()
    lam = t["wavelength_nm"]
    # tabulated with the 500 nm value rounded to 679.16 cm^-1 (6.6e11 * 500^-3.33 = 679.1627)
    np.testing.assert_allclose(t["mua_melanin"], 679.16 * (lam / 500) ** -3.33, rtol=1e-13)
    np.testing.assert_allclose(t["mua_melanin"], spectra.melanin_power_law(lam), rtol=5e-6)
    # between the 1 nm points: linear, as MATLAB's interp1
    a, b = spectra.absorption("melanin", [633.0, 634.0])
    assert spectra.absorption("melanin", 633.25) == pytest.approx(0.75 * a + 0.25 * b, rel=1e-14)
    # the 930 nm lipid band is the only structure of the fat column
    assert spectra.absorption("fat", 930) > 100 * spectra.absorption("fat", 700)


def test_calc_mua_is_jacques_eq_12():
    lam = np.array([450.0, 600.0, 850.0])
    S, B, W, F, M = 0.7, 0.02, 0.65, 0.1, 0.01
    expected = (B * S * spectra.absorption("oxy_blood", lam)
                + B * (1 - S) * spectra.absorption("deoxy_blood", lam)
                + W * spectra.absorption("water", lam) + F * spectra.absorption("fat", lam)
                + M * spectra.absorption("melanin", lam))
    np.testing.assert_allclose(spectra.calc_mua(lam, S, B, W, F, M), expected, rtol=1e-14)
    assert spectra.calc_mua(550, 1, 1, 0, 0, 0) == spectra.absorption("oxy_blood", 550)


def test_calc_mus_is_the_scattering_power_law():
    # at 500 nm mus' is a'; pure Rayleigh falls as lambda^-4, pure Mie as lambda^-b
    assert spectra.reduced_scattering(500, 42.0, 0.3, 1.2) == pytest.approx(42.0, rel=1e-15)
    assert spectra.reduced_scattering(1000, 16.0, 1.0, 1.2) == pytest.approx(1.0, rel=1e-15)
    assert spectra.reduced_scattering(250, 10.0, 0.0, 1.5) == pytest.approx(10 * 2**1.5)
    assert spectra.calc_mus(700, 20.0, 0.4, 1.1, 0.9) == pytest.approx(
        spectra.reduced_scattering(700, 20.0, 0.4, 1.1) / 0.1, rel=1e-14)


@pytest.mark.parametrize("call, message", [
    (lambda: spectra.absorption("water", 250), "wavelength must be in \\[300, 1000\\] nm.*250"),
    (lambda: spectra.absorption("blood", 500), "chromophore must be one of"),
    (lambda: spectra.calc_mua(500, 1.2, 0.1, 0, 0, 0), "S must be in \\[0, 1\\], got 1.2"),
    (lambda: spectra.calc_mus(500, 10, 0.2, 1, 1.0), "g must be in \\[-1, 1\\).*got 1.0"),
])
def test_spectra_bad_input_names_the_parameter(call, message):
    with pytest.raises(ValueError, match=message):
        call()


# ------------------------------------------------------------------ media of wavelength

def small_model(media, geom_func=None, n_photons=3000):
    model = Model()
    model.G.nx, model.G.ny, model.G.nz = 12, 12, 8
    model.G.Lx, model.G.Ly, model.G.Lz = 0.4, 0.4, 0.2
    model.G.media = media
    model.G.geom_func = geom_func
    model.MC.n_photons_requested = n_photons
    model.MC.seed = 11
    model.MC.light_source.source_type = "tophat"
    model.MC.light_source.radius = 0.1
    model.MC.progress = False
    return model


def dermis(wavelength):
    return spectra.calc_mua(wavelength, 0.67, 0.002, 0.65, 0.0, 0.0)


def dermis_mus(wavelength):
    return spectra.calc_mus(wavelength, 43.6, 0.41, 0.562, 0.9)


def test_medium_of_wavelength_is_bit_identical_to_its_numbers():
    lam = 633.0
    functional = Medium("dermis", mua=dermis, mus=dermis_mus, g=lambda wl: 0.9,
                        n=lambda wl: 1.38)
    numbers = Medium("dermis", mua=dermis(lam), mus=dermis_mus(lam), g=0.9, n=1.38)
    a = small_model([functional])
    a.MC.wavelength = lam
    b = small_model([numbers])
    a.run_monte_carlo()
    b.run_monte_carlo()
    assert np.array_equal(a.MC.NA, b.MC.NA)
    assert a.MC.media_properties.mua[0] == dermis(lam)
    # another wavelength gives another result
    a.MC.wavelength = 500.0
    a.run_monte_carlo()
    assert not np.array_equal(a.MC.NA, b.MC.NA)


def test_function_of_wavelength_needs_mc_wavelength():
    model = small_model([Medium("dermis", mua=dermis, mus=100.0, g=0.9)])
    model.run_monte_carlo()  # MCmatlab's default wavelength
    assert model.MC.wavelength == 800.0 and model.MC.media_properties.mua[0] == dermis(800.0)
    model.MC.wavelength = None
    with pytest.raises(ValueError, match="MC.wavelength"):
        model.run_monte_carlo()


def test_g_one_and_n_inf_are_accepted_out_of_range_is_not():
    Medium("air", mua=1e-8, mus=1e-8, g=1)  # MCmatlab's air: no deflection
    Medium("air", mua=1e-8, mus=1e-8, g=-1.0)
    Medium("mirror", mua=0.0, mus=0.0, n=math.inf)  # a perfect reflector
    with pytest.raises(ValueError, match=r"Medium\('x'\)\.g must be in \[-1, 1\], got 1\.01"):
        Medium("x", mua=1.0, mus=1.0, g=1.01)
    with pytest.raises(ValueError, match=r"\.n must not be NaN, got nan"):
        Medium("x", mua=1.0, mus=1.0, n=math.nan)
    with pytest.raises(ValueError, match=r"\.mua must be finite, got inf"):
        Medium("x", mua=math.inf, mus=1.0)


def test_thermal_limits_pass_mcmatlabs_values_and_refuse_si_units():
    """The limits guard against unit mistakes only: MCmatlab's Example 14 gives VHC = 2000
    J cm^-3 K^-1 on purpose; water's VHC in J m^-3 K^-1 (4.19e6) is refused, naming the field,
    also when a function of (T, FD) returns it."""
    Medium("slow", mua=1.0, mus=1.0, VHC=2000.0, TC=5e-3)
    Medium("diamond", mua=1.0, mus=1.0, VHC=1.8, TC=22.0)
    with pytest.raises(ValueError, match=r"Medium\('x'\)\.VHC must be <= 100000, got 4190000"):
        Medium("x", mua=1.0, mus=1.0, VHC=4.19e6)
    with pytest.raises(ValueError, match=r"\.TC must be <= 10000, got 100000"):
        Medium("x", mua=1.0, mus=1.0, TC=1e5)
    m = Medium("x", mua=1.0, mus=1.0, VHC=lambda T, FD: 4.19e6 + 0 * T, TC=0.006)
    with pytest.raises(ValueError, match=r"VHC\(T, FD\) returned 4190000.0: VHC must be <= 100000"):
        m.values("VHC", None, np.zeros(2), np.full(2, 37.0), np.zeros(2))


@pytest.mark.parametrize("kwargs, message", [
    ({"mua": lambda wl, FR: 1.0}, r"mua must be a number or a function of \(wavelength\) or "
                                  r"\(wavelength, FR, T, FD\)"),
    ({"n": lambda wl, FR, T, FD: 1.0}, r"n must be a number or a function of \(wavelength\)"),
    ({"VHC": lambda T: 1.0}, r"VHC must be a number or a function of \(T, FD\)"),
    ({"g": "0.9x"}, r"g must be a number or a function, got '0.9x'"),
    ({"n_bins": 0}, r"n_bins must be >= 1, got 0"),
])
def test_bad_medium_functions_name_the_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Medium("x", **{"mua": 1.0, "mus": 1.0, **kwargs})


def test_function_values_are_checked_at_the_wavelength():
    model = small_model([Medium("x", mua=1.0, mus=10.0, g=lambda wl: wl / 500.0)])
    model.MC.wavelength = 600.0
    with pytest.raises(ValueError, match=r"g\(wavelength=600\.0\) returned 1\.2: g must be in"):
        model.run_monte_carlo()


# ------------------------------------------------------------------ FR, T, FD and n_bins

def test_farthest_point_bins_recover_separated_clusters():
    rng = np.random.default_rng(0)
    centres = np.array([[1.0, 50.0], [5.0, 50.0], [9.0, 80.0]])
    truth = rng.integers(0, 3, 300)
    values = centres[truth] + 0.01 * rng.standard_normal((300, 2))
    reps, labels = farthest_point_bins(values, 3)
    assert np.all(np.diff(reps[:, 0]) > 0)  # sorted
    np.testing.assert_allclose(reps, centres, atol=0.05)
    assert np.array_equal(labels, truth)  # sorted order = the centres' order


def test_covering_radius_of_one_dimensional_bins():
    # Gonzalez' farthest-point rule covers within twice the optimal radius span / (2 k)
    values = np.linspace(0.0, 7.0, 1001)[:, None]
    for k in (2, 5, 16):
        reps, labels = farthest_point_bins(values, k)
        assert np.abs(reps[labels, 0] - values[:, 0]).max() <= 7.0 / k + 1e-12


def two_state_model(n_bins):
    hot = lambda X, Y, Z: (X > 0) & (Z < 0.1)  # noqa: E731

    def mua(wl, FR, T, FD):
        return np.where(T > 50.0, 10.0, 1.0)

    model = small_model([Medium("tissue", mua=mua, mus=50.0, g=0.8, n_bins=n_bins)])
    X, Y, Z = np.meshgrid(model.G.x, model.G.y, model.G.z, indexing="ij")
    model.MC.T = np.where(hot(X, Y, Z), 70.0, 37.0)
    return model, hot


@pytest.mark.parametrize("n_bins", [2, 5])
def test_temperature_dependent_medium_equals_two_plain_media(n_bins):
    model, hot = two_state_model(n_bins)
    model.run_monte_carlo()
    props = model.MC.media_properties
    assert len(props.mua) == n_bins and set(props.parent) == {0}
    hot_mask = hot(*np.meshgrid(model.G.x, model.G.y, model.G.z, indexing="ij"))
    np.testing.assert_array_equal(props.mua[model.MC.M], np.where(hot_mask, 10.0, 1.0))
    if n_bins == 2:
        # the same sub-media and map as two plain media: the same photons, bit for bit
        plain = small_model([Medium("cold", mua=1.0, mus=50.0, g=0.8),
                             Medium("hot", mua=10.0, mus=50.0, g=0.8)],
                            geom_func=lambda X, Y, Z: hot(X, Y, Z).astype(int))
        plain.run_monte_carlo()
        assert np.array_equal(model.MC.M, plain.G.medium_map())
        assert np.array_equal(model.MC.NA, plain.MC.NA)
        np.testing.assert_array_equal(model.MC.NFR, plain.MC.NFR)


def test_state_fields_are_passed_per_voxel_and_binned_within_the_covering_radius():
    seen = {}

    def mus(wl, FR, T, FD):
        seen.update(FR=FR, T=T, FD=FD)
        return 100.0 * (1.0 + FD) + 0.0 * FR

    M = np.zeros((4, 3, 2), dtype=int)
    M[0] = 1  # medium 1 is plain
    FD = np.linspace(0.0, 1.0, M.size).reshape(M.shape)
    media = [Medium("damaged", mua=1.0, mus=mus, g=0.9, n_bins=4), Medium("plain", 2.0, 20.0)]
    props = optical_media_properties(media, M, 800.0, FR=3.0, T=40.0, FD=FD)
    assert seen["FR"].shape == (18,) and np.all(seen["FR"] == 3.0) and np.all(seen["T"] == 40.0)
    np.testing.assert_array_equal(seen["FD"], FD[M == 0])
    assert list(props.parent) == [0, 0, 0, 0, 1] and props.mus[-1] == 20.0
    assert np.all(props.M[M == 1] == 4)
    exact = 100.0 * (1.0 + FD[M == 0])
    span = exact.max() - exact.min()
    assert np.abs(props.mus[props.M[M == 0]] - exact).max() <= span / 4


@pytest.mark.parametrize("field, value, message", [
    ("FR", -1.0, r"MC\.FR must be finite and in \[0\.0, inf\], got -1\.0"),
    ("FD", 1.5, r"MC\.FD must be finite and in \[0\.0, 1\.0\], got 1\.5"),
    ("T", np.zeros((3, 3, 3)), r"MC\.T must be a number or an array of shape \(12, 12, 8\)"),
    ("wavelength", -5.0, r"MC\.wavelength must be > 0, got -5\.0"),
])
def test_bad_state_fields_name_the_field(field, value, message):
    model, _ = two_state_model(2)
    setattr(model.MC, field, value)
    with pytest.raises(ValueError, match=message):
        model.run_monte_carlo()


def test_state_dependent_media_are_not_silently_flattened():
    model, _ = two_state_model(2)
    with pytest.raises(NotBuiltError, match="splits such media into sub-media"):
        optical_arrays(model.G.media)
    model.G.media[0].VHC = lambda T, FD: 3.7 + 0.0 * T
    model.G.media[0].TC = 0.005
    model.MC.NA = np.zeros((12, 12, 8))
    model.HS.progress = False
    model.simulate_heat_distribution()  # thermal sub-media from (T, FD): mcmatlab_py.frt
    assert np.allclose(model.HS.media_properties.VHC, 3.7)


def test_thermal_media_are_binned_on_temperature():
    M = np.zeros((5, 1, 1), dtype=int)
    T = np.array([20.0, 20.0, 90.0, 90.0, 20.0]).reshape(M.shape)
    media = [Medium("t", mua=1.0, mus=1.0, VHC=lambda T, FD: 3.0 + 0.01 * T, TC=0.005,
                    E=4e5, A=1e60, n_bins=2)]
    props = thermal_media_properties(media, M, T=T, FD=0.0)
    np.testing.assert_allclose(props.VHC[props.M].ravel(), 3.0 + 0.01 * T.ravel())
    assert np.all(props.TC == 0.005) and np.all(props.E == 4e5)
