"""Fluorescence Monte Carlo (``model.FMC``): energy, an analytic slab, the API and figures."""

import math

import numpy as np
import pytest
from scipy.special import expn

from mcmatlab_py import Medium, Model
from mcmatlab_py.fluorescence import fluorescence_emitters

LAM_X, LAM_F = 450.0, 600.0  # nm, excitation and fluorescence
MUA_X, MUA_F = 20.0, 10.0  # cm^-1, the slab's absorption at each
QY = 0.5
L = 0.1  # cm, slab thickness
N_FMC = 20_000


def _by_wavelength(at_x, at_f):
    return lambda w: at_x if w < 500 else at_f


def slab_model(n_photons: int = 4000, mus: float = 0.0) -> Model:
    """A uniform fluorescent slab, sides cyclic, under a plane wave, matched interfaces."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 3, 3, 40
    G.Lx = G.Ly = 0.03
    G.Lz = L
    G.media = [Medium("fluorescent slab", mua=_by_wavelength(MUA_X, MUA_F), mus=mus, g=0.0,
                      QY=QY)]
    for sim, wl, seed in ((model.MC, LAM_X, 1), (model.FMC, LAM_F, 2)):
        sim.n_photons_requested = n_photons
        sim.seed = seed
        sim.progress = False
        sim.boundary_type = 3  # top and bottom escape, sides cyclic: an infinite slab
        sim.wavelength = wl
    model.MC.light_source.source_type = "plane_wave"
    return model


@pytest.fixture(scope="module")
def slab():
    model = slab_model(n_photons=4000).run_monte_carlo()
    model.FMC.n_photons_requested = N_FMC
    model.FMC.calc_normalized_irradiance = True
    return model.run_monte_carlo("fluorescence")


def test_emitted_power_is_qy_times_absorbed_times_photon_energy_ratio(slab):
    G, MC, FMC = slab.G, slab.MC, slab.FMC
    dV = G.dx * G.dy * G.dz
    absorbed = MC.NA.sum() * dV  # W per W incident, all in the fluorescent medium
    assert FMC.emitted_power == pytest.approx(QY * LAM_X / LAM_F * absorbed, rel=1e-12)
    np.testing.assert_allclose(FMC.source_distribution, MC.NA * QY * LAM_X / LAM_F, rtol=1e-12)
    assert FMC.energy_balance == pytest.approx(1.0, abs=1e-9)
    # maps per W incident excitation, fractions of the emitted fluorescence
    assert FMC.NA.sum() * dV == pytest.approx(FMC.absorbed_fraction * FMC.emitted_power,
                                              rel=1e-9)
    top = FMC.NI_zneg.sum() * G.dx * G.dy
    assert top == pytest.approx(FMC.escaped["top"] * FMC.emitted_power, rel=1e-9)


def test_non_scattering_slab_against_the_exponential_integral(slab):
    """Isotropic emission at depth z escapes through the top with probability
    (1/2) E2(mua_f z) in a non-scattering slab (Chandrasekhar's slab geometry); averaged over
    the voxels' emitted power (uniform within a voxel, integrated by Gauss-Legendre)."""
    G, FMC = slab.G, slab.FMC
    w = FMC.source_distribution.sum(axis=(0, 1))  # (nz,) emitted power per layer
    xg, wg = np.polynomial.legendre.leggauss(16)
    expected = {}
    for face, depth in (("top", lambda z: z), ("bottom", lambda z: L - z)):
        per_layer = np.array([
            np.sum(wg / 2 * 0.5 * expn(2, MUA_F * depth(z0 + G.dz * (1 + xg) / 2)))
            for z0 in np.arange(G.nz) * G.dz])
        expected[face] = float(np.sum(w * per_layer) / w.sum())
    for face, p in expected.items():
        se = math.sqrt(p * (1 - p) / FMC.n_photons)  # a packet's share lies in [0, 1]
        assert abs(FMC.escaped[face] - p) <= 4 * se, (face, FMC.escaped[face], p, se)
    # the excitation decays as exp(-mua_x z): more fluorescence escapes through the top
    assert expected["top"] > expected["bottom"] + 10 * se


def test_only_fluorescent_media_emit_and_state_dependent_qy():
    model = slab_model(n_photons=2000)
    G = model.G
    G.media = [Medium("absorber", mua=5.0, mus=50.0, g=0.9),
               Medium("dye", mua=_by_wavelength(MUA_X, MUA_F), mus=50.0, g=0.9,
                      QY=lambda wl, FR, T, FD: 0.1 * (T > 40), ES=1.0)]
    G.geom_func = lambda X, Y, Z: (Z > L / 2).astype(int)
    T = np.full((G.nx, G.ny, G.nz), 37.0)
    T[..., -5:] = 45.0
    model.MC.T = T
    model.run_monte_carlo()
    E = fluorescence_emitters(G, model.MC, LAM_F)
    assert np.all(E[..., : G.nz // 2] == 0)  # the absorber does not fluoresce
    np.testing.assert_allclose(E[..., -5:], model.MC.NA[..., -5:] * 0.1 * LAM_X / LAM_F)
    assert np.all(E[..., G.nz // 2:-5] == 0)  # QY(T <= 40) = 0


def test_errors_name_what_is_wrong():
    model = slab_model(n_photons=500)
    with pytest.raises(ValueError, match="run the excitation"):
        model.run_monte_carlo("fluorescence")
    with pytest.raises(ValueError, match="'excitation' or 'fluorescence'"):
        model.run_monte_carlo("fluorescense")
    model.run_monte_carlo()
    model.FMC.wavelength = None
    with pytest.raises(ValueError, match="FMC.wavelength must be set"):
        model.run_monte_carlo("fluorescence")
    model.FMC.wavelength = LAM_F
    model.FMC.n_photons_requested = 0
    with pytest.raises(ValueError, match="FMC.n_photons_requested"):
        model.run_monte_carlo("fluorescence")
    model.FMC.n_photons_requested = 500
    model.G.media[0].ES = lambda wl: 0.0 if wl > 580 else 1.0
    with pytest.raises(ValueError, match="ES is 0 at FMC.wavelength = 600 nm"):
        model.run_monte_carlo("fluorescence")
    model.G.media[0].ES = None
    model.G.media[0].QY = None
    with pytest.raises(ValueError, match="no fluorescence emitters"):
        model.run_monte_carlo("fluorescence")
    with pytest.raises(ValueError, match=r"Medium\('x'\).QY must be >= 0"):
        Medium("x", mua=1.0, mus=1.0, QY=-0.1)
    with pytest.raises(AttributeError, match="did you mean"):
        model.FMC.n_photon_requested = 10


def test_light_collector_and_plot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    model = slab_model(n_photons=2000, mus=50.0).run_monte_carlo()
    FMC = model.FMC
    FMC.use_light_collector = True
    LC = FMC.light_collector
    LC.z, LC.theta, LC.f, LC.diam, LC.field_size, LC.res = -0.1, 0.0, 0.1, 0.1, 0.03, 5
    FMC.far_field_res = 8
    model.run_monte_carlo("fluorescence")
    assert LC.image.shape == (5, 5) and LC.image.sum() > 0
    # the far field holds every escaping packet: W per W incident, like the maps
    assert FMC.far_field.sum() == pytest.approx(
        (FMC.escaped["top"] + FMC.escaped["bottom"]) * FMC.emitted_power, rel=1e-9)
    figs = model.plot("FMC")
    assert set(figs) == {"emitters", "NA", "NFR", "light_collector", "far_field"}
    plt.close("all")
