"""The command-line tool on a tiny block: heat, identify (single, batch, follow), bad input."""

import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from enkf.app.cli import main
from mcmatlab_py.config import ConfigError

EX = Path(__file__).parents[1] / "examples"
TINY = (EX / "tiny.toml").read_text()


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("emulator-cache"))


def run(*argv):
    return main([str(a) for a in argv])


def test_heat_writes_sensors_fields_and_manifest(tmp_path, capsys):
    out = tmp_path / "heat"
    assert run("heat", EX / "tiny.toml", "--out", out, "--quiet") == 0
    printed = capsys.readouterr().out
    for f in ("sensors.csv", "summary.json", "run.json", "fields/temperature.vtu",
              "fields/absorbed_power.vtu", "figures/sensors.png", "figures/NA_slices.png"):
        assert (out / f).exists(), f
    man = json.loads((out / "run.json").read_text())
    assert man["command"] == "heat" and man["config"]["G"]["nx"] == 10
    assert man["versions"]["numpy"] and man["seed"] == 1
    table = np.loadtxt(out / "sensors.csv", delimiter=",", skiprows=1)
    assert table.shape == (21, 3) and table[10, 1] > table[10, 2] > 0  # hotter at the surface
    # the run's maximum: the pulse's peak (a sensor's), not the cooler last field's
    s = json.loads((out / "summary.json").read_text())
    assert s["T_max"] >= table[:, 1:].max() - 1e-6 > s["T_final_max"]  # csv: 8 digits
    assert f"max temperature {s['T_max']:.2f} deg C during the run" in printed


def test_identify_on_the_example_data(tmp_path, cache):
    out = tmp_path / "id"
    assert run("identify", EX / "tiny.toml", "--data", EX / "tiny_data.csv", "--out", out,
               "--quiet", "--cache-dir", cache) == 0
    for f in ("estimates.csv", "summary.json", "run.json", "fields/final.vtu",
              "figures/estimates.png"):
        assert (out / f).exists(), f
    s = json.loads((out / "summary.json").read_text())
    assert set(s["parameters"]) == {"mua", "mus"} and s["stopped"] is None
    assert s["analysed"] == 19  # 20 readings, one gap
    points = json.loads((out / "run.json").read_text())["emulator_points"]
    assert 0 < points["built"] <= points["table"]  # on demand: the points the filter read
    import meshio

    mesh = meshio.read(out / "fields" / "final.vtu")
    assert {"T_mean", "T_std", "absorbed_power_per_W"} <= set(mesh.point_data)


def test_examples_run(tmp_path, cache):
    import importlib.util

    def load(name):
        spec = importlib.util.spec_from_file_location(name, EX / f"{name}.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod

    res = load("forward_run").main(out=tmp_path / "fw", photons=5000)
    assert res["vtu"].exists() and 0 < res["absorbed_fraction"] < 1
    est = load("identify_own_data").main(cache_dir=cache)
    assert est.param_mean.shape == (21, 2)
    # the committed example data come from make_example_data.py: same times and gaps, and
    # values equal up to Monte Carlo noise (bit-equal while the kernel's streams stay)
    from enkf.app.readers import read_sensor_csv

    t_new, y_new, _ = read_sensor_csv(load("make_example_data").main(out_dir=tmp_path), 1)
    t_old, y_old, _ = read_sensor_csv(EX / "tiny_data.csv", 1)
    assert np.array_equal(t_new, t_old) and np.array_equal(np.isnan(y_new), np.isnan(y_old))
    assert np.nanmax(np.abs(y_new - y_old)) < 0.05 * np.nanmax(y_old)


def test_batch_reports_a_bad_file_and_goes_on(tmp_path, cache):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,sensor_0\n0.1,1\n0.1,2\n")
    out = tmp_path / "batch"
    assert run("identify", EX / "tiny.toml", "--data", EX / "tiny_data.csv", bad,
               tmp_path / "missing.csv", "--out", out, "--quiet", "--cache-dir", cache) == 0
    lines = (out / "batch.csv").read_text().splitlines()
    assert lines[1].split(",")[2] == "ok" and (out / "tiny_data" / "estimates.csv").exists()
    assert "error" in lines[2] and "duplicate times" in lines[2]
    assert "error" in lines[3] and "does not exist" in lines[3]


def test_follow_writes_each_estimate_as_the_data_come(tmp_path, cache):
    live = tmp_path / "live.csv"
    data = (EX / "tiny_data.csv").read_text().splitlines()

    def writer():
        time.sleep(0.5)
        with open(live, "w") as f:
            for line in data[:12]:
                f.write(line + "\n")
                f.flush()
                time.sleep(0.02)
            f.write("# end\n")

    th = threading.Thread(target=writer)
    th.start()
    out = tmp_path / "follow"
    assert run("identify", EX / "tiny.toml", "--follow", live, "--out", out, "--quiet",
               "--cache-dir", cache, "--idle-timeout", "5") == 0
    th.join()
    rows = (out / "estimates.csv").read_text().splitlines()
    assert len(rows) == 12 and rows[0].startswith("time_s,mua_mean")
    assert (out / "figures" / "estimates.png").exists() and (out / "run.json").exists()


@pytest.mark.parametrize("old, new, message", [
    ("mua = 1.0 ", "mua = -1.0 ", "mua"),
    ("mus = 100.0 ", "mus = nan ", "mus"),
    ("g = 0.9", "g = 1.2", "g"),
    ("n = 1.3", "n = 0.8", "n"),
    ("nx = 10", "nx = 0", "nx"),
    ("positions = [[0.0, 0.0, 0.0]]", "positions = [[0.0, 0.0, 0.5]]", "outside the tissue"),
    ("n_members = 20", "n_member = 20", "unknown key filter.n_member"),
    ("n_members = 20", "n_members = 20\nmethd = \"etkf\"", "unknown key filter.methd"),
    ("noise_var = 0.01 ", "noise_var = -0.1 ", "sensors.noise_var must be > 0"),
    ("n_mua = 4", "n_mua = 2", "n_mua"),
    ("grid = [5, 5, 5]", "grid = [5, 5]", "filter.grid"),
])
def test_bad_config_exits_2_and_writes_nothing(tmp_path, capsys, bad_toml, old, new, message):
    cfg = bad_toml(old, new)
    out = tmp_path / "out"
    assert run("identify", cfg, "--data", EX / "tiny_data.csv", "--out", out) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1
    assert not out.exists()


@pytest.mark.parametrize("content, message", [
    ("time,sensor_0\n0.1,1.0\n0.2,inf\n", "infinite"),
    ("time,sensor_0\n0.2,1.0\n0.1,2.0\n", "unsorted times"),
    ("time,sensor_0\n0.1,1.0\n0.1,2.0\n", "duplicate times"),
    ("time,a,b\n0.1,1.0,2.0\n", "2 data columns, the config observes 1"),
    ("time,sensor_0\n", "no rows"),
    ("", "empty"),
    ("\x00\x01binary", "first column must be 'time'"),
    ("time,sensor_0\n0.1,abc\n", "not a number"),
])
def test_bad_data_exits_2_and_writes_nothing(tmp_path, capsys, content, message):
    data = tmp_path / "data.csv"
    data.write_text(content)
    out = tmp_path / "out"
    assert run("identify", EX / "tiny.toml", "--data", data, "--out", out) == 2
    err = capsys.readouterr().err
    assert message in err and not out.exists()


def test_missing_and_unreadable_files_exit_2(tmp_path, capsys):
    assert run("identify", tmp_path / "nope.toml", "--data", EX / "tiny_data.csv",
               "--out", tmp_path / "o") == 2
    assert "does not exist" in capsys.readouterr().err
    notoml = tmp_path / "x.toml"
    notoml.write_text("this is [not toml")
    assert run("heat", notoml, "--out", tmp_path / "o") == 2
    assert "not valid TOML" in capsys.readouterr().err
    assert run("identify", EX / "tiny.toml", "--data", tmp_path / "none.csv",
               "--out", tmp_path / "o") == 2
    assert "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_every_command_has_help(capsys):
    for cmd in ("mc", "heat", "identify", "paper", "validate"):
        with pytest.raises(SystemExit) as exc:
            main([cmd, "--help"])
        assert exc.value.code == 0
        assert "--out" in capsys.readouterr().out


def test_identify_from_an_npz_image_series(tmp_path, cache):
    sensors = ("[sensors]\npositions = [[0.0, 0.0, 0.0]]   # one data column after `time`\n"
               "noise_var = 0.01                # deg C^2\n")
    assert sensors in TINY
    cfg = tmp_path / "camera.toml"
    cfg.write_text(TINY.replace(sensors, "[sensors]\npositions = []\n\n[sensors.camera]\n"
                                "x_range = [-0.1, 0.1]\ny_range = [-0.1, 0.1]\nshape = [2, 3]\n"))
    rng = np.random.default_rng(0)
    times = 0.1 * np.arange(1, 21)
    frames = 0.5 * times[:, None, None] + 0.1 * rng.standard_normal((20, 2, 3))
    frames[4, 0, 1] = np.nan
    np.savez(tmp_path / "frames.npz", times=times, frames=frames)
    out = tmp_path / "img"
    with pytest.warns(RuntimeWarning, match="persist from reading to reading"):
        rc = run("identify", cfg, "--data", tmp_path / "frames.npz", "--out", out, "--quiet",
                 "--cache-dir", cache)
    assert rc == 0 and (out / "estimates.csv").exists()
    # frames that keep rising after the pulse: no heat model does that (lag-1 0.82)
    pers = json.loads((out / "summary.json").read_text())["innovation_persistence"]
    assert pers["flagged"] and pers["laser_off"] > 0.5 and pers["laser_off_pairs"] == 54
    assert "docs/beyond.md" in pers["advice"]
    # the smoother's discrepancy is for point sensors: refused with a camera (exit 2)
    cfg.write_text(cfg.read_text().replace("[filter]\n", "[filter]\nsmoother_iterations = 2\n"
                                           "smoother_discrepancy = 0.01\n", 1))
    assert run("identify", cfg, "--data", tmp_path / "frames.npz", "--out", tmp_path / "d",
               "--quiet", "--cache-dir", cache) == 2
    assert not (tmp_path / "d").exists()
    cfg.write_text(cfg.read_text().replace("smoother_discrepancy = 0.01\n", ""))
    from enkf.app.config import load_identify

    assert load_identify(cfg).smoother_options["discrepancy"] == 0.0  # a camera's default
    # so are the drift bank's restarts: no discrepancy with a camera, and a value refused
    assert load_identify(cfg).setup_kw["drift"].restart_discrepancy == 0.0
    cfg.write_text(cfg.read_text() + "\n[filter.drift]\nrestart_discrepancy = 0.01\n")
    with pytest.raises(ValueError, match="filter.drift.restart_discrepancy = 0.01 is for point"):
        load_identify(cfg)
    cfg.write_text(cfg.read_text().replace("\n[filter.drift]\nrestart_discrepancy = 0.01\n", ""))
    np.savez(tmp_path / "wrong.npz", times=times, frames=frames[:, :1])
    assert run("identify", cfg, "--data", tmp_path / "wrong.npz", "--out", tmp_path / "w") == 2
    # the camera's model error: defaults, set, refused when negative (exit 2, nothing written)
    cam = load_identify(cfg).setup_kw["image"]
    assert (cam.model_error_rel_std, cam.model_error_lengths) == (0.04, (0.02, 0.1))
    cfg.write_text(cfg.read_text().replace("shape = [2, 3]\n", "shape = [2, 3]\n"
                                           "model_error_rel_std = 0.0\nmodel_error_lengths = [0.05]\n"))
    cam = load_identify(cfg).setup_kw["image"]
    assert (cam.model_error_rel_std, cam.model_error_lengths) == (0.0, (0.05,))
    for bad in ("[]", "0.05", "[-0.1]"):
        text = cfg.read_text()
        cfg.write_text(text.replace("model_error_lengths = [0.05]", f"model_error_lengths = {bad}"))
        with pytest.raises(ConfigError, match="model_error_lengths"):
            load_identify(cfg)
        cfg.write_text(text)
    cfg.write_text(cfg.read_text().replace("model_error_rel_std = 0.0", "model_error_rel_std = -0.1"))
    assert run("identify", cfg, "--data", tmp_path / "frames.npz", "--out", tmp_path / "m",
               "--quiet", "--cache-dir", cache) == 2
    assert not (tmp_path / "m").exists()


def test_run_table_and_damage_field(tmp_path, cache, capsys):
    cfg = tmp_path / "damage.toml"
    cfg.write_text(TINY.replace("TC = 0.0037       # W cm^-1 K^-1",
                                "TC = 0.0037\nE = 422.5e3\nA = 7.6e66")
                   .replace("T_initial = 0.0         # deg C", "T_initial = 37.0"))
    out = tmp_path / "dmg"
    data = tmp_path / "d.csv"
    rows = (EX / "tiny_data.csv").read_text().splitlines()
    shifted = [rows[0]] + [f"{t},{float(v) + 37.0:.4f}" if v else f"{t},"
                           for t, v in (r.split(",") for r in rows[1:])]
    data.write_text("\n".join(shifted) + "\n")
    assert run("identify", cfg, "--data", data, "--out", out, "--quiet", "--cache-dir", cache) == 0
    import meshio

    pd = meshio.read(out / "fields" / "final.vtu").point_data
    assert pd["damage_Omega_mean"].max() > 0 and np.all(pd["damage_Omega_mean"] >= 0)
    assert np.all((pd["p_damage"] >= 0) & (pd["p_damage"] <= 1))
    assert (out / "fields" / "risk.pvd").exists() and (out / "figures" / "risk_depth_map.png").exists()
    # with a restart from the smoother the damage is re-run for the restarted members
    cfg.write_text(cfg.read_text().replace("[filter]\n", "[filter]\nrandom_walk_std = 0.0\n"
                                           "smoother_restarts = \"laser_off\"\n"
                                           "smoother_restart_iterations = 2\n", 1))
    assert run("identify", cfg, "--data", data, "--out", tmp_path / "dmg2", "--quiet",
               "--cache-dir", cache) == 0
    assert json.loads((tmp_path / "dmg2" / "summary.json").read_text())["smoother_restarts"]
    pd2 = meshio.read(tmp_path / "dmg2" / "fields" / "final.vtu").point_data
    assert pd2["damage_Omega_mean"].max() > 0 and np.all(pd2["damage_Omega_mean"] >= 0)
    bad = tmp_path / "run.toml"
    bad.write_text(TINY + "\n[run]\nschedular = \"tcp://x:1\"\n")
    assert run("heat", bad, "--out", tmp_path / "h") == 2
    assert "unknown key run.schedular" in capsys.readouterr().err


def test_mc_run_has_a_manifest(tmp_path):
    out = tmp_path / "mc"
    assert run("mc", EX / "tiny.toml", "--out", out, "--quiet", "--photons", "5000") == 0
    man = json.loads((out / "run.json").read_text())
    assert man["command"] == "mc" and man["config"]["MC"]["seed"] == 1


OUTPUTS_TOML = TINY.replace("[MC.light_source]", """far_field_res = 8
n_example_paths = 3
calc_normalized_irradiance = true
n_radial_bins = 5
radial_bin_size = 0.02
n_angle_bins = 4
use_light_collector = true

[MC.light_collector]
z = -0.5
f = inf
diam = 0.2
NA = 0.5
t_end = 1e-10
n_time_bins = 5

[MC.deposition_criteria]
min_scatterings = 1

[MC.light_source]""")


def test_mc_config_asks_for_the_optional_outputs_and_gets_them_with_figures(tmp_path, capsys):
    out = tmp_path / "mc"
    cfg = tmp_path / "outputs.toml"
    cfg.write_text(OUTPUTS_TOML)
    assert run("mc", cfg, "--out", out, "--quiet", "--photons", "5000") == 0
    with np.load(out / "outputs.npz") as z:
        names = set(z.files)
        assert {"NI_zneg", "far_field", "Rd_r", "example_paths", "light_collector_image",
                "light_collector_t"} <= names
        # MCmatlab's n_time_bins + 2: before t_start, the bins, after t_end
        assert z["light_collector_image"].shape == (7,)
    summary = json.loads((out / "summary.json").read_text())
    assert 0 < summary["collected_fraction"] < summary["escaped"]["top"]
    assert sorted(p.name for p in out.glob("MC_*.png"))  # MCmatlab's output figures
    (tmp_path / "bad.toml").write_text(OUTPUTS_TOML.replace("diam = 0.2", "diameter = 0.2"))
    assert run("mc", tmp_path / "bad.toml", "--out", tmp_path / "b") == 2
    assert "unknown key MC.light_collector.diameter" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()


def _identify_tiny(tmp_path, cache, filter_lines: str):
    """The tiny config with ``filter_lines`` added to [filter], run on the example data:
    ``(config path, output dir, summary.json)``."""
    cfg = tmp_path / "tiny_extra.toml"
    cfg.write_text(TINY.replace("[filter]\n", "[filter]\n" + filter_lines, 1))
    out = tmp_path / "id"
    assert run("identify", cfg, "--data", EX / "tiny_data.csv", "--out", out, "--quiet",
               "--cache-dir", cache) == 0
    return cfg, out, json.loads((out / "summary.json").read_text())


@pytest.mark.slow
def test_summary_and_run_json_say_whether_the_innovations_persist(tmp_path, cache):
    """summary.json (and --follow's run.json) give the lag-1 persistence of the
    innovations while the laser is off, and whether it is flagged: on the tiny twin's
    data it is not (9 laser-off pairs of one sensor); with a camera whose frames go on
    rising after the pulse it is (test_identify_from_an_npz_image_series)."""
    cfg, out, s = _identify_tiny(tmp_path, cache, "")
    pers = s["innovation_persistence"]
    assert set(pers) == {"laser_off", "laser_off_pairs", "laser_on", "laser_on_pairs", "all",
                         "all_pairs", "threshold", "flagged", "likely_cause", "advice"}
    assert pers["laser_off_pairs"] == 9 and pers["all_pairs"] == 17  # the reading at 1 s is missing
    assert not pers["flagged"] and pers["advice"] is None and -1 <= pers["laser_off"] <= 1
    assert run("identify", cfg, "--follow", EX / "tiny_data.csv", "--out", tmp_path / "f",
               "--quiet", "--cache-dir", cache) == 0
    live = json.loads((tmp_path / "f" / "run.json").read_text())["innovation_persistence"]
    assert live["laser_off_pairs"] == 9 and not live["flagged"]


def test_identify_reports_the_sensor_offsets(tmp_path, cache):
    """[filter] sensor_offset_std: the offset in summary.json, estimates.csv and the printed
    line, for a run on a file and for --follow."""
    cfg, out, s = _identify_tiny(tmp_path, cache, "sensor_offset_std = 0.5\n")
    (off,) = s["sensor_offsets"]
    assert off["position_cm"] == [0.0, 0.0, 0.0] and 0 < off["std_final"] < 0.5
    header = (out / "estimates.csv").read_text().splitlines()[0].split(",")
    assert header[5:7] == ["sensor1_offset_mean", "sensor1_offset_std"]
    live = tmp_path / "live.csv"
    live.write_text("\n".join((EX / "tiny_data.csv").read_text().splitlines()[:6]) + "\n# end\n")
    out2 = tmp_path / "follow"
    assert run("identify", cfg, "--follow", live, "--out", out2, "--quiet", "--cache-dir", cache,
               "--idle-timeout", "5") == 0
    rows = (out2 / "estimates.csv").read_text().splitlines()
    assert rows[0].split(",")[5:7] == ["sensor1_offset_mean", "sensor1_offset_std"]
    assert len(rows) == 6 and len(rows[1].split(",")) == len(rows[0].split(","))


def test_identify_refuses_a_file_too_long_for_the_discrepancy(tmp_path, cache, monkeypatch):
    """The smoother's dense discrepancy covariance: a data file with more readings than it
    allows is refused before the filter runs (exit 2, nothing written)."""
    import enkf.tissue.smooth as sm

    monkeypatch.setattr(sm, "MAX_DISCREPANCY_READINGS", 5)
    cfg = tmp_path / "long.toml"
    cfg.write_text(TINY.replace("[filter]\n", "[filter]\nsmoother_iterations = 2\n", 1))
    out = tmp_path / "long"
    assert run("identify", cfg, "--data", EX / "tiny_data.csv", "--out", out, "--quiet",
               "--cache-dir", cache) == 2
    assert not out.exists()


def test_identify_with_the_smoother_reports_it(tmp_path, cache):
    """``[filter] smoother_iterations``: ES-MDA over the whole window after the filter, in
    summary.json beside the filter's estimates; not with --follow; bad values exit 2."""
    cfg, _, s = _identify_tiny(tmp_path, cache, "smoother_iterations = 2\n")
    sm = s["smoother"]
    assert sm["method"] == "ES-MDA" and sm["iterations"] == 2 and set(sm["parameters"]) == {
        "mua", "mus"}
    for p in sm["parameters"].values():
        lo, hi = p["band_2sd"]
        assert 0 < lo < p["estimate"] < hi and p["std"] > 0
    assert run("identify", cfg, "--follow", EX / "tiny_data.csv", "--out", tmp_path / "f",
               "--quiet", "--cache-dir", cache) == 2
    assert sm["knots"] == 1 and sm["discrepancy"] == 0.01 and sm["discrepancy_time"] == 2.0
    # optics drifting while heated: the values at the knots too
    (tmp_path / "k").mkdir()
    _, _, s = _identify_tiny(tmp_path / "k", cache, "smoother_iterations = 2\n"
                             "smoother_knots = 3\nsmoother_discrepancy = 0\n")
    sm = s["smoother"]
    assert sm["knots"] == 3 and sm["discrepancy"] == 0.0
    heated = sm["knot_times_heated_s"]
    assert len(heated) == 3 and heated[0] == 0.0 and heated[-1] > 0
    for name, p in sm["parameters"].items():
        assert p["estimate"] == pytest.approx(sm["knot_estimates"][name][-1])
    for bad in ("smoother_iterations = -1\n", "smoother_iterations = 1.5\n",
                "smoother_iterations = 2\nparameter_model = \"trend\"\n",
                "smoother_knots = 3\n", "smoother_iterations = 2\nsmoother_knots = 0\n",
                "smoother_iterations = 2\nsmoother_discrepancy = -0.1\n",
                "smoother_iterations = 2\nsmoother_discrepancy_time = 0\n",
                "smoother_importance = 600\n",
                "smoother_iterations = 2\nsmoother_importance = 100\n",
                "smoother_iterations = 2\nsmoother_importance = -1\n",
                "smoother_iterations = 2\nsmoother_modes = 64\n",
                "smoother_iterations = 2\nsmoother_importance = 600\nsmoother_modes = 8\n",
                "smoother_iterations = 2\nsmoother_importance = 600\nsmoother_modes = -1\n"):
        cfg.write_text(TINY.replace("[filter]\n", "[filter]\n" + bad, 1))
        assert run("identify", cfg, "--data", EX / "tiny_data.csv", "--out", tmp_path / "b",
                   "--quiet", "--cache-dir", cache) == 2
        assert not (tmp_path / "b").exists()


@pytest.mark.slow
def test_identify_with_restarts_from_the_smoother(tmp_path, cache):
    """``[filter] smoother_restarts``: the filter restarts from the smoother after the
    pulse (summary.json lists the restart), also with --follow; bad values exit 2 with
    nothing written."""
    # the filter alone (no drift bank): its restarts are the config's
    cfg, out, s = _identify_tiny(tmp_path, cache, "random_walk_std = 0.0\n"
                                 "smoother_restarts = \"laser_off\"\n"
                                 "smoother_restart_iterations = 2\n"
                                 "drift = { mode = \"none\" }\n")
    (r,) = s["smoother_restarts"]
    assert r["time_s"] == pytest.approx(1.0) and r["readings"] == 10
    from enkf.app.config import load_identify

    kw = load_identify(cfg).setup_kw
    assert (kw["smoother_restarts"], kw["smoother_restart_iterations"],
            kw["smoother_restart_discrepancy"]) == ("laser_off", 2, 0.01)
    assert run("identify", cfg, "--follow", EX / "tiny_data.csv", "--out", tmp_path / "f",
               "--quiet", "--cache-dir", cache) == 0
    (r,) = json.loads((tmp_path / "f" / "run.json").read_text())["smoother_restarts"]
    assert r == {"time_s": pytest.approx(1.0), "readings": 10}
    # drifting optics, the restart an equal mixture of two forms of the drift
    (tmp_path / "mix").mkdir()
    cfg, out, s = _identify_tiny(tmp_path / "mix", cache, "random_walk_std = [0.03, 0.1]\n"
                                 "smoother_restarts = \"laser_off\"\n"
                                 "smoother_restart_iterations = 2\n"
                                 "smoother_restart_knots = [2, 3]\n"
                                 "drift = { mode = \"none\" }\n")
    assert load_identify(cfg).setup_kw["smoother_restart_knots"] == (2, 3)
    assert len(s["smoother_restarts"]) == 1
    for bad in ("random_walk_std = [0.03, 0.1]\nsmoother_restarts = \"laser_off\"\n"
                "smoother_restart_knots = [1, 3]\n",
                "random_walk_std = [0.03, 0.1]\nsmoother_restarts = \"laser_off\"\n"
                "smoother_restart_knots = [3, 3]\n","random_walk_std = 0.0\nsmoother_restarts = \"often\"\n",
                "random_walk_std = 0.0\nsmoother_restarts = [1.0, -2.0]\n",
                "random_walk_std = 0.0\nsmoother_restarts = 3\n",
                "smoother_restarts = \"laser_off\"\n",  # the default walk: not constant
                "random_walk_std = 0.0\nsmoother_restart_iterations = 2\n",
                "random_walk_std = 0.0\nsmoother_restarts = [1.0]\n"
                "smoother_restart_gaussian = 1\n",
                "random_walk_std = 0.0\nsmoother_restarts = [1.0]\n"
                "smoother_restart_iterations = 0\n"):
        cfg.write_text(TINY.replace("[filter]\n", "[filter]\n" + bad, 1))
        assert run("identify", cfg, "--data", EX / "tiny_data.csv", "--out", tmp_path / "b",
                   "--quiet", "--cache-dir", cache) == 2, bad
        assert not (tmp_path / "b").exists()


def test_identify_with_importance_sampling_after_the_smoother(tmp_path, cache):
    """``[filter] smoother_importance``: the smoother's ensemble and the modes found from
    256 points of the prior (the default mode search) seed adaptive importance sampling;
    summary.json says so and gives the effective sample size; the weighted estimate lies
    inside its band. ``smoother_modes = 0``: no mode search."""
    _, _, s = _identify_tiny(tmp_path, cache, "smoother_iterations = 2\n"
                             "smoother_importance = 600\n")
    sm = s["smoother"]
    assert sm["method"] == "ES-MDA + AMIS" and sm["importance"] == 600
    assert sm["mode_search"] == 256 and sm["modes_found"] >= 1
    assert 1 <= sm["effective_sample_size"] <= 600
    for p in sm["parameters"].values():
        lo, hi = p["band_2sd"]
        assert 0 < lo < p["estimate"] < hi and p["std"] > 0
    (tmp_path / "none").mkdir()
    _, _, s = _identify_tiny(tmp_path / "none", cache, "smoother_iterations = 2\n"
                             "smoother_importance = 600\nsmoother_modes = 0\n")
    assert s["smoother"]["mode_search"] == 0 and "modes_found" not in s["smoother"]
