"""How long to keep the laser on (enkf.tissue.advice): the forecast against the forward
model run by hand, the damage of known temperature histories, the target and stop times
by brute force, the bank's mixture, the config's errors and the files identify writes."""

import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

import fem
from enkf.app.cli import main
from enkf.tissue import TissueForwardModel, identify
from enkf.tissue.advice import AdviceRow, Advisor, MemberAdvice, Plan, online_ensembles
from enkf.tissue.advice.forecast import damage, first_crossing, heat, low_rank
from enkf.tissue.drift import DriftBank, weighted_quantiles
from enkf.tissue.risk import MCMATLAB_A, MCMATLAB_E
from mcmatlab_py.heat import HeatSimulation

E, A = MCMATLAB_E, MCMATLAB_A
R_GAS = 8.3144598  # J/(mol K), MCmatlab's value
EX = Path(__file__).parents[1] / "examples"


def rate(T):
    """Arrhenius rate (1/s) at T deg C, written out independently of the modules."""
    return A * np.exp(-E / (R_GAS * (np.asarray(T, float) + 273.15)))


def hot_setup(tissue, **kw):
    """The small tissue at 37 deg C under 2 W for 3 s: the target 0.0625 cm deep coagulates."""
    args = dict(T_initial=37.0, max_dt=0.1,
                power=HeatSimulation(P=2.0, duration_on=3.0, duration_off=2.0).laser_power)
    args.update(kw)
    return tissue.setup(**args)


LIMITS = dict(E=E, A=A, target=[[0.0, 0.0, 0.0625]], protected=[[0.0, 0.0, 0.125]],
              protected_T=45.0, protected_omega=1.0, surface_T=70.0)


def members(adv, n=5, seed=0):
    rng = np.random.default_rng(seed)
    X = 37.0 + rng.uniform(0.0, 6.0, (n, adv.model.mesh.p.shape[1]))
    theta = np.column_stack([rng.uniform(0.5, 2.0, n), rng.uniform(50, 200, n)])
    return X, theta


def by_hand(adv, X, theta, powers):
    """(N, K+1, p) the points' temperatures: the forward model stepped under ``powers``."""
    model = TissueForwardModel(adv.setup)
    T, out = np.array(X), [adv.P @ X.T]
    for k, P in enumerate(powers):
        T = model.step(T, theta, k * adv.step, (k + 1) * adv.step, P)
        out.append(adv.P @ T.T)
    return np.array(out).transpose(2, 0, 1)


# ------------------------------------------------------------------ the forecast
@pytest.mark.parametrize("boundary", ["insulating", "convective and fixed"])
@pytest.mark.parametrize("engine", ["adjoint", "direct"])
def test_a_members_forecast_is_the_forward_model_run_by_hand(tissue, engine, boundary):
    kw = {}
    if boundary != "insulating":  # a convective top at 20 deg C, the bottom held at 37
        kw["heat_boundary"] = fem.HeatBoundary({
            "z-": fem.FaceBC("convective", temperature=20.0, h=0.01),
            "z+": fem.FaceBC("fixed", temperature=37.0)})
    adv = Advisor(hot_setup(tissue, **kw), engine=engine, **LIMITS)
    assert adv.engine == engine
    X, theta = members(adv)
    H, G = adv.forecast.responses(X, theta)
    P = np.array([adv.plan.mean_power(k * 0.1, (k + 1) * 0.1) for k in range(adv.K)])
    for c in (adv.K, 0, 17):  # the plan, off now, off after 17 steps
        on = np.where(np.arange(adv.K) < c, P, 0.0)
        np.testing.assert_allclose(heat(H, G, P, np.full(len(X), c)), by_hand(adv, X, theta, on),
                                   rtol=0, atol=1e-7)


def test_members_with_their_own_heat_capacity_are_stepped_one_by_one(tissue):
    s = hot_setup(tissue, estimate=("mua", "mus", "VHC", "TC"))
    adv = Advisor(s, **LIMITS)
    assert adv.engine == "direct"
    X, theta = members(adv)
    theta = np.column_stack([theta, [3.0, 3.5, 4.0, 4.5, 5.0], [0.003, 0.004, 0.005, 0.002, 0.0037]])
    H, G = adv.forecast.responses(X, theta)
    P = np.full(adv.K, 2.0)
    np.testing.assert_allclose(heat(H, G, P, np.full(5, adv.K)), by_hand(adv, X, theta, P),
                               atol=1e-9)
    with pytest.raises(ValueError, match="a heat step the members share"):
        Advisor(s, engine="adjoint", **LIMITS)


def test_low_rank_keeps_its_error_bound():
    rng = np.random.default_rng(1)
    M = rng.standard_normal((200, 20)) @ rng.standard_normal((20, 300)) + 1e-13 * rng.random((200, 300))
    Q, B = low_rank(M, 1e-10)
    assert Q.shape[1] < 64 and np.abs(M - Q @ B).max() <= 1e-10 * np.abs(M).max()
    full = rng.standard_normal((80, 90))  # no low rank: kept whole
    Q, B = low_rank(full, 1e-10)
    np.testing.assert_array_equal(Q @ B, full)


# ------------------------------------------------------------------ the damage
def test_damage_of_known_temperature_histories():
    h = 0.05
    T = np.full((1, 41, 1), 58.0)  # held: Omega = k t, reaching 1 at 1/k exactly
    final, path = damage(E, A, h, np.zeros((1, 1)), T, path=True)
    assert final[0, 0] == pytest.approx(rate(58.0) * 2.0, rel=1e-12)
    t1 = first_crossing(path, 0.0, h)[0]
    assert t1 == pytest.approx(1.0 / rate(58.0), rel=1e-9)
    # a linear ramp 50 -> 70 deg C over 1 s: the trapezoid converges at order 2
    exact = quad(lambda t: rate(50.0 + 20.0 * t), 0.0, 1.0, epsabs=0, epsrel=1e-13)[0]
    errs, hs = [], np.array([0.1, 0.05, 0.025])
    for hh in hs:
        ramp = (50.0 + 20.0 * np.arange(round(1 / hh) + 1) * hh)[None, :, None]
        errs.append(abs(damage(E, A, hh, np.zeros((1, 1)), ramp)[0, 0] - exact) / exact)
    assert abs(np.polyfit(np.log(hs), np.log(errs), 1)[0] - 2.0) < 0.1
    # never reached: inf; reached at the start: the start
    assert first_crossing(np.array([[0.0, 0.5, 0.9], [1.2, 2.0, 3.0]]), 4.0, 0.1).tolist() \
        == [np.inf, 4.0]


# ------------------------------------------------------------------ times and risks
def test_target_and_stop_times_and_risks_by_brute_force(tissue):
    adv = Advisor(hot_setup(tissue), **LIMITS)
    X, theta = members(adv, n=4, seed=3)
    X = np.minimum(X, 40.0)  # the start at most 40 deg C: every member needs the laser
    t0 = 0.5
    tr = adv._track("x", t0, X, 0)
    res = adv.member_advice(tr, X, theta)
    P = np.array([adv.plan.mean_power(t0 + k * 0.1, t0 + (k + 1) * 0.1) for k in range(adv.K)])
    K = int(np.ceil((adv.plan.end + adv.tail - t0) / 0.1 - 1e-9))
    tg = adv.slices["target"]

    def omega(c):  # the target's Omega along the forecast, laser off after c steps
        Y = by_hand(adv, X, theta, np.where(np.arange(K) < c, P[:K], 0.0))
        om = np.zeros((len(X), 1))
        out = [om.copy()]
        for k in range(K):
            fem.advance_damage(om, Y[:, k, tg], Y[:, k + 1, tg], 0.1, E, A, rule="trapezoid")
            out.append(om.copy())
        return np.array(out)[:, :, 0].T, Y  # (N, K+1)

    om_plan, Y_plan = omega(K)
    for n in range(len(X)):
        k = int(np.argmax(om_plan[n] >= 1))
        assert k > 0 and t0 + (k - 1) * 0.1 < res.target_time[n] <= t0 + k * 0.1
        a, b = om_plan[n, k - 1], om_plan[n, k]
        assert res.target_time[n] == pytest.approx(t0 + (k - 1 + (1 - a) / (b - a)) * 0.1, abs=1e-9)
        # the stop time: laser off at the step before it does not coagulate, after it does
        assert t0 < res.stop_time[n] <= res.target_time[n]
        c = int(np.floor((res.stop_time[n] - t0) / 0.1 + 1e-9))
        assert omega(c)[0][n, -1] < 1.0 <= omega(c + 1)[0][n, -1]
    # the protected point's temperature limit under the plan and with the laser off now
    pr = adv.slices["protected"]
    np.testing.assert_array_equal(res.risks["protected_plan"],
                                  (Y_plan[:, :, pr].max(axis=(1, 2)) >= 45.0)
                                  | (omega_final(adv, Y_plan, pr) >= 1.0))
    # the hottest the protected point and the surface get under the plan (the track
    # starts here, so nothing hotter came before)
    for region in ("protected", "surface"):
        np.testing.assert_allclose(res.peak_T[region],
                                   Y_plan[:, :, adv.slices[region]].max(axis=(1, 2)),
                                   rtol=0, atol=1e-8)
    Y_off = by_hand(adv, X, theta, np.zeros(K))
    np.testing.assert_array_equal(res.risks["surface_off"],
                                  Y_off[:, :, adv.slices["surface"]].max(axis=(1, 2)) >= 70.0)


def omega_final(adv, Y, sl):
    om = np.zeros((Y.shape[0], sl.stop - sl.start))
    for k in range(Y.shape[1] - 1):
        fem.advance_damage(om, Y[:, k, sl], Y[:, k + 1, sl], 0.1, E, A, rule="trapezoid")
    return om.max(axis=1)


def test_the_mixture_weighs_each_filters_members():
    adv = object.__new__(Advisor)
    adv.quantiles = (0.05, 0.95)
    a = MemberAdvice(1.0, 11.0, np.array([2.0, 3.0, np.inf]), np.array([1.5, 2.5, np.inf]),
                     {"protected_plan": np.array([True, False, False])}, 0.01,
                     {"protected": np.array([50.0, 46.0, 44.0])})
    b = MemberAdvice(1.0, 11.0, np.array([4.0, 5.0]), np.array([3.0, 4.0]),
                     {"protected_plan": np.array([True, True])}, 0.02,
                     {"protected": np.array([52.0, 51.0])})
    row = Advisor.mix(adv, [(3.0, a), (1.0, b)])
    assert isinstance(row, AdviceRow) and row.time == 1.0 and row.wall_s == pytest.approx(0.03)
    assert row.p_target == pytest.approx(0.75 * 2 / 3 + 0.25)
    assert row.risks["protected_plan"] == pytest.approx(0.75 / 3 + 0.25)
    big = 11.0 + 1e9
    ref = weighted_quantiles([np.r_[2.0, 3.0, big][:, None], np.r_[4.0, 5.0][:, None]],
                             [0.75, 0.25], [0.5, 0.05, 0.95])[:, 0]
    ref = np.where(ref > 11.0, np.inf, ref)
    np.testing.assert_allclose(row.target_time, ref)
    assert row.target_time[2] == np.inf  # the upper end beyond the horizon
    peak = weighted_quantiles([np.r_[50.0, 46.0, 44.0][:, None], np.r_[52.0, 51.0][:, None]],
                              [0.75, 0.25], [0.5, 0.05, 0.95])[:, 0]
    np.testing.assert_allclose(row.peak_T["protected"], peak)
    assert peak[1] < 46.0 < peak[0] < 50.0 < peak[2]  # the heavier filter's members lead
    d = row.as_dict((0.05, 0.95))
    assert list(d)[:5] == ["time_s", "target_time_median_s", "target_time_q5_s",
                           "target_time_q95_s", "p_target"]
    assert [d[f"protected_peak_T_{c}_C"] for c in ("median", "q5", "q95")] == list(peak)


def test_identify_with_a_drift_bank_mixes_its_filters_by_weight(tissue):
    s = hot_setup(tissue, drift=DriftBank(), n_members=12)
    times, data = tissue.twin_data(s, 1.2, 90.0, times=0.1 * np.arange(1, 26))
    adv = Advisor(s, **LIMITS)
    est = identify(s, times, data + 37.0, callback=adv)
    rows = adv.table(est)
    assert len(rows) == len(times) + 1 and set(adv.tracks) >= {"still"}
    k = 10
    # the drifting filters without a restart are one filter, which carries their weights
    comps, w = est.components, dict.fromkeys(adv.tracks, 0.0)
    for n, wn in est.component_weights.items():
        w[next(t for t in adv.tracks if comps[t] is comps[n])] += wn[k]
    assert sum(w.values()) == pytest.approx(1.0)
    ref = adv.mix([(w[n], adv.tracks[n].advice[k]) for n in adv.tracks])
    assert rows[k].target_time == pytest.approx(ref.target_time)
    assert rows[k].risks == pytest.approx(ref.risks)
    assert all(np.isfinite(r.target_time[0]) for r in rows[5:])
    # online: one reading at a time, the bank's weights after each
    from enkf.tissue import OnlineIdentifier

    ident, onl = OnlineIdentifier(s), Advisor(s, **LIMITS)
    for t, y in zip(times[:8], data[:8] + 37.0, strict=True):
        ident.update(t, y)
        row = onl.online(ident)
    assert row.time == pytest.approx(times[7]) and np.isfinite(row.target_time[0])
    assert sum(w for _, w, _, _ in online_ensembles(ident)) == pytest.approx(1.0)


def test_the_advice_of_drifting_filters_that_resume_one_run(tissue):
    """The bank's later drifting filters resume the first one's run at its first restart
    (enkf.tissue.identify.RunHead): after it their advice is, number for number, that of
    filters run from the first reading, and before it the table takes the first one's
    (the same members)."""
    from enkf.tissue.drift import identify_bank
    from enkf.tissue.identify import identify_single

    s = hot_setup(tissue, drift=DriftBank(restart_delay=0.3, restart_weight=0.0), n_members=12)
    times, data = tissue.twin_data(s, 1.2, 90.0, times=0.1 * np.arange(1, 41))

    def from_the_start(*args, head=None, on_head=None, **kw):
        return identify_single(*args, **kw)

    runs = []
    for run in (identify_single, from_the_start):
        adv = Advisor(s, **LIMITS)
        runs.append((identify_bank(s, times, data + 37.0, run, callback=adv), adv))
    (est, adv), (alone, adv_alone) = runs
    assert alone.component_forks is None
    (name, (source, first)), = est.component_forks.items()
    assert source == "drifting-2" and 0 < first < len(times)
    own, whole = adv.tracks[name].advice, adv_alone.tracks[name].advice
    assert sorted(own) == list(range(first + 1, len(times) + 1))
    for k in range(len(times) + 1):
        ref = whole[k] if k > first else adv_alone.tracks[source].advice[k]
        np.testing.assert_array_equal((own if k > first else adv.tracks[source].advice)[k]
                                      .target_time, ref.target_time)
    # the table: the same as the whole runs' where the resumed filter's early steps are
    # its source's (identical members, pooled once)
    alone.component_forks = est.component_forks
    for a, b in zip(adv.table(est), adv_alone.table(alone), strict=True):
        np.testing.assert_array_equal(a.target_time, b.target_time)
        assert a.risks == b.risks


def test_bad_arguments_are_refused(tissue):
    s = hot_setup(tissue)
    for kw, match in ((dict(target=[[0, 0, 0.5]]), "target points must lie in the tissue"),
                      (dict(target=[[0.001, 0.002], [0.001, 0.002], [0.01, 0.02]]),
                       "holds no node"),
                      (dict(protected_T=None, protected_omega=None), "needs a limit"),
                      (dict(quantiles=(0.5, 0.9)), "quantiles"),
                      (dict(step=0.0), "step"), (dict(engine="fast"), "engine")):
        with pytest.raises(ValueError, match=match):
            Advisor(s, **{**LIMITS, **kw})
    with pytest.raises(ValueError, match="coagulation"):
        Advisor(hot_setup(tissue, parameter_model="coagulation"), **LIMITS)
    with pytest.raises(ValueError, match="starts before"):
        Plan(1.0, ((0.0, 2.0), (1.0, 3.0)))
    p = Plan(2.0, ((1.0, 2.0), (3.0, 3.5)))
    assert p.end == 3.5 and p.mean_power(1.5, 3.25) == pytest.approx(2.0 * 0.75 / 1.75)
    hs = HeatSimulation(P=0.7, duration_on=1.5, duration_off=1.0, n_pulses=2)
    q = Plan.from_heat_simulation(hs)
    for a, b in ((0.0, 0.1), (1.45, 1.55), (1.0, 4.0), (2.4, 2.6)):
        assert q.mean_power(a, b) == pytest.approx(hs.mean_laser_power(a, b))


# ------------------------------------------------------------------ the command line
TINY = (EX / "tiny.toml").read_text().replace(
    "TC = 0.0037       # W cm^-1 K^-1", "TC = 0.0037\nE = 422.5e3\nA = 7.6e66").replace(
    "T_initial = 0.0         # deg C", "T_initial = 37.0")
ADVICE = ("\n[advice]\ntarget_depth = 0.05\nprotected_depth = 0.2\nprotected_T = 45.0\n"
          "surface_T = 60.0\nplan_power = 8.0\nplan_pulses = [[0.0, 4.0]]\n")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("emulator-cache"))


def run(*argv):
    return main([str(a) for a in argv])


@pytest.fixture
def hot_files(tmp_path):
    cfg = tmp_path / "advice.toml"
    cfg.write_text(TINY + ADVICE)
    rows = (EX / "tiny_data.csv").read_text().splitlines()
    data = tmp_path / "d.csv"
    data.write_text("\n".join([rows[0]] + [f"{t},{float(v) + 37.0:.4f}" if v else f"{t},"
                                           for t, v in (r.split(",") for r in rows[1:])]) + "\n")
    return cfg, data


def test_identify_writes_the_advice(tmp_path, cache, hot_files, capsys):
    cfg, data = hot_files
    out = tmp_path / "id"
    assert run("identify", cfg, "--data", data, "--out", out, "--quiet", "--cache-dir", cache) == 0
    said = [line for line in capsys.readouterr().out.splitlines() if ": advice at 2 s: " in line]
    assert len(said) == 1 and "target coagulated at" in said[0] and "hottest" in said[0]
    lines = (out / "advice.csv").read_text().splitlines()
    head = lines[0].split(",")
    assert head[:5] == ["time_s", "target_time_median_s", "target_time_q5_s",
                        "target_time_q95_s", "p_target"]
    assert {"p_protected_plan", "p_surface_off", "stop_time_median_s"} <= set(head)
    assert len(lines) == 1 + 21  # the prior and 20 readings
    table = np.genfromtxt(out / "advice.csv", delimiter=",", skip_header=1)
    assert np.all((table[:, 4] >= 0) & (table[:, 4] <= 1)) and np.isfinite(table[-1, 1])
    adv = json.loads((out / "summary.json").read_text())["advice"]
    assert adv["points_cm"]["target"] == [[0.0, 0.0, 0.05]] and adv["plan"]["power_W"] == 8.0
    assert adv["final"]["time_s"] == pytest.approx(2.0) and adv["engine"] == "adjoint"
    assert (out / "figures" / "estimates.png").exists()


def test_follow_writes_the_advice_with_each_line(tmp_path, cache, hot_files, capsys):
    cfg, data = hot_files
    live = tmp_path / "live.csv"
    lines = data.read_text().splitlines()

    def writer():
        time.sleep(0.5)
        with open(live, "w") as f:
            for line in lines[:10]:
                f.write(line + "\n")
                f.flush()
                time.sleep(0.02)
            f.write("# end\n")

    th = threading.Thread(target=writer)
    th.start()
    out = tmp_path / "follow"
    assert run("identify", cfg, "--follow", live, "--out", out, "--quiet", "--cache-dir", cache,
               "--idle-timeout", "5") == 0
    th.join()
    est = (out / "estimates.csv").read_text().splitlines()
    assert est[0].endswith(",target_time_median_s") and len(est) == 10
    adv = (out / "advice.csv").read_text().splitlines()
    assert len(adv) == 10
    for a, e in zip(adv[1:], est[1:], strict=True):  # the same median, to the CSV's digits
        assert float(a.split(",")[1]) == pytest.approx(float(e.split(",")[-1]), rel=1e-5)
    assert json.loads((out / "run.json").read_text())["advice"]["final"]["time_s"] == pytest.approx(0.9)
    assert "advice at 0.9 s: " in capsys.readouterr().out


@pytest.mark.parametrize("new, message", [
    ("target_depth = 0.5", "advice.target_depth must be <= 0.25, got 0.5"),
    ("target_depth = 0.05\ntarget_point = [0.0, 0.0, 0.1]", "give one of advice.target_depth"),
    ("target_region = [[0.01, 0.02], [0.01, 0.02], [0.01, 0.02]]", "holds no node"),
    ("target_point = [0.3, 0.0, 0.1]", "outside the tissue"),
    ("target_depth = 0.05\nsurface_T = 30.0", "not above the start temperature"),
    ("target_depth = 0.05\nplan_pulses = [[2.0, 1.0]]", "advice.plan_pulses[0]"),
    ("target_depth = 0.05\nquantiles = [0.5, 0.9]", "advice.quantiles"),
    ("target_depth = 0.05\nstep = 1e-6", "forecast steps"),
    ("target_depth = 0.05\ndrift = \"trend\"", "advice.drift must be one of"),
    ("target_dept = 0.05", "unknown key advice.target_dept"),
    ("protected_T = 50.0\ntarget_depth = 0.05", "need the protected tissue"),
])
def test_bad_advice_exits_2_and_writes_nothing(tmp_path, capsys, new, message):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(TINY + "\n[advice]\n" + new + "\n")
    out = tmp_path / "o"
    assert run("identify", cfg, "--data", EX / "tiny_data.csv", "--out", out) == 2
    assert message in capsys.readouterr().err and not out.exists()


def test_advice_needs_the_damage_law(tmp_path, capsys):
    cfg = tmp_path / "nolaw.toml"
    cfg.write_text((EX / "tiny.toml").read_text() + ADVICE)
    assert run("identify", cfg, "--data", EX / "tiny_data.csv", "--out", tmp_path / "o") == 2
    assert "G.media[0].E" in capsys.readouterr().err


def test_the_advice_in_one_line():
    from enkf.tissue.advice import advice_line

    final = {"time_s": 2.5, "target_time_median_s": 3.1, "target_time_q5_s": 2.8,
             "target_time_q95_s": None, "p_target": 0.9, "stop_time_median_s": 2.6,
             "stop_time_q5_s": 2.2, "stop_time_q95_s": 2.9, "p_protected_plan": 0.25,
             "protected_peak_T_median_C": 48.04, "protected_peak_T_q5_C": 45.0,
             "protected_peak_T_q95_C": 52.3}
    line = advice_line({"final": final, "limits": {"protected_T": 50.0}})
    assert line == ("advice at 2.5 s: target coagulated at 3.10 s (2.80 to beyond the "
                    "horizon), stop at 2.60 s (2.20 to 2.90); P(protected over 50 deg C) "
                    "0.25, hottest 48.0 deg C (45.0 to 52.3)")
    final.update(target_time_median_s=None, p_target=0.0)
    assert "target not coagulated within the horizon (P = 0.00)" in advice_line(
        {"final": final, "limits": {}})
    assert advice_line({}) == "advice: no reading"
