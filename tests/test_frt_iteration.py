"""Media depending on fluence rate, temperature and damage, coupled by iteration
(MCmatlab's FRdepIterations and mediaPropRecalcPeriod; Examples 12-15)."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

import fem
from mcmatlab_py import Medium, Model
from mcmatlab_py.frt import MediaCoupling, fluence_rate_iterations


def saturable_slab(n_layers=10, mua0=10.0, d=0.1, I_sat=50.0):
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 1, 1, n_layers
    G.Lx, G.Ly, G.Lz = 0.1, 0.1, d
    G.media = [Medium("saturable absorber", mua=lambda wl, FR, T, FD: mua0 / (1 + FR / I_sat),
                      mus=0.0, g=0.0, n=1.0, n_bins=n_layers)]
    MC = model.MC
    MC.boundary_type = 3  # top and bottom escape, sides cyclic: a 1-D slab
    MC.light_source.source_type = "plane_wave"
    MC.n_photons_requested, MC.seed, MC.progress = 20_000, 1, False
    return model


def test_saturable_absorber_follows_the_saturation_law():
    """dI/dz = -mua0 I / (1 + I / I_sat): the transmission T solves
    ln T + (I0 / I_sat) (T - 1) = -mua0 d. Without scattering a packet is absorbed whole at
    its first interaction, so the transmission is binomial: 4 standard errors, plus the
    O((mua dz)^2) of the layers' piecewise-constant mua (about 1e-3 here)."""
    mua0, d, I_sat = 10.0, 0.1, 50.0
    model = saturable_slab(mua0=mua0, d=d, I_sat=I_sat)
    P = 0.5  # W on 0.01 cm^2: I0 = 50 W/cm^2 = I_sat
    I0 = P / (model.G.Lx * model.G.Ly)
    fluence_rate_iterations(model, P, 6)
    MC = model.MC
    exact = brentq(lambda T: math.log(T) + I0 / I_sat * (T - 1) + mua0 * d, 1e-9, 1.0)
    unsaturated = math.exp(-mua0 * d)
    se = math.sqrt(exact * (1 - exact) / MC.n_photons)
    assert MC.escaped["bottom"] == pytest.approx(exact, abs=4 * se + 1e-3)
    assert abs(exact - unsaturated) > 0.15  # the law, not Beer-Lambert
    saturated_at_I0 = math.exp(-mua0 * d / (1 + I0 / I_sat))
    assert abs(MC.escaped["bottom"] - saturated_at_I0) > 0.02  # nor a uniform FR = I0
    # energy: absorbed + transmitted = launched
    assert MC.absorbed_fraction + MC.escaped["bottom"] + MC.escaped["top"] == pytest.approx(1.0)
    # every layer sees its own fluence rate: mua rises with depth as the light weakens
    mua = MC.media_properties.mua[MC.M[0, 0, :]]
    assert mua[-1] - mua[0] > 0.5 and np.polyfit(np.arange(mua.size), mua, 1)[0] > 0
    assert MC.n_photons_requested == 20_000  # restored after the halving sequence


def uniform_block(vhc, tc=0.005):
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 2, 2, 2
    G.Lx = G.Ly = G.Lz = 0.1
    G.media = [Medium("tissue", mua=1.0, mus=1.0, VHC=vhc, TC=tc, n_bins=2)]
    model.MC.NA = np.full((2, 2, 2), 1.0 / 0.1**3)  # all the power absorbed uniformly
    HS = model.HS
    HS.P, HS.T_initial, HS.progress, HS.duration_on = 0.1, 37.0, False, 2.0
    HS.media_prop_recalc_period = 1
    return model


def test_temperature_dependent_heat_capacity_converges_at_first_order():
    """Uniform heating of an insulated block with c(T) = c0 + c1 (T - 37): the enthalpy
    c0 u + c1 u^2 / 2 (u = T - 37) equals q t. VHC is re-evaluated at every update, so
    the error falls as the update interval (first order)."""
    c0, c1 = 3.0, 0.05
    q = 0.1 / 0.1**3  # W/cm^3
    u_exact = (-c0 + math.sqrt(c0**2 + 2 * c1 * q * 2.0)) / c1
    errors, spacing = [], []
    for n in (16, 32, 64):
        model = uniform_block(lambda T, FD: c0 + c1 * (T - 37.0))
        model.HS.n_updates = n
        model.simulate_heat_distribution()
        errors.append(abs(model.HS.T_voxels.mean() - 37.0 - u_exact))
        spacing.append(2.0 / n)
        assert np.ptp(model.HS.T_voxels) < 1e-9  # stays uniform
    rate = np.polyfit(np.log(spacing), np.log(errors), 1)[0]
    assert rate == pytest.approx(1.0, abs=0.15)
    assert errors[-1] < 0.02 * u_exact
    assert model.HS.media_properties.VHC.max() > c0 + c1 * 0.9 * u_exact  # binned on T


def test_thermochromic_absorber_reruns_the_monte_carlo_and_keeps_energy(monkeypatch):
    """mua jumps from 1 to 20 /cm above 45 deg C (Example 14's thermochromism): the Monte
    Carlo re-runs when the bins change, and the heat gained is exactly P times the
    absorbed fraction in force over each update interval."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 5, 5, 4
    G.Lx = G.Ly = 0.2
    G.Lz = 0.1
    vhc = 3.0
    G.media = [Medium("thermochromic", mua=lambda wl, FR, T, FD: np.where(T > 45.0, 20.0, 1.0),
                      mus=20.0, g=0.8, n=1.0, VHC=vhc, TC=0.004, n_bins=2)]
    MC = model.MC
    MC.n_photons_requested, MC.seed, MC.progress = 3000, 2, False
    MC.light_source.source_type = "plane_wave"
    model.run_monte_carlo()
    HS = model.HS
    HS.P, HS.duration_on, HS.n_updates, HS.media_prop_recalc_period = 2.5, 0.4, 8, 1
    HS.progress = False
    fractions = [MC.absorbed_fraction]  # in force after each update
    original = MediaCoupling.update_optics

    def logged(self, *args):
        ran = original(self, *args)
        fractions.append(MC.absorbed_fraction)
        return ran

    monkeypatch.setattr(MediaCoupling, "update_optics", logged)
    model.simulate_heat_distribution()
    assert HS.mc_runs >= 1
    assert fractions[-1] > 2 * fractions[0]  # the hot tissue absorbs more
    heat = fem.lumped_mass(HS.mesh, vhc) @ (HS.T_nodes - 37.0)
    expected = HS.P * (0.4 / 8) * sum(fractions[:8])
    assert heat == pytest.approx(expected, rel=1e-9)
    # the last run's sub-media follow the voxel temperatures it was given
    mua = MC.media_properties.mua[MC.M]
    np.testing.assert_array_equal(mua, np.where(MC.T > 45.0, 20.0, 1.0))
    assert (mua == 20.0).any() and (mua == 1.0).any()


def test_mc_p_and_fr_dep_iterations_make_run_monte_carlo_iterate():
    """MCmatlab's MC.P and MC.FRdepIterations: model.run_monte_carlo() does the iteration,
    bit for bit what fluence_rate_iterations(model, P, n) does with the same seed."""
    by_hand = saturable_slab()
    fluence_rate_iterations(by_hand, 0.5, 4)
    model = saturable_slab()
    model.MC.P, model.MC.fr_dep_iterations = 0.5, 4
    model.run_monte_carlo()
    np.testing.assert_array_equal(model.MC.NA, by_hand.MC.NA)
    np.testing.assert_array_equal(model.MC.FR, by_hand.MC.FR)
    assert model.MC.n_photons == model.MC.n_photons_requested == 20_000
    assert np.ptp(model.MC.media_properties.mua) > 0.5  # the runs saw the fluence rate


def test_fluence_rate_settings_are_checked():
    model = saturable_slab()
    model.MC.fr_dep_iterations = 3
    with pytest.raises(ValueError, match=r"MC.fr_dep_iterations = 3 but MC.P is None: .* give "
                                         r"MC.P, the incident power in W"):
        model.run_monte_carlo()
    model.MC.P = -1.0
    with pytest.raises(ValueError, match=r"MC.P must be > 0, got -1.0"):
        model.run_monte_carlo()
    model.MC.P, model.MC.fr_dep_iterations = 1.0, 2.5
    with pytest.raises(ValueError, match=r"MC.fr_dep_iterations must be an integer"):
        model.run_monte_carlo()
    with pytest.raises(AttributeError, match=r"MCmatlab's FRinitial is MC.FR \(the fluence rate"):
        model.MC.FRinitial = 0.0
    with pytest.raises(AttributeError, match=r"FRdepIterations is MC.fr_dep_iterations here"):
        model.MC.FRdepIterations = 1
    # MCmatlab's fluorescence run has no power or iteration of its own
    model.MC.fr_dep_iterations = 0
    model.run_monte_carlo()
    model.G.media[0].QY = 0.5
    model.FMC.wavelength, model.FMC.n_photons_requested, model.FMC.P = 600.0, 100, 1.0
    with pytest.raises(ValueError, match=r"FMC.P = 1.0: the fluorescence run has no power .* "
                                         r"set MC.P, the excitation's"):
        model.run_monte_carlo("fluorescence")


def conducting_block(theta, dt=None):
    """8^3 voxels heated in the middle; TC grows 26-fold from 37 to 57 deg C (Test 1's
    material 2 grows thirty-fold), re-binned at every update."""
    model = Model()
    G = model.G
    G.nx = G.ny = G.nz = 8
    G.Lx = G.Ly = G.Lz = 0.08
    G.media = [Medium("t", mua=1.0, mus=1.0, VHC=4.0, n_bins=8,
                      TC=lambda T, FD: 0.002 + 0.05 * np.clip((T - 37.0) / 20.0, 0.0, 1.0))]
    NA = np.zeros((8, 8, 8))
    NA[3:5, 3:5, 3:5] = 1 / (8 * 0.01**3)  # W/cm^3 per W, in the central 2^3 voxels
    model.MC.NA = NA
    HS = model.HS
    HS.P, HS.duration_on, HS.n_updates, HS.media_prop_recalc_period = 0.2, 0.2, 20, 1
    HS.theta, HS.dt, HS.progress = theta, dt, False
    HS.step_control = "stability"  # the bound of the automatic step is what is tested
    return model


def test_automatic_step_is_chosen_again_when_the_media_conduct_faster(monkeypatch):
    """The automatic step bounds lambda_max dt (Crank-Nicolson: 2, or stiff modes flip sign
    every step); when the tissue heats and conducts 26 times faster the steps are cut into
    sub-steps within the new bound, and the run agrees with one of 1e-4 s steps to 1e-3 K
    (measured: 2e-4 K). With the first step kept it is 100 times further off (2.4e-2 K)."""
    import mcmatlab_py.heat.run as heat

    reference = conducting_block(0.5, dt=1e-4).simulate_heat_distribution().HS
    HS = conducting_block(0.5).simulate_heat_distribution().HS
    assert HS.T_nodes.max() > 75.0  # the hot centre is in the conducting regime
    bound = heat.auto_dt((0.01, 0.01, 0.01), HS.media_properties.VHC, HS.media_properties.TC,
                         theta=0.5)
    assert HS.dt_used.min() <= bound * (1 + 1e-12) < HS.dt_used.max()
    assert np.abs(HS.T_nodes - reference.T_nodes).max() < 1e-3

    first, original = [], heat.auto_dt

    def first_choice(*args, **kwargs):  # the step as chosen at the start, never again
        if not first:
            first.append(original(*args, **kwargs))
        return first[0]

    monkeypatch.setattr(heat, "auto_dt", first_choice)
    kept = conducting_block(0.5).simulate_heat_distribution().HS
    assert kept.dt_used.size == 1
    assert np.abs(kept.T_nodes - reference.T_nodes).max() > 1e-2


def test_heat_power_that_differs_from_mc_p_is_warned():
    model = uniform_block(3.0)
    model.MC.P, model.HS.duration_on = 0.2, 0.5  # HS.P = 0.1
    with pytest.warns(UserWarning, match=r"MC.P = 0.2 W and HS.P = 0.1 W differ: .* set "
                                         r"HS.P = MC.P"):
        model.simulate_heat_distribution()


def fluorescent_block(mua, QY):
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 5, 5, 4
    G.Lx = G.Ly = 0.2
    G.Lz = 0.1
    G.media = [Medium("fluorescent", mua=mua, mus=20.0, g=0.8, n=1.0, VHC=3.0, TC=0.004,
                      n_bins=2, QY=QY)]
    for sim, wavelength, seed in ((model.MC, 500.0, 2), (model.FMC, 600.0, 3)):
        sim.n_photons_requested, sim.seed, sim.progress = 3000, seed, False
        sim.wavelength = wavelength
    model.MC.light_source.source_type = "plane_wave"
    model.run_monte_carlo()
    model.run_monte_carlo("fluorescence")
    HS = model.HS
    HS.P, HS.duration_on, HS.n_updates, HS.media_prop_recalc_period = 2.5, 0.4, 8, 1
    HS.progress = False
    return model


def test_coupled_heat_run_reruns_the_fluorescence_and_heats_where_it_is_absorbed(monkeypatch):
    """MCmatlab's heatSimParamsRecalc runs the fluorescence again after the excitation, and
    heats with NA - emitted + fluorescence absorbed (calcdTdtArrays): the heat gained is
    exactly P times that source, as in force over each update interval."""
    from mcmatlab_py.fluorescence import fluorescence_emitters
    from mcmatlab_py.heat import heat_source

    model = fluorescent_block(lambda wl, FR, T, FD: np.where(T > 45.0, 20.0, 1.0), QY=0.5)
    G, MC, FMC, HS = model.G, model.MC, model.FMC, model.HS
    HS.P = 3.5  # W: the fluorescence takes heat away, it must still pass 45 deg C
    dV = G.dx * G.dy * G.dz
    emitted = FMC.emitted_power
    assert heat_source(model).sum() * dV == pytest.approx(
        MC.absorbed_fraction - emitted + FMC.absorbed_fraction * emitted, rel=1e-9)
    before = FMC.source_distribution.copy()
    sources = [heat_source(model).sum() * dV]  # W per W, in force after each update
    original = MediaCoupling.update_fluorescence

    def logged(self, *args):
        ran = original(self, *args)
        sources.append(heat_source(model).sum() * dV)
        return ran

    monkeypatch.setattr(MediaCoupling, "update_fluorescence", logged)
    model.simulate_heat_distribution()
    assert HS.mc_runs >= 1
    heat = fem.lumped_mass(HS.mesh, 3.0) @ (HS.T_nodes - 37.0)
    assert heat == pytest.approx(HS.P * (0.4 / 8) * sum(sources[:8]), rel=1e-9)
    # the last fluorescence run is that of the last excitation
    np.testing.assert_array_equal(FMC.source_distribution,
                                  fluorescence_emitters(G, MC, FMC.wavelength))
    assert not np.array_equal(FMC.source_distribution, before)


def test_temperature_dependent_quantum_yield_reruns_only_the_fluorescence():
    from mcmatlab_py.fluorescence import fluorescence_emitters

    model = fluorescent_block(5.0, QY=lambda wl, FR, T, FD: 0.5 / (1 + (T - 37.0) / 10))
    G, MC, FMC, HS = model.G, model.MC, model.FMC, model.HS
    NA = MC.NA.copy()
    model.simulate_heat_distribution()
    assert HS.mc_runs == 0 and np.array_equal(MC.NA, NA)
    assert HS.T_voxels.max() > 40.0
    # the last update is the end of the run: the emitters of the final temperatures
    np.testing.assert_array_equal(
        FMC.source_distribution,
        fluorescence_emitters(G, MC, FMC.wavelength, state=(MC.FR, HS.T_voxels, 0.0)))
    assert FMC.emitted_power < 0.9 * (MC.NA.sum() * G.dx * G.dy * G.dz) * 0.5 * 500 / 600
