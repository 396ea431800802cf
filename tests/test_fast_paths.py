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
from enkf.random import SPLIT_MIN, standard_normal
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
