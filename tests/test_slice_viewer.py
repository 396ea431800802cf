"""MCmatlab's NdimSliderPlot counterpart (mcmatlab_py.plotting.slice_viewer), headless."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mcmatlab_py import Model  # noqa: E402
from mcmatlab_py.plotting.slice_viewer import laser_face_on_top, slice_viewer  # noqa: E402


def field(*shape):
    return np.arange(np.prod(shape), dtype=float).reshape(shape)


def test_sliders_move_the_slices():
    data = field(5, 6, 7)
    viewer = slice_viewer(data)
    viewer.sliders["z"].set_val(4)
    np.testing.assert_array_equal(viewer.slice("xy"), data[:, :, 4].T)
    viewer.sliders["y"].set_val(1)
    np.testing.assert_array_equal(viewer.slice("xz"), data[:, 1, :].T)
    viewer.sliders["x"].set_val(3)
    np.testing.assert_array_equal(viewer.slice("yz"), data[3, :, :].T)
    assert viewer.index == {"x": 3, "y": 1, "z": 4}


def test_wavelength_and_time_sliders():
    data = field(4, 5, 6, 3, 2)  # (nx, ny, nz, wavelength, time)
    G = Model().G
    G.nx, G.ny, G.nz = 4, 5, 6
    viewer = slice_viewer(data, G, wavelength=[500, 550, 600], time=[0.0, 0.1])
    assert set(viewer.sliders) == {"x", "y", "z", "wavelength [nm]", "time [s]"}
    viewer.sliders["wavelength [nm]"].set_val(2)
    viewer.sliders["time [s]"].set_val(1)
    viewer.sliders["z"].set_val(5)
    np.testing.assert_array_equal(viewer.slice("xy"), data[:, :, 5, 2, 1].T)
    assert viewer.sliders["wavelength [nm]"].valtext.get_text() == "600"
    # z into the tissue: the xz panel's first row is z = 0 (its extent runs top to bottom)
    left, right, bottom, top = viewer.images["xz"].get_extent()
    assert top < bottom and top == pytest.approx(0.0)


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="data must be"):
        slice_viewer(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="wavelength must have 3 values"):
        slice_viewer(np.zeros((2, 2, 2, 3)), wavelength=[1, 2])


def test_pyvista_view_puts_the_laser_face_on_top():
    pv = pytest.importorskip("pyvista")
    plotter = pv.Plotter(off_screen=True)
    plotter.add_mesh(pv.Box((-0.05, 0.05, -0.05, 0.05, 0.0, 0.1)))
    laser_face_on_top(plotter)
    assert tuple(plotter.camera.up) == pytest.approx((0.0, 0.0, -1.0))
    # looking along the y axis at the xz plane
    pos, focal = np.array(plotter.camera.position), np.array(plotter.camera.focal_point)
    d = (focal - pos) / np.linalg.norm(focal - pos)
    assert abs(d[1]) == pytest.approx(1.0)
    plotter.close()
