"""model.plot("G" | "MC" | "HS"; "FMC" in test_fluorescence.py): MCmatlab's figures as PNG."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mcmatlab_py import Medium, Model  # noqa: E402
from mcmatlab_py.plotting.slices import slice_indices  # noqa: E402


@pytest.fixture(scope="module")
def model():
    m = Model()
    G = m.G
    G.nx, G.ny, G.nz = 8, 8, 6
    G.Lx = G.Ly = 0.2
    G.Lz = 0.15
    G.media = [Medium("water", 0.1, 10.0, 0.9, 1.33, VHC=4.19, TC=5.8e-3),
               Medium("blood", 20.0, 100.0, 0.9, 1.33, VHC=3.8, TC=5.2e-3, E=4.48e5, A=7.6e66)]
    G.geom_func = lambda X, Y, Z: (Z > 0.05).astype(int)
    MC = m.MC
    MC.n_photons_requested, MC.seed, MC.progress = 5000, 1, False
    MC.light_source.source_type, MC.light_source.radius = "tophat", 0.05
    m.run_monte_carlo()
    HS = m.HS
    HS.P, HS.duration_on, HS.duration_off, HS.progress = 3.0, 0.2, 0.2, False
    HS.temp_sensor_positions = [(0, 0, 0.06), (0, 0, 0.1)]
    with pytest.warns(UserWarning):  # it boils
        m.simulate_heat_distribution()
    yield m
    plt.close("all")


@pytest.mark.parametrize("what, names", [
    ("G", {"geometry", "media_properties"}),
    ("MC", {"media_properties", "NA", "NFR"}),
    ("HS", {"sensor_positions", "sensor_temperatures", "temperature", "damage",
            "fractional_damage"}),
])
def test_figures_are_returned_and_saved(model, tmp_path, what, names):
    figs = model.plot(what, tmp_path / "fig.png")
    assert set(figs) == names
    for name, fig in figs.items():
        png = tmp_path / f"fig_{name}.png"
        assert png.stat().st_size > 10_000
        assert isinstance(fig, matplotlib.figure.Figure)
    plt.close("all")


def test_slices_show_the_data(model):
    """The panels hold the field's slices: NFR on a log scale, the medium map as categories."""
    figs = model.plot("MC")
    G, MC = model.G, model.MC
    ix, iy, iz = slice_indices(MC.NFR.shape, (0.5, 0.5, 0.0))
    xy, xz, yz = [ax.images[0] for ax in figs["NFR"].axes[:3]]
    np.testing.assert_array_equal(xz.get_array().filled(np.nan), MC.NFR[:, iy, :].T)
    assert isinstance(xz.norm, matplotlib.colors.LogNorm)
    assert xz.norm.vmax == pytest.approx(MC.NFR.max())
    geo = model.plot("G")["geometry"]
    np.testing.assert_array_equal(geo.axes[1].images[0].get_array(),
                                  G.medium_map()[:, iy, :].T)
    heat = model.plot("HS")
    hottest = np.unravel_index(np.argmax(model.HS.T_voxels), MC.NFR.shape)
    np.testing.assert_allclose(heat["temperature"].axes[0].images[0].get_array(),
                               model.HS.T_voxels[:, :, hottest[2]].T)
    lines = heat["sensor_temperatures"].axes[0].lines
    np.testing.assert_array_equal(lines[1].get_ydata(), model.HS.sensor_temps[:, 1])
    assert lines[0].get_label() == "1, blood"
    # the two sensors lie on one vertical: one label "1,2" in the xy panel, not two on top
    xy, xz, _ = heat["sensor_positions"].axes[:3]
    assert [t.get_text() for t in xy.texts] == ["1,2"]
    assert [t.get_text() for t in xz.texts] == ["1", "2"]
    plt.close("all")


def test_light_maps_slice_at_their_maximum_and_draw_zero_dark(model):
    """The xy slice of NA lies at the depth of NA's maximum (not the top layer, air in most
    examples), and a voxel of zero is drawn in the scale's lowest colour, not blank (which
    read as inferno's hottest)."""
    from mcmatlab_py.plotting.figures import light_slices

    MC = model.MC
    iz = np.unravel_index(np.argmax(MC.NA), MC.NA.shape)[2]
    assert light_slices(MC.NA)[2] == pytest.approx(iz / (MC.NA.shape[2] - 1))
    xy = model.plot("MC")["NA"].axes[0].images[0]
    np.testing.assert_array_equal(xy.get_array().filled(0.0),
                                  np.where(MC.NA > 0, MC.NA, 0.0)[:, :, iz].T)
    cmap = xy.get_cmap()
    np.testing.assert_allclose(cmap.get_bad(), cmap(0.0))
    assert light_slices(np.zeros((4, 4, 6))) == (0.5, 0.5, 0.0)
    plt.close("all")


def test_heat_maps_slice_through_their_maximum_unless_positions_are_set(model):
    """By default (``HS.slice_positions = None``) the temperature panels, the live plot's
    and the movie's cut through the hottest voxel and the damage panels through the most
    damaged one (MCmatlab's default, (0.5, 1, 1), drew the bottom layer and the back face:
    cold); positions the user sets are kept."""
    from mcmatlab_py.plotting.figures import heat_slices
    from mcmatlab_py.plotting.movie import TemperatureMonitor

    G, HS = model.G, model.HS
    assert HS.slice_positions is None
    T, Om = HS.T_voxels, HS.Omega_voxels
    figs = model.plot("HS")
    for name, field in (("temperature", T), ("sensor_positions", T), ("damage", Om),
                        ("fractional_damage", Om)):
        ix, iy, iz = np.unravel_index(np.argmax(field), field.shape)
        titles = [ax.get_title() for ax in figs[name].axes[:3]]
        assert titles == [f"xy at z = {G.z[iz]:.3g} cm", f"xz at y = {G.y[iy]:.3g} cm",
                          f"yz at x = {G.x[ix]:.3g} cm"], name
    for name, top in (("temperature", T.max()), ("fractional_damage", -np.expm1(-Om.max()))):
        for ax in figs[name].axes[:3]:  # each panel holds the maximum
            assert ax.images[0].get_array().max() == pytest.approx(top), (name, ax.get_title())
    # the movie's slices follow the hottest voxel from update to update
    mon = TemperatureMonitor(model, G.medium_map(), show=False, record=False)
    for hot in ((1, 6, 2), (5, 2, 4)):
        T_vox = np.full(T.shape, HS.T_initial)
        T_vox[hot] += 10.0
        mon.update(T_vox, 0.1)
        for ax in mon.axes:
            assert ax.images[0].get_array().max() == HS.T_initial + 10.0
        cut_x = [line.get_xdata()[0] for line in mon.axes[0].lines if line.get_gid() == "cut"]
        assert cut_x[1] == pytest.approx(G.x[hot[0]])
    plt.close(mon.fig)
    # nothing heated: through the middle; positions set by the user: exactly those
    assert heat_slices(HS, np.zeros(T.shape)) == (0.5, 0.5, 0.5)
    try:
        HS.slice_positions = (0.25, 0.75, 1.0)
        assert heat_slices(HS, T - HS.T_initial) == (0.25, 0.75, 1.0)
        ix, iy, iz = slice_indices(T.shape, HS.slice_positions)
        xy, xz, yz = [ax.images[0].get_array() for ax in model.plot("HS")["temperature"].axes[:3]]
        np.testing.assert_array_equal(xy, T[:, :, iz].T)
        np.testing.assert_array_equal(xz, T[:, iy, :].T)
        np.testing.assert_array_equal(yz, T[ix, :, :].T)
    finally:
        HS.slice_positions = None
    plt.close("all")


def test_fmc_needs_its_run_and_bad_names_fail(model):
    with pytest.raises(ValueError, match=r"run model.run_monte_carlo\('fluorescence'\)"):
        model.plot("FMC")
    with pytest.raises(ValueError, match="'G', 'MC', 'FMC', 'HS' or None"):
        model.plot("XX")
    empty = Model()
    empty.G.media = model.G.media
    with pytest.raises(ValueError, match="run model.run_monte_carlo"):
        empty.plot("MC")
    with pytest.raises(ValueError, match="simulate_heat_distribution"):
        empty.plot("HS")


def test_interactive_slicer_builds_off_screen(model):
    pytest.importorskip("pyvista")
    from mcmatlab_py.plotting.slicer import interactive_slicer, voxel_image

    img = voxel_image(model.G, T=model.HS.T_voxels)
    assert img.n_cells == model.G.nx * model.G.ny * model.G.nz
    # cell (i, j, k) holds T[i, j, k]
    c = img.find_containing_cell((model.G.x[2], model.G.y[5], model.G.z[3]))
    assert img.cell_data["T"][c] == pytest.approx(model.HS.T_voxels[2, 5, 3])
    plotter = interactive_slicer(model, "HS", show=False)
    plotter.close()


def test_far_field_and_boundary_figures_are_drawn_as_mcmatlab():
    """The far field as radiant intensity (per bin over its solid angle: the bins' solid
    angles sum to 4 pi), a face no light leaves drawn black from 0 with its units, and
    slice titles without rounding noise."""
    from mcmatlab_py.monte_carlo.outputs import far_field_solid_angles
    from mcmatlab_py.plotting.outputs import plot_boundary_irradiance, plot_far_field

    sr = far_field_solid_angles(12)
    assert sr.shape == (12, 12) and sr.sum() == pytest.approx(4 * np.pi, rel=1e-12)
    # a pencil beam straight down into a non-scattering slab: light leaves only at the bottom
    m = Model()
    G = m.G
    G.nx = G.ny = G.nz = 5
    G.Lx = G.Ly = G.Lz = 0.1
    G.media = [Medium("clear", 1.0, 1e-8, 1.0, 1.0)]
    G.geom_func = lambda X, Y, Z: np.zeros(X.shape, dtype=int)
    MC = m.MC
    MC.n_photons_requested, MC.seed, MC.progress = 200, 1, False
    MC.calc_normalized_irradiance = True
    MC.far_field_res = 12
    MC.light_source.source_type = "pencil"
    m.run_monte_carlo()
    fig = plot_far_field(m)
    np.testing.assert_allclose(fig.axes[0].collections[0].get_array().reshape(12, 12),
                               MC.far_field / sr, rtol=1e-12)
    fig = plot_boundary_irradiance(m)
    titles = {ax.get_title(): ax for ax in fig.axes if ax.images}
    dark = titles["NI_zneg (no light)"].images[0]
    assert dark.get_clim() == (0.0, 1.0)
    assert titles["NI_zpos"].images[0].get_clim()[0] == 0.0
    assert "W/cm" in fig.axes[-1].get_ylabel()
    # Example 17's grid: the middle voxel's centre is 6.9e-18 cm, not 0, by rounding
    from mcmatlab_py.plotting.slices import orthogonal_slices

    G.nx, G.Lx = 201, 0.1
    assert G.x[100] != 0.0
    f = plt.figure()
    orthogonal_slices(f, np.ones((201, 5, 5)), G, (0.5, 0.5, 0.5))
    assert "x = 0 cm" in f.axes[2].get_title()
    plt.close("all")


def test_example_paths_in_pyvista_have_the_laser_face_on_top():
    pv = pytest.importorskip("pyvista")
    from mcmatlab_py.plotting.outputs import plot_example_paths

    m = Model()
    G = m.G
    G.nx = G.ny = G.nz = 5
    G.Lx = G.Ly = 0.1
    G.Lz = 0.2
    G.media = [Medium("tissue", 1.0, 50.0, 0.9, 1.0)]
    G.geom_func = lambda X, Y, Z: np.zeros(X.shape, dtype=int)
    MC = m.MC
    MC.n_photons_requested, MC.seed, MC.progress = 100, 1, False
    MC.n_example_paths = 4
    MC.light_source.source_type = "pencil"
    m.run_monte_carlo()
    plotter = plot_example_paths(m, use_pyvista=True, off_screen=True)
    assert isinstance(plotter, pv.Plotter)
    # the cuboid's wireframe and a polyline per path with more than one point
    assert len(plotter.meshes) >= 2
    ren = plotter.renderer

    def screen(point):
        ren.SetWorldPoint(*point, 1.0)
        ren.WorldToDisplay()
        return np.array(ren.GetDisplayPoint()[:2])

    # the irradiated face z = 0 above the bottom z = Lz on the screen (display y points up),
    # x across it, y along the line of sight (perspective moves it only up or down)
    top, bottom = screen((0.0, 0.0, 0.0)), screen((0.0, 0.0, G.Lz))
    assert top[1] > bottom[1] and top[0] == pytest.approx(bottom[0])
    assert screen((G.Lx / 2, 0.0, 0.0))[0] != pytest.approx(top[0])
    assert screen((0.0, G.Ly / 2, 0.0))[0] == pytest.approx(top[0])
    plotter.close()
