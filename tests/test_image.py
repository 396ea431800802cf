"""Whole-image observations (enkf.tissue.image) and the localized EnKF analysis."""

import numpy as np
import pytest

import fem
from enkf.analysis import enkf_localized, enkf_perturbed_obs, gaspari_cohn
from enkf.app.readers import load_frames
from enkf.tissue import TissueForwardModel, identify
from enkf.tissue.image import ThermalImage

CAMERA = ThermalImage(x_range=(-0.15, 0.15), y_range=(-0.1, 0.1), shape=(4, 6))


def test_pixel_average_of_a_linear_field_is_its_value_at_the_centre(tissue):
    mesh = tissue.grid.mesh()
    x, y, z = mesh.p
    T = 20.0 + 3.0 * x - 5.0 * y + 7.0 * z
    pix = CAMERA.matrix(mesh) @ T
    c = CAMERA.pixel_centers()
    np.testing.assert_allclose(pix, 20.0 + 3.0 * c[:, 0] - 5.0 * c[:, 1], atol=1e-12)
    np.testing.assert_allclose(CAMERA.matrix(mesh, "p1") @ T, pix, atol=1e-12)
    assert pix.shape == (24,) and c[0, 0] < c[1, 0]  # C order: x runs fastest along a row


def test_cubic_surface_interpolation_is_exact_for_cubics(tissue):
    mesh = tissue.grid.mesh()
    x, y, z = mesh.p
    T = 1 + x**3 - 2 * x * y**2 + y**3 + 5 * z
    cam = ThermalImage(CAMERA.x_range, CAMERA.y_range, CAMERA.shape, subsamples=1)
    c = cam.pixel_centers()
    exact = 1 + c[:, 0] ** 3 - 2 * c[:, 0] * c[:, 1] ** 2 + c[:, 1] ** 3
    np.testing.assert_allclose(cam.matrix(mesh) @ T, exact, atol=1e-12)
    assert np.abs(cam.matrix(mesh, "p1") @ T - exact).max() > 1e-4  # P1 is not
    with pytest.raises(ValueError, match="interpolation"):
        cam.matrix(mesh, "spline")


def test_pixel_average_of_a_curved_field_converges_with_subsamples():
    mesh = fem.BoxGrid(20, 20, 4, 0.5, 0.5, 0.25).mesh()
    x, y, _ = mesh.p
    T = np.exp(-(x**2 + y**2) / 0.01)
    fine = ThermalImage(CAMERA.x_range, CAMERA.y_range, CAMERA.shape, subsamples=64)
    exact = fine.matrix(mesh) @ T
    errs = [np.abs(ThermalImage(CAMERA.x_range, CAMERA.y_range, CAMERA.shape,
                                subsamples=s).matrix(mesh) @ T - exact).max() for s in (1, 4)]
    assert errs[1] < errs[0] / 3


@pytest.mark.parametrize("kw, pattern", [
    (dict(x_range=(0.1, -0.1)), "x_range"),
    (dict(shape=(0, 3)), "shape"),
    (dict(noise_var=-1.0), "noise_var"),
    (dict(model_error_rel_std=-0.01), "model_error_rel_std"),
    (dict(model_error_rel_std=float("nan")), "model_error_rel_std"),
    (dict(model_error_lengths=(0.02, -1.0)), "model_error_lengths"),
    (dict(model_error_lengths=()), "model_error_lengths"),
])
def test_bad_camera(kw, pattern):
    args = dict(x_range=(-0.1, 0.1), y_range=(-0.1, 0.1), shape=(2, 2))
    args.update(kw)
    with pytest.raises(ValueError, match=pattern):
        ThermalImage(**args)


def test_camera_outside_the_tissue_is_refused(tissue):
    cam = ThermalImage(x_range=(-0.3, 0.1), y_range=(-0.1, 0.1), shape=(2, 2))
    with pytest.raises(ValueError, match="outside the tissue"):
        cam.matrix(tissue.grid.mesh())


def test_load_frames(tmp_path):
    frames = np.random.default_rng(0).random((5, 4, 6))
    frames[2, 1, 3] = np.nan  # a dead pixel
    np.savez(tmp_path / "ok.npz", times=0.1 * np.arange(1, 6), frames=frames)
    t, f = load_frames(tmp_path / "ok.npz", CAMERA)
    assert f.shape == (5, 24) and np.isnan(f[2, 1 * 6 + 3]) and t[-1] == pytest.approx(0.5)
    bad = {
        "missing": dict(times=np.arange(5.0)),
        "unsorted": dict(times=np.array([0.1, 0.3, 0.2, 0.4, 0.5]), frames=frames),
        "inf": dict(times=0.1 * np.arange(1, 6), frames=np.where(np.isnan(frames), np.inf, frames)),
        "shape": dict(times=0.1 * np.arange(1, 6), frames=frames[:, :3]),
    }
    patterns = {"missing": "missing array", "unsorted": "strictly increasing", "inf": "Inf",
                "shape": "camera"}
    for name, arrays in bad.items():
        np.savez(tmp_path / f"{name}.npz", **arrays)
        with pytest.raises(ValueError, match=patterns[name]):
            load_frames(tmp_path / f"{name}.npz", CAMERA)
    (tmp_path / "junk.npz").write_text("not a zip")
    with pytest.raises(ValueError, match="not a readable NPZ"):
        load_frames(tmp_path / "junk.npz")


def test_localized_analysis_without_taper_is_the_perturbed_obs_enkf():
    rng = np.random.default_rng(4)
    E, Y = rng.random((30, 7)), rng.random((30, 3))
    y, R = np.array([0.4, 0.6, np.nan]), np.array([0.1, 0.2, 0.3])
    ones_xy, ones_yy = np.ones((7, 3)), np.ones((3, 3))
    np.testing.assert_allclose(enkf_localized(E, Y, y, R, ones_xy, ones_yy, 9),
                               enkf_perturbed_obs(E, Y, y, R, 9), atol=1e-12)
    rho = ones_xy.copy()
    rho[2] = 0.0  # a component cut off from every observation does not move
    np.testing.assert_array_equal(enkf_localized(E, Y, y, R, rho, ones_yy, 9)[:, 2], E[:, 2])
    assert gaspari_cohn(np.array([0.0, 2.0, 3.0])).tolist() == [1.0, 0.0, 0.0]


def twin_image(s, mua, mus, seed=0):
    """Frames (20, n_pixels) of the filter's own model, noise variance 0.01."""
    model = TissueForwardModel(s)
    P = CAMERA.matrix(model.mesh)
    T = np.zeros((1, model.mesh.p.shape[1]))
    times = 0.1 * np.arange(1, 21)
    frames, t0 = [], 0.0
    for t1 in times:
        T = model(T, np.array([[mua, mus]]), t0, t1)
        frames.append(P @ T[0])
        t0 = t1
    rng = np.random.default_rng(seed)
    return times, np.array(frames) + 0.1 * rng.standard_normal((len(times), CAMERA.n_pixels))


@pytest.mark.parametrize("kw", [dict(), dict(method="enkf", localization_radius=1.0)])
def test_identify_from_an_image_with_dead_pixels(kw, tissue):
    s = tissue.setup(sensor_positions=np.zeros((0, 3)), image=CAMERA, **kw)
    times, frames = twin_image(s, 1.4, 100.0)
    frames[3, :5] = np.nan  # dead pixels in one frame
    frames[7] = np.nan  # a lost frame: no analysis
    est = identify(s, times, frames)
    assert est.param_mean.shape == (21, 2) and est.diverged is None
    assert not est.analysed[7] and est.analysed[3]
    assert abs(est.param_mean[-1, 0] - 1.4) < 3 * est.param_std[-1, 0] + 0.05
    with pytest.raises(ValueError, match="nothing observed"):
        tissue.setup(sensor_positions=np.zeros((0, 3)))


def test_image_error_covariance_is_relative_to_the_rise_and_correlated_over_the_length():
    cam = ThermalImage(x_range=(-0.1, 0.1), y_range=(-0.05, 0.05), shape=(2, 4),
                       model_error_rel_std=0.05, model_error_lengths=(0.04, 0.0))
    T0 = 37.0
    rise = np.array([0.0, 1.0, 2.0, 4.0, 8.0, 4.0, 2.0, 1.0])
    R = cam.error_covariance(T0 + rise, T0)
    xy = cam.pixel_centers()[:, :2]
    i, j = 2, 3  # neighbours along x in the first row, 0.05 cm apart
    d = np.linalg.norm(xy[i] - xy[j])
    assert d == pytest.approx(0.05)
    assert R[i, i] == pytest.approx(2 * (0.05 * 2.0) ** 2)  # one error at each length
    assert R[i, j] == pytest.approx(0.05**2 * 2.0 * 4.0 * np.exp(-0.5 * (d / 0.04) ** 2))
    assert np.all(R[0] == 0) and np.allclose(R, R.T)
    assert np.linalg.eigvalsh(R).min() > -1e-12  # a covariance
    # a fall below the initial temperature is an error of the same size
    assert np.allclose(cam.error_covariance(T0 - rise, T0), R)
    # no correlation length: independent pixels
    flat = ThermalImage(cam.x_range, cam.y_range, cam.shape, model_error_rel_std=0.05,
                        model_error_lengths=[0.0])
    assert np.allclose(flat.error_covariance(T0 + rise, T0), np.diag((0.05 * rise) ** 2))
    with pytest.raises(ValueError, match="predicted"):
        cam.error_covariance(np.zeros(3), T0)


def test_the_image_model_error_widens_the_bands_and_can_be_turned_off(tissue):
    """A model error of the pixels is less information: wider parameter bands than the
    pixel noise alone gives, on the same data and random numbers."""
    import dataclasses

    sd = {}
    for rel in (0.0, 0.05):
        cam = dataclasses.replace(CAMERA, model_error_rel_std=rel)
        s = tissue.setup(sensor_positions=np.zeros((0, 3)), image=cam)
        times, frames = twin_image(s, 1.4, 100.0)
        est = identify(s, times, frames)
        assert est.diverged is None
        sd[rel] = est.param_std[-1]
    assert np.all(sd[0.05] > 1.2 * sd[0.0])
