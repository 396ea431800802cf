"""Arrhenius damage and VTU/PVD export."""

import numpy as np
import pytest

from fem import (
    GAS_CONSTANT,
    TimeSeriesWriter,
    advance_damage,
    arrhenius_increment,
    box_mesh,
    element_to_node,
    fractional_damage,
    update_damage,
    write_vtu,
)

E_BLOOD, A_BLOOD = 2.8e5, 7.6e66  # J/mol, 1/s (blood, MCmatlab's media list)


def test_arrhenius_matches_formula_and_broadcasts():
    T_old = np.array([[37.0, 60.0, 80.0], [37.0, 70.0, 90.0]])
    T_new = T_old + 2.0
    E = np.array([E_BLOOD, E_BLOOD, 0.0])
    A = np.array([A_BLOOD, A_BLOOD, 0.0])  # third node not damageable
    d = arrhenius_increment(T_old, T_new, 0.01, E, A)
    Tm = T_old + 1.0
    expected = 0.01 * A * np.exp(-E / (GAS_CONSTANT * (Tm + 273.15)))
    expected[:, 2] = 0.0
    np.testing.assert_allclose(d, expected, rtol=1e-14)
    assert GAS_CONSTANT == 8.3144598
    om = update_damage(np.zeros_like(T_old), T_old, T_new, 0.01, E, A)
    np.testing.assert_allclose(fractional_damage(om), 1 - np.exp(-om))
    # constant temperature for a time t gives omega = t * rate
    om = np.zeros(3)
    for _ in range(100):
        om = update_damage(om, T_old[0] + 30, T_old[0] + 30, 0.01, E, A)
    rate = A * np.exp(-E / (GAS_CONSTANT * (T_old[0] + 30 + 273.15)))
    np.testing.assert_allclose(om, 1.0 * np.where(A > 0, rate, 0), rtol=1e-12)


def test_trapezoid_rule_in_place_and_both_rules_agree_at_order_two():
    """The trapezoid rule is the formula; advance_damage works in place; on a linear ramp
    the two rules differ by O(dt^2), with opposite signs of the error (convex rate)."""
    T_old, T_new = np.array([[55.0, 60.0], [58.0, 61.0]]), np.array([[57.0, 66.0], [58.0, 60.0]])
    E, A = np.array([E_BLOOD, E_BLOOD]), np.array([A_BLOOD, 0.0])
    rate = lambda T: A * np.exp(-E / (GAS_CONSTANT * (T + 273.15)))  # noqa: E731
    om = np.ones((2, 2))
    assert advance_damage(om, T_old, T_new, 0.1, E, A, rule="trapezoid") is om
    np.testing.assert_allclose(om, 1 + 0.05 * (rate(T_old) + rate(T_new)), rtol=1e-14)
    np.testing.assert_allclose(
        arrhenius_increment(T_old, T_new, 0.1, np.tile(E, (2, 1)), A, "trapezoid"), om - 1,
        rtol=1e-14)  # per-member E
    ramp = lambda dt: np.arange(0.0, 1.0 + dt / 2, dt) * 10 + 50  # noqa: E731
    gaps = []
    for dt in (0.1, 0.05, 0.025):
        T = ramp(dt)
        mid, trap = (arrhenius_increment(T[:-1], T[1:], dt, E_BLOOD, A_BLOOD, r).sum()
                     for r in ("midpoint", "trapezoid"))
        assert mid < trap
        gaps.append((trap - mid) / trap)
    assert np.polyfit(np.log([0.1, 0.05, 0.025]), np.log(gaps), 1)[0] == pytest.approx(2, abs=0.1)
    with pytest.raises(ValueError, match="rule must be one of"):
        arrhenius_increment(37.0, 38.0, 0.1, E_BLOOD, A_BLOOD, rule="simpson")
    with pytest.raises(ValueError, match=r"omega must be a float64 array of shape \(2, 2\)"):
        advance_damage(np.zeros(2), T_old, T_new, 0.1, E, A)


def test_damage_bad_input():
    with pytest.raises(ValueError, match="dt must be > 0, got 0.0"):
        arrhenius_increment(37.0, 38.0, 0.0, E_BLOOD, A_BLOOD)
    with pytest.raises(ValueError, match="A must be finite and >= 0"):
        arrhenius_increment(37.0, 38.0, 0.1, E_BLOOD, -1.0)


def test_element_to_node():
    mesh = box_mesh(2, 1, 1, 1.0, 1.0, 1.0)
    v = np.repeat([0.0, 5.0], 6)  # voxel 0 medium value 0, voxel 1 value 5
    nmax = element_to_node(mesh, v, "max")
    shared = np.flatnonzero(np.isclose(mesh.p[0], 0.0))
    assert np.all(nmax[shared] == 5.0)
    assert np.all(element_to_node(mesh, v, "min")[shared] == 0.0)


def test_vtu_and_pvd_read_back_with_meshio_and_pyvista(tmp_path):
    meshio = pytest.importorskip("meshio")
    pv = pytest.importorskip("pyvista")
    mesh = box_mesh(3, 2, 2, 0.3, 0.2, 0.2)
    T = 37.0 + mesh.p[2]
    media = np.arange(mesh.t.shape[1]) % 3
    f = write_vtu(tmp_path / "a.vtu", mesh, point_data={"T": T}, cell_data={"medium": media})
    m = meshio.read(f)
    np.testing.assert_allclose(m.points, mesh.p.T)
    np.testing.assert_array_equal(m.cells_dict["tetra"], mesh.t.T)
    np.testing.assert_allclose(m.point_data["T"], T)
    np.testing.assert_array_equal(m.cell_data["medium"][0], media)
    g = pv.read(f)
    assert g.n_points == mesh.p.shape[1] and g.n_cells == mesh.t.shape[1]
    np.testing.assert_allclose(g.point_data["T"], T)

    with TimeSeriesWriter(tmp_path / "run.pvd", mesh, cell_data={"medium": media}) as w:
        for k in range(3):
            w.write(0.1 * k, T=T + k, omega=np.zeros_like(T))
    reader = pv.get_reader(str(tmp_path / "run.pvd"))
    np.testing.assert_allclose(reader.time_values, [0.0, 0.1, 0.2])
    reader.set_active_time_value(0.2)
    last = reader.read()[0]
    np.testing.assert_allclose(last.point_data["T"], T + 2)
    with pytest.raises(ValueError, match=r"point_data 'T' must have"):
        write_vtu(tmp_path / "b.vtu", mesh, point_data={"T": T[:-1]})


def test_damage_integral_checked_once_adds_what_advance_damage_adds():
    """fem.DamageIntegral (E and A checked when made) adds bit for bit what
    advance_damage adds, for both rules, and refuses what advance_damage refuses."""
    import fem

    rng = np.random.default_rng(0)
    E = np.where(rng.random(50) < 0.3, 0.0, 4.2e5)
    A = np.where(E > 0, 7.6e66, 0.0)
    T0, T1 = rng.uniform(37, 90, 50), rng.uniform(37, 90, 50)
    for rule in fem.damage.RULES:
        a, b = np.zeros(50), np.zeros(50)
        fem.advance_damage(a, T0, T1, 1e-3, E, A, rule)
        fem.DamageIntegral(E, A, rule).advance(b, T0, T1, 1e-3)
        np.testing.assert_array_equal(a, b)
        assert a.max() > 0
    d = fem.DamageIntegral(E, A)
    with pytest.raises(ValueError, match="dt"):
        d.advance(np.zeros(50), T0, T1, 0.0)
    with pytest.raises(ValueError, match="omega"):
        d.advance(np.zeros(49), T0, T1, 1e-3)
    with pytest.raises(ValueError, match="A must be"):
        fem.DamageIntegral(E, -A)
