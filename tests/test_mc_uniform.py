"""The one-medium Monte Carlo kernel (mcmatlab_py.monte_carlo._uniform) and its random draws.

The kernel itself is held to the published and analytic references of
tests/test_mc_physics.py and tests/test_mc_references.py, which run blocks of one medium
and so take it; here: its exponential and azimuth draws, when it is chosen, and its
agreement with the general kernel on what only it computes differently.
"""

import math

import numba
import numpy as np
import pytest
from scipy import stats

from mcmatlab_py import Medium, Model
from mcmatlab_py._rng import next_azimuth, next_exponential, seed_stream

N_DRAWS = 400_000


@numba.njit(cache=True)
def _exponentials(seed, n):
    s0, s1, s2, s3 = seed_stream(seed, 0)
    out = np.empty(n)
    for i in range(n):
        s0, s1, s2, s3, out[i] = next_exponential(s0, s1, s2, s3)
    return out


@numba.njit(cache=True)
def _azimuths(seed, n):
    s0, s1, s2, s3 = seed_stream(seed, 0)
    out = np.empty((n, 2))
    for i in range(n):
        s0, s1, s2, s3, out[i, 0], out[i, 1] = next_azimuth(s0, s1, s2, s3)
    return out


def test_ziggurat_exponentials_follow_the_exponential_law():
    x = _exponentials(np.uint64(7), N_DRAWS)
    assert x.min() >= 0.0
    # Kolmogorov-Smirnov: a false alarm once in 10^4 runs
    assert stats.kstest(x, "expon").pvalue > 1e-4
    se = 1.0 / math.sqrt(N_DRAWS)  # sd of the mean of a unit exponential
    assert abs(x.mean() - 1.0) < 4.5 * se
    # variance 1: the sd of a sample variance of exponentials is sqrt(8 / n)
    assert abs(x.var() - 1.0) < 4.5 * math.sqrt(8.0 / N_DRAWS)


@pytest.mark.parametrize("edge", [1.0, 4.0, 7.697117470131487, 9.0])
def test_ziggurat_exponentials_have_the_right_tail(edge):
    """Mass beyond the layers' edges and in the tail (layer 0, past x = 7.70)."""
    x = _exponentials(np.uint64(11), 2_000_000)
    p = math.exp(-edge)
    assert abs((x > edge).mean() - p) < 4.5 * math.sqrt(p * (1 - p) / x.size)


def test_ziggurat_draws_depend_on_the_seed_only():
    a = _exponentials(np.uint64(3), 1000)
    np.testing.assert_array_equal(a, _exponentials(np.uint64(3), 1000))
    assert not np.array_equal(a, _exponentials(np.uint64(4), 1000))


def test_azimuth_is_a_uniform_angle():
    cs = _azimuths(np.uint64(5), N_DRAWS)
    np.testing.assert_allclose(np.hypot(cs[:, 0], cs[:, 1]), 1.0, atol=1e-12)
    psi = np.arctan2(cs[:, 1], cs[:, 0])
    assert stats.kstest(psi, stats.uniform(loc=-math.pi, scale=2 * math.pi).cdf).pvalue > 1e-4
    # quadrant balance of sin(psi) cos(psi), which a biased disc sampler would tilt
    assert abs((cs[:, 0] * cs[:, 1]).mean()) < 4.5 * math.sqrt(0.125 / N_DRAWS)


def block(boundary_type=1, n_media=1, n_photons=20_000, seed=1, matched=True):
    model = Model()
    model.G.nx, model.G.ny, model.G.nz = 20, 20, 10
    model.G.Lx, model.G.Ly, model.G.Lz = 0.5, 0.5, 0.25
    tissue = Medium("tissue", mua=1.0, mus=100.0, g=0.9, n=1.3)
    model.G.media = [tissue] if n_media == 1 else [
        tissue, Medium("copy", tissue.mua, tissue.mus, tissue.g, tissue.n)]
    if n_media == 2:
        model.G.geom_func = lambda X, Y, Z: (Z > 0.1).astype(int)
    model.MC.n_photons_requested = n_photons
    model.MC.seed = seed
    model.MC.progress = False
    model.MC.matched_interfaces = matched
    model.MC.boundary_type = boundary_type
    model.MC.light_source.radius = 0.1
    return model


def test_the_one_medium_kernel_is_chosen_only_where_it_applies():
    """Escaping faces and one medium: the one-medium kernel (other numbers than the general
    kernel for the same seed); cyclic sides or several media: the general kernel, whose
    numbers a second medium identical to the first does not change."""
    from mcmatlab_py.monte_carlo._kernel import transport_batch  # noqa: F401 (the module compiles)
    from mcmatlab_py.monte_carlo._uniform import uniform_path_applies

    nref = np.array([1.3])
    ab = (np.array([1.0]), np.array([100.0]))
    assert uniform_path_applies(0, 1, nref, *ab, None)
    assert not uniform_path_applies(-1, 1, nref, *ab, None)  # several media
    for bt in (0, 2, 3):
        assert not uniform_path_applies(0, bt, nref, *ab, None)
    assert not uniform_path_applies(0, 1, np.array([np.inf]), *ab, None)  # a perfect mirror
    assert not uniform_path_applies(0, 1, nref, np.zeros(1), np.zeros(1), None)  # vacuum
    assert not uniform_path_applies(0, 1, nref, *ab, np.array([0], dtype=np.int32))  # table
    assert uniform_path_applies(0, 1, nref, *ab, np.array([-1], dtype=np.int32))
    one = block(boundary_type=3).run_monte_carlo().MC.NA
    two = block(boundary_type=3, n_media=2).run_monte_carlo().MC.NA
    np.testing.assert_array_equal(one, two)  # general kernel both times
    fast = block().run_monte_carlo().MC.NA
    walk = block(n_media=2).run_monte_carlo().MC.NA
    assert not np.array_equal(fast, walk)


@pytest.mark.parametrize("matched", [True, False])
def test_one_medium_kernel_same_result_any_thread_count(matched):
    runs = []
    for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        model = block(matched=matched, n_photons=5000)
        model.MC.n_threads = threads
        MC = model.run_monte_carlo().MC
        runs.append((MC.NA, MC.escaped, MC.specular_reflectance))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    assert runs[0][1:] == runs[1][1:]
