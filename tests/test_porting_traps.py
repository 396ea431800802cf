"""MCmatlab habits that the port must take, or refuse naming its own way (issue 46)."""

import numpy as np
import pytest

import fem
from mcmatlab_py import Medium, Model

VHC, TC = 3.7, 0.0052


def block(n=(4, 4, 3), absorbed=False, media=None, geom_func=None):
    """A small insulated block heated (when ``absorbed``) by 1 W absorbed in its top layer."""
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = n
    G.Lx, G.Ly, G.Lz = 0.3, 0.3, 0.2
    G.media = media or [Medium("tissue", mua=1.0, mus=10.0, VHC=VHC, TC=TC)]
    G.geom_func = geom_func
    NA = np.zeros(n)
    if absorbed:
        NA[:, :, 0] = 1.0 / (G.Lx * G.Ly * G.dz)
    model.MC.NA = NA
    HS = model.HS
    HS.P, HS.progress = 1.0, False
    HS.duration_on, HS.duration_off, HS.dt = 0.1, 0.1, 0.05
    return model


# ------------------------------------------------------------------ 1. HS.T as the start


def test_hs_T_set_before_the_run_is_the_start_temperature():
    model = block()
    model.HS.T = 20
    model.simulate_heat_distribution()
    np.testing.assert_allclose(model.HS.T_voxels, 20.0, rtol=1e-12)
    assert model.HS.T_initial == 20.0  # recorded: a reset run starts there again
    model.HS.reset()
    model.simulate_heat_distribution()
    np.testing.assert_allclose(model.HS.T_voxels, 20.0, rtol=1e-12)


def test_hs_T_array_equals_the_same_T_initial():
    T0 = np.full((4, 4, 3), 30.0)
    T0[:2, :2, :2] = 60.0
    by_T, by_initial = block(absorbed=True), block(absorbed=True)
    by_T.HS.T = T0
    by_initial.HS.T_initial = T0.copy()
    by_T.simulate_heat_distribution()
    by_initial.simulate_heat_distribution()
    np.testing.assert_allclose(by_T.HS.T_nodes, by_initial.HS.T_nodes, rtol=1e-13)
    np.testing.assert_array_equal(by_T.HS.T_initial, T0)


def test_hs_T_and_a_different_T_initial_are_refused():
    model = block()
    model.HS.T, model.HS.T_initial = 20.0, 45.0
    with pytest.raises(ValueError, match=r"HS\.T = 20\.0 and HS\.T_initial = 45\.0"):
        model.simulate_heat_distribution()
    model.HS.T_initial = 20.0  # the same: no ambiguity
    model.simulate_heat_distribution()
    np.testing.assert_allclose(model.HS.T_voxels, 20.0, rtol=1e-12)


@pytest.mark.parametrize("value, pattern", [
    ("hot", r"HS\.T must be a number or an array of shape \(4, 4, 3\)"),
    (np.zeros((2, 2, 2)), r"HS\.T must be a number or an array of shape \(4, 4, 3\), got shape"),
    (float("nan"), r"HS\.T must be finite"),
])
def test_bad_hs_T_is_named(value, pattern):
    model = block()
    model.HS.T = value
    with pytest.raises(ValueError, match=pattern):
        model.simulate_heat_distribution()


def test_chained_run_still_continues_and_a_new_hs_T_restarts_the_temperature():
    one, two = block(absorbed=True), block(absorbed=True)
    one.HS.duration_on, one.HS.duration_off = 0.1, 0.2
    one.simulate_heat_distribution()
    two.simulate_heat_distribution()  # 0.1 on, 0.1 off
    two.HS.duration_on, two.HS.duration_off = 0.0, 0.1
    two.simulate_heat_distribution()  # chained: HS.T holds the last run's result
    np.testing.assert_allclose(two.HS.T_nodes, one.HS.T_nodes, rtol=1e-12)
    # MCmatlab's: a HS.T set between runs is where the next one starts; the clock goes on
    two.HS.T = 25.0
    two.simulate_heat_distribution()
    np.testing.assert_allclose(two.HS.T_voxels, 25.0, rtol=1e-12)
    assert two.HS.sensor_times[-1] == pytest.approx(0.4)


# ------------------------------------------------------------------ 2. TC = 0


def test_a_perfect_insulator_is_a_medium():
    assert Medium("insulator", mua=1.0, mus=10.0, VHC=3.7, TC=0).TC == 0.0
    with pytest.raises(ValueError, match=r"Medium\('x'\)\.TC must be >= 0, got -1\.0"):
        Medium("x", mua=1.0, mus=10.0, VHC=3.7, TC=-1.0)
    with pytest.raises(ValueError, match=r"VHC must be > 0, got 0"):
        Medium("x", mua=1.0, mus=10.0, VHC=0, TC=0)


@pytest.mark.parametrize("dt", [0.05, None])
def test_heat_deposited_in_an_insulator_stays_where_it_was_deposited(dt):
    """The lower half is a perfect insulator heated in its deepest voxel layer: the nodes
    with only insulating elements around them rise by exactly the energy their hat
    functions receive over their heat capacity (no conduction), and the rest stays at T0."""
    media = [Medium("tissue", mua=1.0, mus=10.0, VHC=VHC, TC=TC),
             Medium("insulator", mua=1.0, mus=10.0, VHC=VHC, TC=0)]
    model = block(n=(4, 4, 4), media=media, geom_func=lambda X, Y, Z: (Z > 0.1).astype(int))
    G, HS = model.G, model.HS
    NA = np.zeros((4, 4, 4))
    NA[:, :, 3] = 1.0 / (G.Lx * G.Ly * G.dz)  # 1 W per W, all in the deepest layer
    model.MC.NA = NA
    HS.dt = dt
    model.simulate_heat_distribution()
    mesh = HS.mesh
    energy = fem.voxel_load_matrix(mesh, G.grid) @ NA.ravel() * HS.P * HS.duration_on  # J
    rise = energy / fem.lumped_mass(mesh, VHC)
    z = mesh.p[2]
    insulated = z > 0.1 + 1e-9  # node layers 3 and 4: every element around them insulates
    np.testing.assert_allclose(HS.T_nodes[insulated] - 37.0, rise[insulated], rtol=1e-10)
    np.testing.assert_allclose(HS.T_nodes[~insulated], 37.0, rtol=1e-12)


def test_all_insulators_need_a_given_time_step():
    model = block(absorbed=True, media=[Medium("insulator", mua=1.0, mus=10.0, VHC=VHC, TC=0)])
    model.HS.dt = None
    with pytest.raises(ValueError, match=r"HS\.dt = None, but every medium has TC = 0.*set "
                                         r"HS\.dt"):
        model.simulate_heat_distribution()
    model.HS.dt = 0.05  # then the heat stays in the top layer
    model.simulate_heat_distribution()
    top = model.HS.T_voxels[:, :, 0]
    assert np.all(top > 37.0) and np.all(model.HS.T_voxels[:, :, 2] == pytest.approx(37.0))


# ------------------------------------------------------------------ 3. plot(model)


def test_plot_without_a_type_draws_every_stage_that_has_outputs(tmp_path):
    """MCmatlab's ``plot(model)``: the geometry always, then each stage that has run."""
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure

    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 4, 4, 3
    G.Lx = G.Ly = G.Lz = 0.1
    G.media = [Medium("dye", mua=lambda w: 5.0 if w < 500 else 1.0, mus=10.0, g=0.9, n=1.0,
                      VHC=VHC, TC=TC, QY=0.5)]
    for sim, wavelength, seed in ((model.MC, 450.0, 1), (model.FMC, 550.0, 2)):
        sim.n_photons_requested, sim.seed, sim.progress = 2000, seed, False
        sim.wavelength = wavelength
    model.MC.light_source.source_type = "plane_wave"
    model.HS.progress, model.HS.duration_on, model.HS.dt = False, 0.02, 0.01
    try:
        def stages(figs):
            assert figs and all(isinstance(f, Figure) for f in figs.values())
            return {name.split("_", 1)[0] for name in figs}

        assert stages(model.plot()) == {"G"}
        model.run_monte_carlo()
        assert stages(model.plot()) == {"G", "MC"}
        model.run_monte_carlo("fluorescence")
        model.simulate_heat_distribution()
        figs = model.plot(path=tmp_path / "all")
        assert stages(figs) == {"G", "MC", "FMC", "HS"}
        assert {"G_geometry", "MC_NA", "FMC_NA", "HS_temperature"} <= set(figs)
        assert (tmp_path / "all_HS_temperature.png").is_file()
        assert set(model.plot("MC")) == {"media_properties", "NA", "NFR"}  # as before
    finally:
        plt.close("all")


# ------------------------------------------------------------------ 4. MCmatlab's other names


def fluorescent_model(seed=2, n_photons=2000):
    model = Model()
    G = model.G
    G.nx, G.ny, G.nz = 3, 3, 4
    G.Lx = G.Ly = G.Lz = 0.1
    G.media = [Medium("dye", mua=lambda w: 5.0 if w < 500 else 1.0, mus=10.0, g=0.9, n=1.0,
                      QY=0.5)]
    for sim, wavelength in ((model.MC, 450.0), (model.FMC, 550.0)):
        sim.n_photons_requested, sim.seed, sim.progress = n_photons, 1, False
        sim.wavelength = wavelength
    model.MC.light_source.source_type = "plane_wave"
    model.FMC.seed = seed
    return model


def test_reset_returns_the_model_with_defaults():
    """MCmatlab's ``model = reset(model, what)``: settings and results back to the defaults."""
    model = block(absorbed=True)
    model.simulate_heat_distribution()
    model.MC.n_photons_requested = 123
    assert model.reset("HS") is model
    assert model.HS.T is None and model.HS.duration_on == Model().HS.duration_on
    assert model.MC.n_photons_requested == 123 and model.G.nx == 4  # the others kept
    model = model.reset()
    assert model.MC.n_photons_requested is None and model.MC.NA is None
    assert model.G.nx == Model().G.nx and model.G.media == []
    with pytest.raises(ValueError, match=r"model\.reset takes 'G', 'MC', 'FMC', 'HS' or None "
                                         r"\(all\), got 'heat'"):
        model.reset("heat")


def test_media_prop_params_names_the_way_of_this_port():
    from mcmatlab_py import NotBuiltError

    G = Model().G
    for name in ("mediaPropParams", "media_prop_params"):
        with pytest.raises(NotBuiltError, match=rf"MCmatlab's G\.{name} has no counterpart in "
                                                r"this port: G\.media is the list of Medium "
                                                r"itself.*G\.media = my_media\(params\)"):
            setattr(G, name, [1.0])
        assert not hasattr(G, name)


def test_combine_models_combines_fluorescence_runs_by_photon_count():
    """MCmatlab's ``combineModels(models, 'FMC')``: two fluorescence runs of one excitation
    averaged with weights FMC.n_photons, as one run of all their photons."""
    import copy

    from mcmatlab_py.combine import combine_models

    a = fluorescent_model().run_monte_carlo()
    b = copy.deepcopy(a)
    a.FMC.seed, b.FMC.seed, b.FMC.n_photons_requested = 2, 3, 6000
    a.run_monte_carlo("fluorescence")
    b.run_monte_carlo("fluorescence")
    ab = combine_models([a, b], simulation="FMC")
    wa, wb = a.FMC.n_photons, b.FMC.n_photons
    assert ab.FMC.n_photons == wa + wb
    np.testing.assert_allclose(ab.FMC.NA, (wa * a.FMC.NA + wb * b.FMC.NA) / (wa + wb),
                               rtol=1e-12)
    np.testing.assert_array_equal(ab.MC.NA, a.MC.NA)  # the excitation unchanged
    assert ab.FMC.emitted_power == a.FMC.emitted_power
    mc = combine_models([a, b])  # the excitations (one run, copied): as before, by MC photons
    assert mc.MC.n_photons == 2 * a.MC.n_photons
    np.testing.assert_allclose(mc.MC.NA, a.MC.NA, rtol=1e-12)
    np.testing.assert_array_equal(mc.FMC.NA, a.FMC.NA)  # the FMC of the first, untouched
    with pytest.raises(ValueError, match=r"powers = \[1\.0, 2\.0\] with simulation='FMC'"):
        combine_models([a, b], powers=[1.0, 2.0], simulation="FMC")
    other = fluorescent_model().run_monte_carlo()
    other.MC.seed = 9
    other.run_monte_carlo().run_monte_carlo("fluorescence")
    with pytest.raises(ValueError, match=r"the excitations differ \(MC\.NA or MC\.wavelength\)"):
        combine_models([a, other], simulation="FMC")
    with pytest.raises(ValueError, match=r"every model must have run its FMC Monte Carlo"):
        combine_models([a, fluorescent_model().run_monte_carlo()], simulation="FMC")
    with pytest.raises(ValueError, match=r"simulation must be 'MC' or 'FMC', got 'HS'"):
        combine_models([a], simulation="HS")
