"""Risk of thermal injury from the ensemble (enkf.tissue.risk): analytic damage, probabilities as
ensemble fractions, recording, bad input, exports, and an end-to-end run with identify."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import quad

import fem
from enkf.tissue import ParameterModel, TissueFilterSetup, TissueForwardModel, identify
from enkf.tissue.risk import MCMATLAB_A, MCMATLAB_E, RiskSnapshot, RiskTracker, plot_depth_maps, xz_slice
from mcmatlab_py import Medium
from mcmatlab_py.heat import HeatSimulation

R_GAS = 8.3144598  # J/(mol K), MCmatlab's value
E, A = MCMATLAB_E, MCMATLAB_A


def rate(T):
    """Arrhenius rate (1/s) at T deg C, written out independently of the module."""
    return A * np.exp(-E / (R_GAS * (np.asarray(T, float) + 273.15)))


def feed(tracker, temps, dt=0.1, t0=0.0):
    for k, X in enumerate(temps):
        tracker(SimpleNamespace(step=k, time=t0 + k * dt, state_ensemble=np.asarray(X, float)))


# ------------------------------------------------------------------ the damage integral
def test_constant_temperature_gives_the_closed_form_damage():
    T = np.array([55.0, 62.0, 70.0])  # three nodes at three temperatures, held 1 s
    tr = RiskTracker(E=E, A=A, record_every=5)
    feed(tr, [np.tile(T, (4, 1))] * 11)
    np.testing.assert_allclose(tr.omega, np.tile(rate(T) * 1.0, (4, 1)), rtol=1e-12)
    assert [s.time for s in tr.snapshots] == pytest.approx([0.0, 0.5, 1.0])
    assert [s.step for s in tr.snapshots] == [0, 5, 10]


def test_per_node_E_and_A_and_A_zero_never_damages():
    Es = np.array([E, 6.28e5, E])
    As = np.array([A, 3.1e98, 0.0])  # MCmatlab-like, Henriques' skin, a medium without damage
    tr = RiskTracker(E=Es, A=As, record_every=1)
    feed(tr, [np.full((2, 3), 65.0)] * 3, dt=0.5)
    expected = As * np.exp(-Es / (R_GAS * (65.0 + 273.15))) * 1.0
    np.testing.assert_allclose(tr.omega, np.tile(expected, (2, 1)), rtol=1e-12)
    assert np.all(tr.omega[:, 2] == 0) and np.all(tr.omega[:, :2] > 0)


def test_trapezoid_in_the_rate_converges_at_order_two():
    """A linear heating ramp: the trapezoid's error against an exact quadrature falls as dt^2,
    and one step equals the trapezoid formula exactly."""
    T_of = lambda t: 45.0 + 20.0 * t  # noqa: E731 - deg C, 45 -> 65 over 1 s
    exact = quad(lambda t: rate(T_of(t)), 0.0, 1.0, epsabs=0, epsrel=1e-13)[0]
    errs, dts = [], np.array([0.2, 0.1, 0.05, 0.025])
    for dt in dts:
        n = int(round(1.0 / dt))
        tr = RiskTracker(E=E, A=A)
        feed(tr, [np.full((1, 1), T_of(k * dt)) for k in range(n + 1)], dt=dt)
        errs.append(abs(tr.omega[0, 0] - exact) / exact)
    order = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert abs(order - 2.0) < 0.1, (order, errs)
    tr = RiskTracker(E=E, A=A)
    feed(tr, [[[45.0]], [[65.0]]], dt=1.0)
    assert tr.omega[0, 0] == pytest.approx(0.5 * (rate(45.0) + rate(65.0)), rel=1e-12)


# ------------------------------------------------------------------ probabilities
def test_half_hot_half_cold_gives_one_half():
    hot, cold = np.full((3, 5), 90.0), np.full((3, 5), 37.0)
    tr = RiskTracker(E=E, A=A, record_times=[0.5])
    feed(tr, [np.vstack([hot, cold])] * 6)
    (s,) = tr.snapshots
    np.testing.assert_allclose(s.p_damage, 0.5)
    np.testing.assert_allclose(s.p_T, 0.5)
    np.testing.assert_allclose(s.p_T_ever, 0.5)
    np.testing.assert_allclose(s.T_mean, 63.5)
    np.testing.assert_allclose(s.T_std, np.std([90.0] * 3 + [37.0] * 3, ddof=1))
    np.testing.assert_allclose(s.omega_mean, 0.5 * (rate(90.0) + rate(37.0)) * 0.5)
    assert tr.omega[:3].min() > 1 and tr.omega[3:].max() < 1e-3


def test_thresholds_are_strict_and_configurable():
    tr = RiskTracker(E=E, A=A, T_threshold=60.0, record_every=1)
    feed(tr, [np.array([[60.0, 60.001, 59.0]])])
    s = tr.snapshots[-1]
    assert s.p_T.tolist() == [0.0, 1.0, 0.0]  # "above" means strictly above
    # Omega = 2 at every node after 1 s at the temperature with rate 2 /s
    T2 = E / (R_GAS * np.log(A / 2.0)) - 273.15
    for thr, p in ((1.5, 1.0), (2.5, 0.0), (1.0, 1.0)):
        tr = RiskTracker(E=E, A=A, omega_threshold=thr, record_every=10)
        feed(tr, [np.full((1, 2), T2)] * 11)
        np.testing.assert_allclose(tr.omega, 2.0, rtol=1e-9)
        np.testing.assert_array_equal(tr.snapshots[-1].p_damage, p)
    tr = RiskTracker(E=E, A=A, T_threshold=42.5, record_every=1)
    feed(tr, [np.array([[43.0], [42.0]])])
    assert tr.snapshots[-1].p_T.tolist() == [0.5]


def test_ever_remembers_a_past_excursion():
    tr = RiskTracker(E=E, A=0.0, record_every=1)
    feed(tr, [[[70.0], [40.0]], [[40.0], [40.0]]])
    s = tr.snapshots[-1]
    assert s.p_T[0] == 0 and s.p_T_ever[0] == 0.5
    assert np.all(tr.omega == 0)  # A = 0: no damage


def test_record_times_and_restart():
    tr = RiskTracker(E=E, A=A, record_times=[1.0, 0.25, 0.3, 5.0])
    feed(tr, [np.full((2, 2), 50.0)] * 11)  # t = 0, 0.1, ..., 1.0
    # 0.25 and 0.3 both fall due at t = 0.3 (one snapshot), 1.0 at 1.0, 5.0 never
    assert [s.time for s in tr.snapshots] == pytest.approx([0.3, 1.0])
    om = tr.omega.copy()
    feed(tr, [np.full((2, 2), 50.0)] * 4)  # step 0 again: a new run
    assert [s.time for s in tr.snapshots] == pytest.approx([0.3])
    np.testing.assert_allclose(tr.omega, om * 0.3, rtol=1e-12)
    tr.update(0.35, np.full((2, 2), 50.0))  # a step without a number follows on
    assert tr.time == 0.35 and tr.snapshot().step == 4


def test_from_medium():
    m = Medium("tissue", mua=1.0, mus=100.0, g=0.9, n=1.3, VHC=3.76, TC=0.0037, E=E, A=A)
    assert RiskTracker.from_medium(m, T_threshold=55.0).E == E
    with pytest.raises(ValueError, match="'plain' has no Arrhenius"):
        RiskTracker.from_medium(Medium("plain", mua=1.0, mus=100.0))


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("kw, pattern", [
    (dict(E=-1.0, A=1.0), r"RiskTracker.E must be finite and >= 0 \(J/mol\), got -1.0"),
    (dict(E=1.0, A=np.nan), r"RiskTracker.A must be finite and >= 0 \(1/s\), got nan"),
    (dict(E=np.ones((2, 2)), A=1.0), r"RiskTracker.E must be a scalar or \(n_nodes,\).*\(2, 2\)"),
    (dict(E=1.0, A=[1.0, -3.0]), r"RiskTracker.A .* got -3.0"),
    (dict(E=1.0, A=1.0, record_every=0), "record_every must be an integer >= 1, got 0"),
    (dict(E=1.0, A=1.0, record_every=2.5), "record_every must be an integer >= 1, got 2.5"),
    (dict(E=1.0, A=1.0, T_threshold=np.inf), "T_threshold must be a finite number, got inf"),
    (dict(E=1.0, A=1.0, omega_threshold=0.0), "omega_threshold must be > 0, got 0.0"),
    (dict(E=1.0, A=1.0, record_times=[1.0, np.nan]), "record_times must be finite"),
])
def test_bad_parameters(kw, pattern):
    with pytest.raises(ValueError, match=pattern):
        RiskTracker(**kw)


def test_bad_ensembles():
    tr = RiskTracker(E=np.full(4, E), A=A)
    with pytest.raises(ValueError, match=r"RiskTracker.E has shape \(4,\), the ensemble has 3"):
        tr.update(0.0, np.zeros((2, 3)))
    tr = RiskTracker(E=E, A=A)
    with pytest.raises(ValueError, match=r"state_ensemble must be \(N, n_nodes\).*\(3,\)"):
        tr.update(0.0, np.zeros(3))
    with pytest.raises(ValueError, match="above -273.15 deg C, got min nan"):
        tr.update(0.0, np.array([[np.nan, 1.0]]))
    with pytest.raises(ValueError, match="got min -300.0"):
        tr.update(0.0, np.array([[-300.0, 1.0]]))
    with pytest.raises(ValueError, match="time must be finite"):
        tr.update(np.inf, np.zeros((1, 2)))
    tr.update(0.0, np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"time must increase: got 0.0 s after 0.0 s"):
        tr.update(0.0, np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"shape \(3, 3\), the run so far \(2, 3\)"):
        tr.update(0.1, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="no snapshots"):
        RiskTracker(E=E, A=A).write_vtu("x.pvd", None)
    with pytest.raises(ValueError, match="nothing reported"):
        RiskTracker(E=E, A=A).snapshot()


# ------------------------------------------------------------------ output
def test_xz_slice_is_exact_between_node_planes():
    grid = fem.BoxGrid(4, 5, 3, 0.5, 0.5, 0.25)  # ny odd: no node plane at y = 0
    X, Y, Z = np.meshgrid(grid.x_nodes, grid.y_nodes, grid.z_nodes, indexing="ij")
    f = (2 * X - 3 * Y + 5 * Z + 1).ravel()
    xx, zz = np.meshgrid(grid.x_nodes, grid.z_nodes, indexing="ij")
    np.testing.assert_allclose(xz_slice(f, grid, 0.0), 2 * xx + 5 * zz + 1, atol=1e-12)
    np.testing.assert_allclose(xz_slice(f, grid, 0.1), 2 * xx - 0.3 + 5 * zz + 1, atol=1e-12)
    with pytest.raises(ValueError, match=r"y must lie in \[-0.25, 0.25\] cm, got 0.3"):
        xz_slice(f, grid, 0.3)
    with pytest.raises(ValueError, match=r"values must be \(120,\)"):
        xz_slice(f[:-1], grid)


def test_vtu_series_single_file_and_depth_maps(tmp_path):
    meshio = pytest.importorskip("meshio")
    grid = fem.BoxGrid(4, 4, 2, 0.5, 0.5, 0.25)
    mesh = grid.mesh()
    n = mesh.p.shape[1]
    tr = RiskTracker(E=E, A=A, T_threshold=62.5, record_every=1)
    hot = np.vstack([np.full(n, 80.0), np.full(n, 37.0), np.full(n, 80.0)])
    feed(tr, [np.full((3, n), 37.0), hot])
    pvd = tr.write_vtu(tmp_path / "risk.pvd", mesh)
    files = sorted((tmp_path / "risk_vtu").glob("*.vtu"))
    assert pvd.exists() and len(files) == 2
    last = meshio.read(files[-1])
    assert set(last.point_data) == {"p_damage", "p_T_above_62p5C", "p_T_ever_above_62p5C",
                                    "omega_mean", "T_mean", "T_std"}
    np.testing.assert_allclose(last.point_data["p_T_above_62p5C"], 2 / 3)
    np.testing.assert_allclose(last.point_data["T_mean"], (80 + 37 + 80) / 3)
    one = meshio.read(tr.write_vtu(tmp_path / "first.vtu", mesh, which=0))
    np.testing.assert_allclose(one.point_data["p_damage"], 0.0)
    with pytest.raises(ValueError, match=r"path must end in .pvd .* got '.*risk.csv'"):
        tr.write_vtu(tmp_path / "risk.csv", mesh)
    truth = {"p_damage": [np.zeros(n), np.ones(n) * (mesh.p[2] < 0.1)]}
    png = plot_depth_maps(tmp_path / "depth.png", tr.snapshots, grid, 62.5, truth=truth)
    assert png.stat().st_size > 5000
    plot_depth_maps(tmp_path / "one.png", tr.snapshots[-1], grid)  # one snapshot
    with pytest.raises(ValueError, match="unknown field 'p_x'"):
        plot_depth_maps(tmp_path / "bad.png", tr.snapshots, grid, columns=("p_x",))


# ------------------------------------------------------------------ with the filter


def test_end_to_end_with_identify(tissue):
    """Heated from 45 deg C: the tracker's damage equals an independent trapezoid over the
    states identify reports; the top is damaged, the bottom is not; the probabilities behave."""
    setup = TissueFilterSetup(
        grid=tissue.grid, absorption=tissue.absorption, T_initial=45.0,
        power=HeatSimulation(P=2.0, duration_on=1.0, duration_off=1.0).laser_power,
        parameters=ParameterModel(nominal=tissue.nominal), n_members=20, seed=1, method="etkf")
    times = 0.1 * np.arange(1, 21)
    model = TissueForwardModel(setup)  # identical-twin data at the nominal optics
    T, t0, data = np.full((1, tissue.grid.npoints), 45.0), 0.0, []
    for t1 in times:  # the top reaches 62.5 deg C at 1 s, the bottom 51 deg C
        T = model(T, np.array([[1.0, 100.0]]), t0, t1)
        data.append(T[0, tissue.grid.node_index(3, 3, 0)])
        t0 = t1
    data = np.array(data)[:, None] + 0.1 * np.random.default_rng(0).standard_normal((20, 1))
    tracker = RiskTracker(E=E, A=A, record_times=[0.5, 1.0, 2.0])
    states = []

    def both(rep):
        states.append((rep.time, rep.state_ensemble.copy()))
        tracker(rep)

    est = identify(setup, times, data, callback=both)
    assert est.diverged is None and len(states) == 21
    ref = np.zeros_like(states[0][1])
    for (t0, X0), (t1, X1) in zip(states[:-1], states[1:], strict=True):
        ref += 0.5 * (t1 - t0) * (rate(X0) + rate(X1))
    np.testing.assert_allclose(tracker.omega, ref, rtol=1e-12)
    snaps = tracker.snapshots
    assert [s.time for s in snaps] == pytest.approx([0.5, 1.0, 2.0])
    n = tissue.grid.npoints
    assert all(isinstance(s, RiskSnapshot) and s.p_damage.shape == (n,) for s in snaps)
    for a, b in zip(snaps[:-1], snaps[1:], strict=True):  # damage only grows
        assert np.all(b.p_damage >= a.p_damage) and np.all(b.p_T_ever >= a.p_T_ever)
    for s in snaps:
        assert np.all(s.p_T_ever >= s.p_T) and 0 <= s.p_damage.min() <= s.p_damage.max() <= 1
    top = tissue.grid.node_index(3, 3, 0)
    bottom = tissue.grid.node_index(3, 3, 4)
    assert snaps[-1].p_damage[top] == 1.0 and snaps[-1].p_damage[bottom] == 0.0
    np.testing.assert_allclose(snaps[-1].T_mean, states[-1][1].mean(axis=0))
