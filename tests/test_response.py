"""The smoother's readings as a linear function of the sources (enkf.tissue.response)
against the member runs they stand for."""

from __future__ import annotations

import numpy as np
import pytest

import fem
from enkf.tissue import TissueForwardModel
from enkf.tissue.response import sensor_response
from enkf.tissue.smooth import smooth_drifting
from mcmatlab_py.heat import HeatSimulation


def _member_runs(model, P, T0, theta, times):
    """(N, M, p) the readings of each member run step by step (the reference)."""
    edges = np.r_[0.0, times]
    T = np.tile(T0, (theta.shape[1], 1))
    out = np.empty((theta.shape[1], times.size, P.shape[0]))
    for k in range(times.size):
        T = model(T, np.ascontiguousarray(theta[k]), edges[k], edges[k + 1])
        out[:, k] = (P @ T.T).T
    return out


def _paths(rng, M, N):
    """(M, N, 2) optics that drift differently in each member."""
    start = np.exp(rng.normal(0, 0.3, (N, 2))) * [1.0, 100.0]
    slope = rng.normal(0, 0.5, (N, 2))
    return start[None] * np.exp(np.linspace(0, 1, M)[:, None, None] * slope[None])


@pytest.mark.parametrize("kw", [
    {},  # one heat step per reading, insulating faces
    {"max_dt": 0.05, "heat_boundary": fem.HeatBoundary({
        "z-": fem.FaceBC("convective", temperature=20.0, h=2e-3),
        "z+": fem.FaceBC("fixed", temperature=37.0)})},
])
def test_the_response_gives_the_member_runs_readings(tissue, kw):
    """Two pulses (the laser on, off, on again within the window, switching within a
    reading's interval), members whose optics drift apart, two sensors, sub-steps and
    convective and fixed faces: the response's readings are the step-by-step runs' to
    1e-9 deg C of a rise of several degrees."""
    power = HeatSimulation(P=0.5, duration_on=0.65, duration_off=0.4, n_pulses=2).laser_power
    s = tissue.setup(power=power, T_initial=37.0, **kw)
    model = TissueForwardModel(s)
    P = fem.probe_matrix(model.mesh, np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.1]]).T)
    times = 0.1 * np.arange(1, 21)
    theta = _paths(np.random.default_rng(0), times.size, 7)
    T0 = np.full(model.mesh.p.shape[1], 37.0)
    response = sensor_response(model, P, times, T0)
    assert response is not None and 1 <= response.rank <= 2 * times.size * (1 + bool(kw))
    ref = _member_runs(model, P, T0, theta, times)
    assert np.ptp(ref) > 2.0
    np.testing.assert_allclose(response.readings(theta), ref, rtol=0, atol=1e-9)


def test_the_response_declines_where_the_readings_are_not_linear(tissue):
    """Estimated VHC and TC (the heat operator changes per member) or readings at uneven steps:
    no response (the smoother runs the members)."""
    s = tissue.setup()
    model = TissueForwardModel(s)
    P = fem.probe_matrix(model.mesh, np.zeros((3, 1)))
    T0 = np.full(model.mesh.p.shape[1], s.T_initial)
    assert sensor_response(model, P, 0.1 * np.arange(1, 5), T0) is not None
    assert sensor_response(model, P, np.array([0.1, 0.2, 0.35]), T0) is None
    thermal = TissueForwardModel(tissue.setup(estimate=("mua", "mus", "VHC", "TC")))
    assert sensor_response(thermal, P, 0.1 * np.arange(1, 5), T0) is None


def test_the_smoother_gives_the_same_optics_with_and_without_the_response(tissue,
                                                                           monkeypatch):
    """The drifting smoother's members (knots and the logistic) with the response and with
    member runs: the same numbers to rounding."""
    import enkf.tissue.smooth as smooth

    s = tissue.setup(n_members=30)
    times, data = tissue.twin_data(s, 1.4, 80.0)
    for form in (3, "logistic"):
        fast = smooth_drifting(s, times, data, knots=form)
        with monkeypatch.context() as m:
            m.setattr(smooth, "sensor_response", lambda *a: None)
            slow = smooth_drifting(s, times, data, knots=form)
        np.testing.assert_allclose(fast.theta, slow.theta, rtol=1e-7)


def test_a_window_without_the_laser_reads_the_free_cooling(tissue):
    """No power over the window: every member reads the laser-off run, whatever its
    optics (the absorption model is not called)."""
    s = tissue.setup(power=HeatSimulation(P=0.0, duration_on=1.0).laser_power,
                     T_initial=37.0)
    model = TissueForwardModel(s)
    P = fem.probe_matrix(model.mesh, np.zeros((3, 1)))
    times = 0.1 * np.arange(1, 6)
    response = sensor_response(model, P, times, np.full(model.mesh.p.shape[1], 37.0))
    theta = _paths(np.random.default_rng(1), times.size, 3)
    np.testing.assert_allclose(response.readings(theta), 37.0, atol=1e-9)


def test_constant_optics_read_the_absorption_once_and_the_same(tissue):
    """Optics constant over the window (the constant smoother's members): the absorption
    model is called once for all intervals, and the readings are the member runs'."""
    calls = []

    def counted(mua, mus):
        calls.append(len(mua))
        return tissue.absorption(mua, mus)

    s = tissue.setup(absorption=counted, T_initial=37.0)
    model = TissueForwardModel(s)
    P = fem.probe_matrix(model.mesh, np.zeros((3, 1)))
    times = 0.1 * np.arange(1, 16)
    T0 = np.full(model.mesh.p.shape[1], 37.0)
    response = sensor_response(model, P, times, T0)
    start = _paths(np.random.default_rng(2), 1, 5)[0]
    theta = np.broadcast_to(start, (times.size, *start.shape))
    calls.clear()
    y = response.readings(theta)
    assert calls == [5]
    np.testing.assert_allclose(y, _member_runs(model, P, T0, theta, times), rtol=0, atol=1e-9)
