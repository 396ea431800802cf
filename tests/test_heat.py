"""The MCmatlab-style heat front end (``model.HS``): contract, physics, bad input."""

import math

import numpy as np
import pytest

from enkf.paper import paper_model
from mcmatlab_py import Medium, Model


def small_paper_model(n_photons=20_000):
    model = paper_model((10, 10, 5), n_photons=n_photons, progress=False)
    model.HS.duration_on, model.HS.duration_off = 1.0, 1.0
    return model


def test_contract_and_energy_balance():
    """Insulated block: the heat content equals P x absorbed fraction x time on."""
    model = small_paper_model().run_monte_carlo()
    HS = model.HS
    model.simulate_heat_distribution()
    assert HS.sensor_times.shape == (21,)
    assert HS.sensor_times[-1] == pytest.approx(2.0)
    assert HS.sensor_temps.shape == (21, 3)
    assert HS.T.shape == (11, 11, 6) and HS.Omega.shape == HS.T.shape
    import fem

    heat = fem.lumped_mass(HS.mesh, 3.76) @ (HS.T_nodes - HS.T_initial)
    deposited = HS.P * model.MC.absorbed_fraction * HS.duration_on
    assert heat == pytest.approx(deposited, rel=1e-8)
    # the surface heats first and most
    assert HS.sensor_temps[10, 0] > HS.sensor_temps[10, 1] > HS.sensor_temps[10, 2] > 0


def test_steps_that_a_pulse_edge_cuts_get_the_energy_delivered_in_them():
    """HS.dt = 0.1 s against pulses of 0.25 s every 0.6 s: the steps that hold a pulse's
    end get its mean power over the step, so the heat content is still P x absorbed
    fraction x time on (at the step's middle power, 0.4 s of the 0.5 s on)."""
    import fem

    model = small_paper_model().run_monte_carlo()
    HS = model.HS
    HS.duration_on, HS.duration_off, HS.n_pulses, HS.dt = 0.25, 0.35, 2, 0.1
    model.simulate_heat_distribution()
    heat = fem.lumped_mass(HS.mesh, 3.76) @ (HS.T_nodes - HS.T_initial)
    deposited = HS.P * model.MC.absorbed_fraction * 2 * 0.25
    assert heat == pytest.approx(deposited, rel=1e-8)


def test_mean_laser_power_is_the_energy_over_the_step():
    model = small_paper_model()
    HS = model.HS
    HS.P, HS.duration_on, HS.duration_off, HS.n_pulses = 2.0, 0.25, 0.25, 2
    assert HS.mean_laser_power(0.1, 0.2) == HS.laser_power(0.15) == 2.0  # within a pulse
    assert HS.mean_laser_power(0.3, 0.4) == 0.0  # within a pause
    assert HS.mean_laser_power(1.0, 1.5) == 0.0  # after the train
    assert HS.mean_laser_power(0.2, 0.3) == pytest.approx(1.0, rel=1e-12)  # an end inside
    assert HS.mean_laser_power(0.45, 0.55) == pytest.approx(1.0, rel=1e-12)  # a start
    assert HS.mean_laser_power(0.0, 1.0) == pytest.approx(1.0, rel=1e-12)  # both pulses
    edges = np.linspace(0.0, 1.3, 14)  # steps of 0.1 s: the energy of the whole train
    energy = sum((b - a) * HS.mean_laser_power(a, b)
                 for a, b in zip(edges[:-1], edges[1:], strict=True))
    assert energy == pytest.approx(2.0 * 2 * 0.25, rel=1e-12)
    HS.P = lambda t: 4.0 * t  # a callable power: at the middle of the step's on-time
    assert HS.mean_laser_power(0.2, 0.3) == pytest.approx(0.05 * 4.0 * 0.225 / 0.1)


def test_one_dimensional_surface_heating():
    """Plane wave on a strong absorber, cyclic sides: T_surface = 2 q sqrt(alpha t / pi) / k."""
    vhc, tc = 3.76, 0.0037
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 1, 1, 160
    G.Lx, G.Ly, G.Lz = 0.1, 0.1, 0.4
    G.media = [Medium("absorber", mua=1e4, mus=0.0, g=0.0, n=1.0, VHC=vhc, TC=tc)]
    MC = model.MC
    MC.boundary_type = 3
    MC.light_source.source_type = "plane_wave"
    MC.n_photons_requested = 2000
    MC.seed = 1
    MC.progress = False
    model.run_monte_carlo()
    assert MC.absorbed_fraction == pytest.approx(1.0)
    HS = model.HS
    HS.P = 0.01
    HS.duration_on, HS.duration_off, HS.dt = 2.0, 0.0, 0.002
    HS.T_initial = 0.0
    HS.temp_sensor_positions = [(0, 0, 0)]
    HS.progress = False
    model.simulate_heat_distribution()
    q = HS.P / (G.Lx * G.Ly)  # W/cm^2
    alpha = tc / vhc
    t = HS.sensor_times
    exact = 2 * q * np.sqrt(alpha * t / math.pi) / tc
    dz = G.Lz / G.nz
    for time in (0.5, 1.0, 2.0):
        k = int(round(time / HS.dt))
        # source spread over the first layer (dz) instead of the surface, and O(dt) time error
        tol = (dz / math.sqrt(math.pi * alpha * time) + HS.dt / time) * exact[k]
        assert abs(HS.sensor_temps[k, 0] - exact[k]) < tol


def test_time_varying_optics_follow_the_emulator():
    """With HS.absorption given, the map is re-evaluated when mua(t) changes."""
    model = small_paper_model()
    calls = []

    def absorption(mua, mus):
        calls.append(float(mua[0]))
        return np.full((1, 10, 10, 5), 10.0 * mua[0])

    model.HS.absorption = absorption
    model.HS.mua_t = lambda t: 1.0 + t
    model.simulate_heat_distribution()
    assert len(calls) == 10  # one per step while the laser is on
    assert calls[0] == pytest.approx(1.05) and calls[-1] == pytest.approx(1.95)


def test_direct_monte_carlo_when_optics_change():
    model = small_paper_model(n_photons=2000)
    model.HS.duration_on, model.HS.duration_off = 0.3, 0.1
    model.HS.mus_t = lambda t: 100.0 if t < 0.2 else 200.0
    model.simulate_heat_distribution()
    assert model.HS.mc_runs == 2  # recomputed only when the properties change


@pytest.mark.parametrize(
    "mutate, pattern",
    [
        (lambda HS: setattr(HS, "dt", 0.0), r"HS\.dt must be > 0, got 0\.0"),
        (lambda HS: setattr(HS, "duration_on", -1.0), r"HS\.duration_on must be >= 0, got -1"),
        (lambda HS: setattr(HS, "temp_sensor_positions", [(0, 0, 0.3)]),
         r"temp_sensor_positions\[0\] = \(0, 0, 0\.3\) cm is outside"),
        (lambda HS: setattr(HS, "heat_boundary_type", 5), r"heat_boundary_type must be"),
        (lambda HS: setattr(HS, "theta", 0.2), r"HS\.theta"),
    ],
)
def test_bad_heat_input(mutate, pattern):
    model = small_paper_model(n_photons=1000).run_monte_carlo()
    mutate(model.HS)
    with pytest.raises(ValueError, match=pattern):
        model.simulate_heat_distribution()


def test_bad_thermal_media():
    with pytest.raises(ValueError, match=r"VHC must be > 0, got 0"):
        Medium("t", 1.0, 100.0, 0.9, 1.3, VHC=0, TC=0.0037)
    model = small_paper_model(n_photons=1000).run_monte_carlo()
    model.G.media[0].TC = None
    with pytest.raises(ValueError, match=r"G\.media\[0\]\.TC is needed"):
        model.simulate_heat_distribution()
