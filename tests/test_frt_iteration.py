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
