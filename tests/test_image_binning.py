"""Super-pixels (ThermalImage.binning): the filter reads the means of b x b blocks of a
camera's pixels; their operator, noise and model error are the block means of the
pixels' (an equivalence against the unbinned camera, to rounding)."""

import numpy as np
import pytest

from enkf.tissue.image import ThermalImage


def cameras(b=2, rotation=7.0, mirror=True):
    kw = dict(shape=(8, 6), pixel_size=(0.011, 0.013), spot_center=(2.7, 3.4),
              rotation=rotation, mirror=mirror, model_error_lengths=(0.0, 0.02, 0.1),
              subsamples=3)
    return ThermalImage.registered(**kw), ThermalImage.registered(binning=b, **kw)


def block_mean(b, shape):
    """(n_super, n_pixels): the mean of each b x b block, super-pixels in C order."""
    ny, nx = shape
    rows, cols = np.divmod(np.arange(ny * nx), nx)
    M = np.zeros(((ny // b) * (nx // b), ny * nx))
    M[(rows // b) * (nx // b) + cols // b, np.arange(ny * nx)] = 1.0 / b ** 2
    return M


@pytest.mark.parametrize("b", [1, 2])
def test_binned_readings_model_error_and_noise_are_the_block_means(b):
    fine, cam = cameras(b)
    M = block_mean(b, fine.shape)
    assert cam.n_pixels == fine.n_pixels // b ** 2 and cam.grid == (8 // b, 6 // b)
    # the model error: the covariance of the block means of the pixels' errors
    C = fine.error_correlation()
    assert np.allclose(cam.error_correlation(), M @ C @ M.T, rtol=1e-12, atol=1e-14)
    pts = np.array([[0.01, -0.02], [0.0, 0.0], fine.pixel_centers()[5, :2]])
    assert np.allclose(cam.point_correlation(pts), fine.point_correlation(pts) @ M.T,
                       rtol=1e-12, atol=1e-14)
    assert cam.reading_noise_var == pytest.approx(fine.noise_var / b ** 2)
    # the footprint average: a super-pixel's probes are its pixels' probes
    rng = np.random.default_rng(0)
    f = rng.standard_normal(fine.sample_points().shape[0])
    order = np.lexsort(cam.sample_points()[:, :2].T.round(12)[::-1])
    ref = np.lexsort(fine.sample_points()[:, :2].T.round(12)[::-1])
    assert np.allclose(cam.sample_points()[order], fine.sample_points()[ref], atol=1e-12)
    g = np.empty_like(f)
    g[order] = f[ref]  # the same field at the binned camera's probes
    assert np.allclose(cam.average(g), M @ fine.average(f), rtol=1e-12, atol=1e-12)
    frames = rng.standard_normal((3, *fine.shape))
    assert np.allclose(cam.readings(frames), frames.reshape(3, -1) @ M.T, rtol=1e-12)


def test_unbinned_is_the_camera_as_before():
    fine, cam = cameras(1)
    assert cam == fine and cam.binning == 1
    frames = np.arange(2 * 48.0).reshape(2, 8, 6)
    assert np.array_equal(cam.readings(frames), frames.reshape(2, -1))


def test_a_dead_pixel_blanks_its_block_and_bad_binning_is_refused():
    _, cam = cameras(2)
    f = np.ones((8, 6))
    f[3, 5] = np.nan
    r = cam.readings(f).reshape(cam.grid)
    assert np.isnan(r[1, 2]) and np.isfinite(np.delete(r.ravel(), 1 * 3 + 2)).all()
    with pytest.raises(ValueError, match="binning"):
        cameras(4)  # 6 columns are not whole blocks of 4
    with pytest.raises(ValueError, match="camera's shape"):
        cam.readings(np.ones((4, 3)))
