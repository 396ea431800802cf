"""The filter step's fast paths give the numbers of the plain ones (issue #20).

Each fast path is checked against a direct computation that shares no code with it:
the ziggurat normals against the normal law (tolerances from the sample size), the
one-product ETKF against its low-rank form, the gathered sparse observation against a
dense product, the shared-basis fast diagonalization against the batched contractions.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy import stats

import enkf.analysis as an
import fem
from enkf.checks import rows_times
from enkf.random import SPLIT_MIN, standard_normal, standard_normal_later
from fem.threads import keep_freed_memory, run_blocks


def test_standard_normal_follows_the_normal_law():
    n = 1_000_000
    x = standard_normal(np.random.default_rng(5), (n,))
    se = 1 / np.sqrt(n)
    assert abs(x.mean()) < 4 * se
    assert abs(x.var() - 1) < 4 * np.sqrt(2 / n)
    assert abs(stats.kurtosis(x)) < 4 * np.sqrt(24 / n)
    assert stats.kstest(x, "norm").pvalue > 1e-4
    # the tail beyond the ziggurat's base (r = 3.4426) and the wedges: counts within 4 sd
    for c in (1.0, 2.5, 3.4426, 4.0):
        p = 2 * stats.norm.sf(c)
        assert abs(np.mean(np.abs(x) > c) - p) < 4 * np.sqrt(p * (1 - p) / n) + 1 / n


def test_standard_normal_blocks_are_independent_and_reproducible():
    shape = (50, 4851)
    assert np.prod(shape) >= SPLIT_MIN  # the two-block path
    a = standard_normal(np.random.default_rng(1), shape)
    b = standard_normal(np.random.default_rng(1), shape)
    np.testing.assert_array_equal(a, b)
    c = standard_normal(np.random.default_rng(2), shape)
    assert not np.array_equal(a, c)
    # the two halves are different streams: their correlation is that of independent data
    r = np.corrcoef(a[:25].ravel(), a[25:].ravel())[0, 1]
    assert abs(r) < 4 / np.sqrt(a[:25].size)
    assert standard_normal(np.random.default_rng(0), (0, 3)).shape == (0, 3)
    assert standard_normal(np.random.default_rng(0), (3,)).shape == (3,)


def test_standard_normal_does_not_depend_on_the_threads(monkeypatch):
    import enkf.random as er

    a = standard_normal(np.random.default_rng(9), (40, 1000))
    monkeypatch.setattr(er, "_pool", lambda: None)  # one core: the blocks in turn
    b = standard_normal(np.random.default_rng(9), (40, 1000))
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("shape", [(50, 4851), (3, 7), (0, 4)])
def test_normals_drawn_later_are_the_same_numbers(monkeypatch, shape):
    import enkf.random as er

    scale = np.linspace(0.5, 2.0, shape[1])
    rng_a, rng_b = np.random.default_rng(4), np.random.default_rng(4)
    want = standard_normal(rng_a, shape) * scale
    pending = standard_normal_later(rng_b, shape, scale)
    # the generator has moved as with the immediate draw, before the numbers are done
    assert rng_a.integers(0, 2**63) == rng_b.integers(0, 2**63)
    np.testing.assert_array_equal(pending.result(), want)
    np.testing.assert_array_equal(pending.result(), want)  # a second call: the same array
    monkeypatch.setattr(er, "_pool", lambda: None)  # one core: drawn before returning
    one = standard_normal_later(np.random.default_rng(4), shape, scale)
    np.testing.assert_array_equal(one.result(), want)


def test_filter_draws_the_next_noise_ahead_without_changing_its_numbers(monkeypatch):
    """The ETKF run draws step k+1's model noise during step k's analysis; the results
    equal those of a run that draws every noise at its own step."""
    import enkf.loop as loop
    from enkf.problem import FilterConfig, FilterProblem

    n, M = 500, 30  # 50 x 500 noise draws: the two-block path
    rng = np.random.default_rng(8)
    times = 0.1 * np.arange(1, M + 1)
    data = rng.standard_normal((M, 2))
    data[4] = np.nan  # a step without data: no analysis, the draw ahead goes on
    problem = FilterProblem(
        forecast=lambda X, th, t0, t1: 0.9 * X + th[:, :1],
        observation=sp.csr_matrix(([1.0, 1.0], ([0, 1], [3, 250])), shape=(2, n)),
        obs_times=times, obs_data=data, obs_cov=np.ones(2), model_noise=0.01,
        param_noise=0.05, prior=lambda r, N: (r.standard_normal((N, n)),
                                              r.standard_normal((N, 1))),
        tracked=np.array([3, 250, 400]))
    config = FilterConfig(method="etkf", seed=3)
    ahead = loop.run_filter(problem, config)
    init = loop._Filter.__init__

    def no_ahead(self, *a, **k):
        init(self, *a, **k)
        self._draw_ahead = False

    monkeypatch.setattr(loop._Filter, "__init__", no_ahead)
    plain = loop.run_filter(problem, config)
    np.testing.assert_array_equal(ahead.param_mean, plain.param_mean)
    np.testing.assert_array_equal(ahead.tracked_mean, plain.tracked_mean)
    np.testing.assert_array_equal(ahead.tracked_std, plain.tracked_std)


@pytest.mark.parametrize("N,p", [(50, 1), (20, 7), (60, 80)])
def test_etkf_one_product_equals_low_rank(monkeypatch, N, p):
    rng = np.random.default_rng(N + p)
    E, Y = rng.standard_normal((N, 300)), rng.standard_normal((N, p))
    y, R = rng.standard_normal(p), rng.uniform(0.5, 2, p)
    monkeypatch.setattr(an, "GEMM_MAX_MEMBERS", 10**6)
    a = an.etkf(E, Y, y, R)
    monkeypatch.setattr(an, "GEMM_MAX_MEMBERS", 0)
    b = an.etkf(E, Y, y, R)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_rows_times_matches_dense_product():
    rng = np.random.default_rng(3)
    X = rng.standard_normal((6, 500))[:, :400]  # a strided view, as the filter passes
    for density in (0.0, 0.002, 0.02, 0.6):
        H = sp.random(5, 400, density=density, format="csr", random_state=2)
        H = sp.vstack([H, sp.csr_matrix((1, 400)), H]).tocsr()  # an empty row
        np.testing.assert_allclose(rows_times(H, X), X @ H.toarray().T, atol=1e-12)
        np.testing.assert_allclose(rows_times(H.toarray(), X), X @ H.toarray().T, atol=1e-12)


def test_shared_basis_solve_equals_batched_contractions():
    from fem import fastdiag as fd

    mesh = fem.BoxGrid(6, 5, 4, 0.5, 0.5, 0.25).mesh()
    st = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, operator="kronecker", mass="averaged")
    solver = st._solver
    rng = np.random.default_rng(4)
    N = 7
    r = rng.standard_normal((N, solver.free_nodes.size))
    dinv, Phis, W = solver._cached(np.full(N, 37.6), np.full(N, 0.0037))
    assert W is None and all(P.ndim == 2 for P in Phis)
    X = r.reshape((N,) + solver.shape_f)
    for a in range(3):
        X = fd._contract(X, Phis[a], a)
    Y = X * dinv
    for a in range(3):
        Y = fd._contract(Y, fd._transpose(Phis[a]), a)
    ref = Y.reshape(N, -1)
    np.testing.assert_allclose(fd._shared_basis_solve(r, dinv, Phis, solver.shape_f), ref,
                               rtol=0, atol=1e-13 * np.abs(ref).max())


def test_heat_step_does_not_depend_on_the_threads(monkeypatch):
    import fem.threads

    mesh = fem.BoxGrid(8, 8, 4, 0.5, 0.5, 0.25).mesh()
    st = fem.HeatStepper(mesh, 3.76, 0.0037, 0.1, operator="kronecker", mass="averaged")
    rng = np.random.default_rng(6)
    Z = rng.random((12, mesh.p.shape[1] + 2))
    T = Z[:, :-2]  # a strided view of an augmented ensemble
    f = 1e-3 * rng.random(T.shape)
    out = []
    for n in (1, 2, 3):
        monkeypatch.setattr(fem.threads, "DEFAULT_THREADS", n)
        out.append(st.step(T, f))
    np.testing.assert_array_equal(out[0], out[1])
    np.testing.assert_array_equal(out[0], out[2])


def test_run_blocks_covers_every_index_once():
    seen = np.zeros(11, int)

    def mark(i0, i1):
        seen[i0:i1] += 1

    run_blocks(11, mark)
    run_blocks(11, mark, blocks=1)
    np.testing.assert_array_equal(seen, 2)


def test_keep_freed_memory_is_idempotent():
    first = keep_freed_memory()
    assert keep_freed_memory() == first


def test_box_load_matrix_equals_element_sum():
    """The column-built load matrix of a box mesh against the sum over its elements."""
    from fem.mesh import element_volumes

    grid = fem.BoxGrid(5, 4, 3, 0.5, 0.4, 0.3)
    mesh = grid.mesh()
    L = fem.voxel_load_matrix(mesh, grid)
    vox = np.repeat(np.arange(grid.nvoxels), 6)  # six Kuhn elements per voxel, in order
    w = element_volumes(mesh) / 4.0
    ref = sp.csr_matrix((np.tile(w, 4), (mesh.t.ravel(), np.tile(vox, 4))),
                        shape=(mesh.p.shape[1], grid.nvoxels))
    assert abs(L - ref).max() < 1e-14 * abs(ref).max()  # rounding of six summed terms
    np.testing.assert_allclose(np.asarray(L.sum(axis=0)).ravel(), grid.dx * grid.dy * grid.dz)


def test_release_free_memory_runs():
    from fem.threads import release_free_memory

    assert release_free_memory() in (True, False)
