"""The posterior's modes from many starts (enkf.modes), checked against least-squares
problems whose minima and curvatures are known exactly; and the importance sampler seeded
by them (``amis(..., modes=...)``) on a two-mode posterior whose mass in each mode is known
in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from enkf.importance import amis
from enkf.modes import find_modes

SIGMA = 0.05


def _two_wells(U):
    """Minima at (+-1, 0.5): residuals ((u0^2 - 1) / sigma, (u1 - 0.5) / sigma)."""
    return np.column_stack([(U[:, 0] ** 2 - 1) / SIGMA, (U[:, 1] - 0.5) / SIGMA])


def test_find_modes_finds_both_minima_with_their_curvature():
    """Starts spread over the box end in the two minima (cost 0, within 1e-4); duplicates
    are merged; each Laplace covariance is (J^T J + box prior)^-1 with J = diag(2 u0,
    1) / sigma at the minimum, within 1% (forward differences)."""
    lo, hi = np.array([-2.0, -1.0]), np.array([2.0, 2.0])
    starts = np.random.default_rng(3).uniform(lo, hi, size=(12, 2))
    modes = find_modes(_two_wells, starts, lo, hi, n_iter=40)
    assert modes.U.shape == (2, 2)
    assert np.allclose(np.sort(modes.U[:, 0]), [-1.0, 1.0], atol=1e-4)
    assert np.allclose(modes.U[:, 1], 0.5, atol=1e-4)
    assert np.all(modes.cost < 1e-4) and np.all(np.diff(modes.cost) >= 0)
    prior = (4.0 / (hi - lo)) ** 2
    want = np.diag(1.0 / (np.array([4.0, 1.0]) / SIGMA ** 2 + prior))
    for C in modes.cov:
        assert np.allclose(C, want, rtol=0.01, atol=1e-9), C
    assert modes.n_evaluations > 12


def test_find_modes_stops_at_the_box():
    """The minimum a start leads to lies outside the box (u0 = 1 > hi): the search ends
    on the face u0 = hi, not outside."""
    lo, hi = np.array([-2.0, -1.0]), np.array([0.5, 2.0])
    modes = find_modes(_two_wells, np.array([[0.2, 1.5]]), lo, hi, n_iter=40)
    assert modes.U.shape == (1, 2)
    assert modes.U[0, 0] == pytest.approx(0.5) and modes.U[0, 1] == pytest.approx(0.5, abs=1e-4)
    assert modes.cost[0] == pytest.approx(0.5 * (0.25 - 1) ** 2 / SIGMA ** 2, rel=1e-6)


@pytest.mark.parametrize("kw, match", [
    (dict(lo=[0.0, 0.0], hi=[0.0, 1.0]), "hi > lo"),
    (dict(starts=np.zeros((2, 3))), "starts must have shape"),
    (dict(n_iter=0), "n_iter"),
    (dict(fd_step=0.5), "fd_step"),
    (dict(starts=np.array([[np.nan, 0.0]])), "starts"),
])
def test_find_modes_refuses_bad_input(kw, match):
    args = dict(residuals=_two_wells, starts=np.zeros((1, 2)), lo=[-2.0, -1.0], hi=[2.0, 2.0])
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        find_modes(**args)


def _two_gaussians():
    """Two Gaussian modes of mass 0.3 and 0.7 far apart (20 sd): the log density."""
    m1, m2, s = np.array([-3.0, 0.0]), np.array([3.0, 1.0]), 0.3

    def logp(U):
        a = -0.5 * np.sum((U - m1) ** 2, axis=1) / s ** 2 + np.log(0.3)
        b = -0.5 * np.sum((U - m2) ** 2, axis=1) / s ** 2 + np.log(0.7)
        return np.logaddexp(a, b)

    return m1, m2, s, logp


def test_amis_seeded_by_modes_weighs_both_modes():
    """The first guess sits in the lighter mode only. Alone, AMIS puts (almost) no weight
    on the other (the test can fail); seeded by the two modes (equal masses, wrong on
    purpose) it gives the heavier mode its mass 0.7 within 4 sqrt(0.21 / ESS)."""
    m1, m2, s, logp = _two_gaussians()
    rng = np.random.default_rng(11)
    U0 = m1 + s * rng.standard_normal((50, 2))
    alone = amis(logp, U0, np.random.default_rng(2), n_samples=3000, n_rounds=6)
    assert alone.weights[alone.U[:, 0] > 0].sum() < 0.05
    modes = (np.array([m1, m2]), np.array([np.eye(2) * s ** 2] * 2), np.array([1.0, 1.0]))
    res = amis(logp, U0, np.random.default_rng(2), n_samples=3000, n_rounds=6, modes=modes)
    heavy = res.weights[res.U[:, 0] > 0].sum()
    assert abs(heavy - 0.7) <= 4 * np.sqrt(0.21 / res.ess), (heavy, res.ess)
    assert np.all(np.abs(res.mean - (0.3 * m1 + 0.7 * m2)) <= 4 * 3.0 / np.sqrt(res.ess))


def test_amis_refuses_bad_modes():
    m1, m2, s, logp = _two_gaussians()
    U0 = m1 + s * np.random.default_rng(1).standard_normal((20, 2))
    with pytest.raises(ValueError, match="modes must be"):
        amis(logp, U0, 1, n_samples=600, modes=(np.zeros((1, 3)), np.zeros((1, 3, 3)),
                                                np.ones(1)))
    with pytest.raises(ValueError, match="masses"):
        amis(logp, U0, 1, n_samples=600, modes=(m1[None], np.eye(2)[None], np.zeros(1)))
    with pytest.raises(ValueError, match="mode_share"):
        amis(logp, U0, 1, n_samples=600, mode_share=0.9)


def test_find_modes_skips_starts_where_the_model_fails():
    """Residuals that are NaN on part of the box (a model that fails there): starts there
    give no mode, the others still find theirs; all NaN gives none."""
    def partly(U):
        r = _two_wells(U)
        r[U[:, 0] < 0] = np.nan
        return r

    lo, hi = np.array([-2.0, -1.0]), np.array([2.0, 2.0])
    starts = np.array([[-1.5, 0.0], [1.5, 0.0]])
    modes = find_modes(partly, starts, lo, hi, n_iter=40)
    assert modes.U.shape == (1, 2) and modes.U[0, 0] == pytest.approx(1.0, abs=1e-4)
    none = find_modes(lambda U: np.full((len(U), 2), np.nan), starts, lo, hi, n_iter=3)
    assert none.U.shape == (0, 2) and none.cost.shape == (0,)
