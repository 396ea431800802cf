"""Risk of thermal injury from the ensemble (enkf.risk)."""

from types import SimpleNamespace

import numpy as np
import pytest

import fem
from enkf.risk import RiskTracker, plot_depth_maps
from fem.damage import GAS_CONSTANT as R_GAS  # MCmatlab's value


def feed(tracker, temps, dt=0.1):
    for k, X in enumerate(temps):
        tracker(SimpleNamespace(step=k, time=k * dt, state_ensemble=X))


def test_constant_temperature_gives_the_closed_form_damage():
    E, A, T = 4.0e5, 1.0e62, 62.0
    tr = RiskTracker(E=E, A=A, record_every=5)
    feed(tr, [np.full((4, 3), T)] * 11)
    expected = A * np.exp(-E / (R_GAS * (T + 273.15))) * 1.0  # 1 s at T
    np.testing.assert_allclose(tr.omega, expected, rtol=1e-6)
    assert [s.time for s in tr.snapshots] == pytest.approx([0.0, 0.5, 1.0])


def test_probabilities_are_ensemble_fractions():
    hot, cold = np.full((2, 5), 90.0), np.full((2, 5), 37.0)
    tr = RiskTracker(E=4.0e5, A=1.0e62, record_times=[0.5])
    feed(tr, [np.vstack([hot, cold])] * 6)
    s = tr.snapshots[0]
    np.testing.assert_allclose(s.p_damage, 0.5)  # the hot half is cooked, the cold half not
    np.testing.assert_allclose(s.p_T, 0.5)
    np.testing.assert_allclose(s.T_mean, 63.5)
    assert tr.omega[:2].min() > 1 and tr.omega[2:].max() < 1e-3


def test_ever_remembers_a_past_excursion():
    X1 = np.array([[70.0], [40.0]])
    X2 = np.array([[40.0], [40.0]])
    tr = RiskTracker(E=4.0e5, A=0.0, record_every=1)
    feed(tr, [X1, X2])
    assert tr.snapshots[-1].p_T[0] == 0 and tr.snapshots[-1].p_T_ever[0] == 0.5
    assert np.all(tr.omega == 0)  # A = 0: no damage


@pytest.mark.parametrize("kw, pattern", [
    (dict(E=-1.0, A=1.0), "RiskTracker.E"),
    (dict(E=1.0, A=np.nan), "RiskTracker.A"),
    (dict(E=1.0, A=1.0, record_every=0), "record_every"),
])
def test_bad_input(kw, pattern):
    with pytest.raises(ValueError, match=pattern):
        RiskTracker(**kw)


def test_exports(tmp_path):
    grid = fem.BoxGrid(4, 4, 2, 0.5, 0.5, 0.25)
    mesh = grid.mesh()
    n = mesh.p.shape[1]
    tr = RiskTracker(E=4.0e5, A=1.0e62, record_every=1)
    feed(tr, [np.full((3, n), 37.0), np.full((3, n), 80.0)])
    pvd = tr.write_vtu(tmp_path / "risk.pvd", mesh)
    assert pvd.exists() and len(list((tmp_path / "risk_vtu").glob("*.vtu"))) == 2
    plot_depth_maps(tmp_path / "depth.png", tr.snapshots[-1], grid)
    assert (tmp_path / "depth.png").stat().st_size > 1000
