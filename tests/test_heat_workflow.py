"""MCmatlab's heat workflow on model.HS: phases and automatic steps, chaining, 3-D initial
temperatures, voxel results, the boiling warning, movies. The absorbed power map is given
(no Monte Carlo) so that every answer is exact."""

import math
import warnings

import numpy as np
import pytest

import fem
from mcmatlab_py import Medium, Model
from mcmatlab_py.heat import auto_dt

VHC, TC = 3.7, 0.0052


def block(n=(6, 6, 4), T0=37.0, absorbed=True):
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = n
    G.Lx, G.Ly, G.Lz = 0.3, 0.3, 0.2
    G.media = [Medium("tissue", mua=1.0, mus=10.0, VHC=VHC, TC=TC)]
    NA = np.zeros(n)
    if absorbed:
        NA[:, :, 0] = 1.0 / (G.Lx * G.Ly * G.dz)  # all of 1 W absorbed in the top layer
    model.MC.NA = NA
    HS = model.HS
    HS.P, HS.T_initial, HS.progress = 2.0, T0, False
    return model


def heat_content(model):
    """J above 0 deg C on the mesh (lumped mass, uniform VHC)."""
    return fem.lumped_mass(model.HS.mesh, VHC) @ model.HS.T_nodes


def test_auto_dt_follows_the_theta_scheme_and_mcmatlab_phases():
    model = block()
    HS = model.HS
    HS.duration_on, HS.duration_off, HS.duration_end, HS.n_pulses = 0.2, 0.8, 0.5, 2
    HS.step_control = "stability"
    model.simulate_heat_distribution()
    G = model.G
    lam = 4 * TC / VHC * (1 / G.dx**2 + 1 / G.dy**2 + 1 / G.dz**2)
    assert auto_dt((G.dx, G.dy, G.dz), [VHC], [TC]) == pytest.approx(3 / lam)
    assert auto_dt((G.dx, G.dy, G.dz), [VHC], [TC], theta=0.5) == pytest.approx(2 / lam)
    assert np.all(HS.dt_used <= 3 / lam * (1 + 1e-12))
    t = HS.sensor_times
    assert t[-1] == pytest.approx(2 * 1.0 + 0.5)
    for boundary in (0.2, 1.0, 1.2, 2.0):  # every phase ends on a step
        assert np.min(np.abs(t - boundary)) < 1e-12
    # MCmatlab's updates: 2 on + 8 off per pulse, round(10 * 0.5 / 1) = 5 at the end
    starts_lengths_updates = HS.phases()
    assert [n for _, _, n in starts_lengths_updates] == [2, 8, 2, 8, 5]
    assert len(HS.schedule(3 / lam).updates) == 25
    # insulated: the heat of the pulses stays through the cooling
    assert heat_content(model) - VHC * G.Lx * G.Ly * G.Lz * 37.0 == pytest.approx(
        HS.P * 2 * 0.2, rel=1e-10)


def test_given_dt_is_kept_and_the_end_phase_appended():
    model = block()
    HS = model.HS
    HS.duration_on, HS.duration_off, HS.duration_end, HS.dt = 0.3, 0.2, 0.25, 0.05
    model.simulate_heat_distribution()
    np.testing.assert_allclose(HS.sensor_times, 0.05 * np.arange(16), atol=1e-12)
    assert HS.dt_used == pytest.approx([0.05])


def test_chained_runs_equal_one_run():
    """Example 11: the second run starts where the first ended (T, Omega, clock)."""
    def configure(HS, on, off, end):
        HS.duration_on, HS.duration_off, HS.duration_end, HS.dt = on, off, end, 0.02
        HS.temp_sensor_positions = [(0, 0, 0), (0.05, 0, 0.1)]

    one = block()
    configure(one.HS, 0.2, 0.3, 0.0)
    one.simulate_heat_distribution()
    two = block()
    configure(two.HS, 0.2, 0.0, 0.0)
    two.simulate_heat_distribution()
    configure(two.HS, 0.0, 0.3, 0.0)
    two.simulate_heat_distribution()
    np.testing.assert_allclose(two.HS.sensor_times, one.HS.sensor_times, atol=1e-12)
    np.testing.assert_allclose(two.HS.sensor_temps, one.HS.sensor_temps, rtol=1e-12)
    np.testing.assert_allclose(two.HS.T_voxels, one.HS.T_voxels, rtol=1e-12)
    two.HS.reset()  # and afresh
    configure(two.HS, 0.2, 0.3, 0.0)
    two.simulate_heat_distribution()
    np.testing.assert_allclose(two.HS.sensor_temps, one.HS.sensor_temps, rtol=1e-12)


def test_three_dimensional_initial_temperature_relaxes_to_its_mean():
    """A hot corner in an insulated block: heat is kept exactly, and the block tends to the
    mean temperature at the rate of the slowest mode, exp(-alpha (pi / L)^2 t)."""
    model = block(n=(6, 6, 4), absorbed=False)
    G, HS = model.G, model.HS
    T0 = np.full((6, 6, 4), 20.0)
    T0[:2, :2, :2] = 80.0
    HS.T_initial = T0
    HS.duration_on, HS.duration_off, HS.dt, HS.theta = 0.0, 40.0, 0.5, 0.5
    model.simulate_heat_distribution()
    mean = T0.mean()
    volume = G.Lx * G.Ly * G.Lz
    assert heat_content(model) == pytest.approx(VHC * volume * mean, rel=1e-12)
    alpha = TC / VHC
    slowest = math.exp(-alpha * (math.pi / G.Lx) ** 2 * 40.0)  # the x and y modes decay slowest
    spread = np.abs(HS.T_voxels - mean).max()
    assert spread < 2 * 60.0 * slowest and spread < 1.0
    assert HS.T_voxels.shape == (6, 6, 4) and HS.Omega_voxels.shape == (6, 6, 4)


def test_voxel_results_are_the_p1_field_at_the_centres():
    model = block()
    HS = model.HS
    HS.duration_on, HS.dt = 0.2, 0.05
    model.simulate_heat_distribution()
    G = model.G
    X, Y, Z = np.meshgrid(G.x, G.y, G.z, indexing="ij")
    P = fem.probe_matrix(HS.mesh, np.vstack([X.ravel(), Y.ravel(), Z.ravel()]))
    np.testing.assert_allclose(HS.T_voxels.ravel(), P @ HS.T_nodes, rtol=1e-13)
    assert HS.T.shape == (7, 7, 5)


def test_max_media_temps_and_the_boiling_warning():
    model = block(T0=95.0)
    HS = model.HS
    HS.duration_on, HS.dt = 0.5, 0.05
    HS.P = 20.0
    with pytest.warns(UserWarning, match="'tissue' gets hotter than 100 deg C"):
        model.simulate_heat_distribution()
    # insulated and heated from the top: the hottest moment is the end, at the surface
    assert HS.max_media_temps[0] == pytest.approx(HS.T_nodes.max(), rel=1e-12)
    assert HS.max_media_temps[0] > 100
    cool = block(T0=37.0)
    cool.HS.duration_on, cool.HS.dt, cool.HS.P = 0.1, 0.05, 0.01
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cool.simulate_heat_distribution()


def test_movie_is_an_mp4_of_the_updates(tmp_path):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    import matplotlib

    matplotlib.use("Agg")
    model = block()
    HS = model.HS
    HS.duration_on, HS.duration_off, HS.n_updates = 0.1, 0.1, 2
    HS.make_movie, HS.defer_movie_write = True, True
    model.simulate_heat_distribution()
    frames = HS.movie_frames
    assert frames.shape[0] == 1 + 1 + 2  # geometry, the start, the updates (on, off)
    HS.defer_movie_write, HS.movie_path = False, str(tmp_path / "heat.mp4")
    model.simulate_heat_distribution()  # chained: appends its 2 frames, then writes
    reader = imageio_ffmpeg.read_frames(HS.movie_path)
    meta = next(reader)
    n = sum(1 for _ in reader)
    assert meta["size"] == (frames.shape[2], frames.shape[1])
    assert n == 30 + (4 + 2) + 30


@pytest.mark.parametrize("mutate, pattern", [
    (lambda HS: setattr(HS, "duration_end", -1.0), r"HS\.duration_end must be >= 0"),
    (lambda HS: setattr(HS, "n_updates", 0), r"HS\.n_updates must be >= 1"),
    (lambda HS: setattr(HS, "slice_positions", (0.5, 2, 0)), r"HS\.slice_positions"),
    (lambda HS: setattr(HS, "plot_temp_limits", (50, 40)), r"HS\.plot_temp_limits"),
    (lambda HS: setattr(HS, "T_initial", np.zeros((2, 2, 2))), r"HS\.T_initial must be"),
    (lambda HS: setattr(HS, "media_prop_recalc_period", -1), r"media_prop_recalc_period"),
])
def test_bad_workflow_input(mutate, pattern):
    model = block()
    mutate(model.HS)
    with pytest.raises(ValueError, match=pattern):
        model.simulate_heat_distribution()
