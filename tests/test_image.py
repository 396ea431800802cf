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


def _small_camera():
    """A 2 x 4 camera with a relative model error of 0.05 at 0.04 cm and per pixel, a
    rise over T0 = 37 deg C, its error covariance and its pixel centres."""
    cam = ThermalImage(x_range=(-0.1, 0.1), y_range=(-0.05, 0.05), shape=(2, 4),
                       model_error_rel_std=0.05, model_error_lengths=(0.04, 0.0))
    T0 = 37.0
    rise = np.array([0.0, 1.0, 2.0, 4.0, 8.0, 4.0, 2.0, 1.0])
    return cam, T0, rise, cam.error_covariance(T0 + rise, T0), cam.pixel_centers()[:, :2]


def test_image_error_covariance_is_relative_to_the_rise_and_correlated_over_the_length():
    cam, T0, rise, R, xy = _small_camera()
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


def test_discrepancy_posterior_is_the_joint_kalman_update():
    """The reported quantity z = Gx + delta_z after an analysis with the model error
    delta_y in R: the mean and variance of the exact Kalman update of the joint Gaussian
    (x, delta_z) on a linear model, where the ensemble carries x exactly."""
    from enkf.analysis import etkf
    from enkf.discrepancy import discrepancy_posterior

    rng = np.random.default_rng(3)
    n, p, N = 6, 4, 400
    H, G = rng.standard_normal((p, n)), rng.standard_normal((2, n))
    L = rng.standard_normal((n, n))
    P = L @ L.T / n
    # the model errors of (y, z): one covariance, y's block in R with the noise
    B = rng.standard_normal((p + 2, p + 2))
    K = B @ B.T / (p + 2)
    k_yy, k_zy, k_zz = K[:p, :p], K[p:, :p], K[p:, p:]
    R = k_yy + 0.3 * np.eye(p)
    x_mean, y = rng.standard_normal(n), rng.standard_normal(p)
    E = rng.multivariate_normal(x_mean, P, size=N)
    A = E - E.mean(axis=0)
    P_ens = A.T @ A / (N - 1)  # the filter knows only its ensemble: compare with it
    Ea = etkf(E, E @ H.T, y, R)
    shift, var = discrepancy_posterior(E @ G.T, E @ H.T, y, R, k_zy, np.diag(k_zz))
    # the joint update with the ensemble's covariance
    S = H @ P_ens @ H.T + R
    C_zy = G @ P_ens @ H.T + k_zy
    z_mean = G @ E.mean(axis=0) + C_zy @ np.linalg.solve(S, y - H @ E.mean(axis=0))
    z_cov = G @ P_ens @ G.T + k_zz - C_zy @ np.linalg.solve(S, C_zy.T)
    Za = Ea @ G.T
    assert np.allclose(Za.mean(axis=0) + shift, z_mean, rtol=1e-10, atol=1e-10)
    assert np.allclose(Za.var(axis=0, ddof=1) + var, np.diag(z_cov), rtol=1e-9)
    # without a model error nothing changes; diagonal R as (p,) and a missing datum
    s0, v0 = discrepancy_posterior(E @ G.T, E @ H.T, y, R, np.zeros((2, p)), np.zeros(2))
    assert np.allclose(s0, 0) and np.allclose(v0, 0)
    y_gap = y.copy()
    y_gap[1] = np.nan
    Rd = np.diag(R).copy()
    s1, v1 = discrepancy_posterior(E @ G.T, E @ H.T, y_gap, Rd, k_zy, np.diag(k_zz))
    keep = [0, 2, 3]
    s2, v2 = discrepancy_posterior(E @ G.T, (E @ H.T)[:, keep], y[keep], Rd[keep],
                                   k_zy[:, keep], np.diag(k_zz))
    assert np.allclose(s1, s2) and np.allclose(v1, v2)
    s3, v3 = discrepancy_posterior(E @ G.T, E @ H.T, np.full(p, np.nan), R, k_zy,
                                   np.diag(k_zz))
    assert np.all(s3 == 0) and np.allclose(v3, np.diag(k_zz))
    with pytest.raises(ValueError, match="shapes"):
        discrepancy_posterior(E @ G.T, E @ H.T, y, R, k_zy[:, :2], np.diag(k_zz))


def test_point_error_is_the_pixels_error_at_a_point():
    """At a pixel's centre the point's error is that pixel's: the same variance and the
    same covariance with every pixel (ThermalImage.error_covariance)."""
    cam, T0, rise, R, xy = _small_camera()
    k_zy, k_zz = cam.point_error(xy[[2, 4]], rise[[2, 4]], T0 + rise, T0)
    assert np.allclose(k_zy, R[[2, 4]]) and np.allclose(k_zz, np.diag(R)[[2, 4]])
    # between pixels: no share of the independent (length 0) part
    k_zy, k_zz = cam.point_error([[0.0, 0.0]], [3.0], T0 + rise, T0)
    assert k_zz[0] == pytest.approx(2 * (0.05 * 3.0) ** 2)
    d = np.linalg.norm(xy - 0.0, axis=1)
    assert np.allclose(k_zy[0], 0.05**2 * 3.0 * rise * np.exp(-0.5 * (d / 0.04) ** 2))
    with pytest.raises(ValueError, match="point_rise"):
        cam.point_error([[0.0, 0.0]], [1.0, 2.0], T0 + rise, T0)


def test_a_surface_point_under_a_camera_carries_the_camera_model_error(tissue):
    """With the camera's model error the tracked points on the surface are reported with
    their share of it, wider than the ensemble's own spread; the points below the surface
    with the ensemble's alone; in identify and in the online identifier."""
    import dataclasses

    from enkf.tissue import OnlineIdentifier
    from enkf.tissue.pieces import assemble

    cam = dataclasses.replace(CAMERA, model_error_rel_std=0.05)
    s = tissue.setup(sensor_positions=np.zeros((0, 3)), image=cam,
                     tracked_positions=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.1]]))
    P_track = assemble(s).P_track
    times, frames = twin_image(s, 1.4, 100.0)
    frames[5] = np.nan  # a lost frame: the error's whole variance
    bare = []  # the ensemble's own spread at each step of the same run
    est = identify(s, times, frames, callback=lambda rep: bare.append(
        (P_track @ rep.state_ensemble.T).T.std(axis=0, ddof=1)))
    bare = np.array(bare)  # steps 0..M, as the estimates
    assert bare.shape == est.tracked_std.shape
    assert np.allclose(est.tracked_std[:, 1], bare[:, 1], rtol=1e-12)
    rise = est.tracked_mean[:, 0] - s.T_initial
    heated = rise > 0.5
    assert heated.sum() > 10
    assert np.all(est.tracked_std[heated, 0] > 1.05 * bare[heated, 0])
    # no frame: the ensemble's variance plus the error's, 2 lengths of 0.05 of the rise
    k = 6  # frames[5] is the reading of step 6
    assert not est.analysed[k - 1]
    assert est.tracked_std[k, 0] ** 2 == pytest.approx(
        bare[k, 0] ** 2 + 2 * (0.05 * rise[k]) ** 2, rel=1e-9)
    ident = OnlineIdentifier(s)
    last = [ident.update(t, f) for t, f in zip(times, frames, strict=True)][-1]
    Y = (P_track @ ident._X.T).T
    assert last.tracked_std[1] == pytest.approx(Y[:, 1].std(ddof=1), rel=1e-12)
    assert last.tracked_std[0] > 1.05 * Y[:, 0].std(ddof=1)


def test_a_registered_camera_maps_its_pixels_onto_the_tissue():
    # 4 x 6 pixels of 0.05 cm, the spot at column 2.5, row 1.5: the image's centre
    cam = ThermalImage.registered((4, 6), 0.05, (2.5, 1.5))
    assert cam.x_range == pytest.approx((-0.15, 0.15)) and cam.y_range == pytest.approx((-0.1, 0.1))
    np.testing.assert_allclose(cam.pixel_centers(), CAMERA.pixel_centers(), atol=1e-12)
    # turned by 90 degrees: a pixel one column right of the spot lies along +y
    turned = ThermalImage.registered((4, 6), 0.05, (2.0, 1.0), rotation=90.0)
    c = turned.pixel_centers().reshape(4, 6, 3)
    np.testing.assert_allclose(c[1, 3, :2], [0.0, 0.05], atol=1e-12)
    np.testing.assert_allclose(c[2, 2, :2], [-0.05, 0.0], atol=1e-12)
    mirrored = ThermalImage.registered((4, 6), 0.05, (2.0, 1.0), mirror=True)
    np.testing.assert_allclose(mirrored.pixel_centers().reshape(4, 6, 3)[1, 3, :2], [-0.05, 0.0],
                               atol=1e-12)
    lo_x, hi_x, lo_y, hi_y = turned.footprint_bounds()
    assert (lo_x, hi_x, lo_y, hi_y) == pytest.approx((-0.125, 0.075, -0.125, 0.175))
    # distances between pixels, and so the model error's correlations, do not turn
    np.testing.assert_allclose(turned.error_correlation(),
                               ThermalImage.registered((4, 6), 0.05, (2.0, 1.0))
                               .error_correlation(), atol=1e-12)


def test_the_spot_centre_is_found_in_the_first_frames():
    from enkf.tissue.image import estimate_spot_center

    rng = np.random.default_rng(3)
    y, x = np.mgrid[:32, :32]
    # a round spot centred off the image's centre, rising over 10 frames, noise 0.1 deg C
    shape = np.exp(-((x - 13.3) ** 2 + (y - 18.6) ** 2) / 20.0)
    frames = 30 + np.linspace(0, 8, 10)[:, None, None] * shape + 0.1 * rng.standard_normal(
        (10, 32, 32))
    col, row = estimate_spot_center(frames, 0.1)
    assert abs(col - 13.3) < 0.15 and abs(row - 18.6) < 0.15
    assert estimate_spot_center(frames[:2], 0.1) is None  # too little rise yet
    assert estimate_spot_center(frames[:8], 0.1, complete=False) is None  # waits for 5
    assert estimate_spot_center(frames[:9], 0.1, complete=False) is not None
