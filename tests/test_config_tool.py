"""Configs and data files at the library level, the [data] and [filter.bounds] tables,
bad input to `heat`, the health check's stop through `identify`, and `validate`."""

import copy
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from enkf.app.cli import main
from enkf.app.config import FILTER_KEYS, identify_config_from_dict, load_identify
from enkf.app.readers import read_sensor_csv
from mcmatlab_py.config import _HS_KEYS, _MC_KEYS, ConfigError, load_model, model_from_config

EX = Path(__file__).parents[1] / "examples"
TINY = (EX / "tiny.toml").read_text()
BASE = tomllib.loads(TINY)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("emulator-cache"))


def run(*argv):
    return main([str(a) for a in argv])


def with_(path: str, value, base=None):
    """``base`` (default BASE) with ``value`` at the dotted ``path`` ('G.media.0.mua');
    None deletes."""
    cfg = copy.deepcopy(BASE if base is None else base)
    *head, last = path.split(".")
    node = cfg
    for k in head:
        node = node[int(k)] if isinstance(node, list) else node.setdefault(k, {})
    if value is None:
        del node[last]
    else:
        node[last] = value
    return cfg


# ------------------------------------------------------------------ library level: config

@pytest.mark.parametrize("path, value, message", [
    ("G.media.0.mua", -1.0, "mua must be >= 0, got -1.0"),
    ("G.media.0.mus", float("nan"), "mus must be finite, got nan"),
    ("G.media.0.VHC", 0.0, "VHC must be > 0, got 0.0"),
    ("G.media.0.TC", -0.1, "TC must be >= 0, got -0.1"),
    ("G.media.0.g", 1.5, "g must be in [-1, 1], got 1.5"),
    ("G.media.0.g", -1.5, "g must be in [-1, 1], got -1.5"),
    ("G.media.0.n", 0.5, "n must be >= 1, got 0.5"),
    ("G.nx", 0, "G.nx"),
    ("G.Lz", 0.0, "G.Lz must be > 0, got 0.0"),
    ("G.Ly", float("nan"), "G.Ly"),
    ("G.media", [], "G.media must be a non-empty array"),
    ("G.media.0.mua", None, "G.media[0].mua is missing"),
    ("HS.dt", 0.0, "HS.dt must be > 0, got 0.0"),
    ("HS.dt", 5.0, "HS.dt = 5.0 s is longer than the whole run"),
    ("HS.P", -0.5, "HS.P must be >= 0, got -0.5"),
    ("HS.n_pulses", 0, "HS.n_pulses must be >= 1, got 0"),
    ("HS.mesh_divisions", [0, 5, 5], "HS.mesh_divisions must be [nx, ny, nz]"),
    ("HS.T_ambient", "warm", "HS.T_ambient must be a number, got 'warm'"),
    ("HS.heat_transfer_coefficient", -1.0, "HS.heat_transfer_coefficient must be > 0"),
    ("HS.temp_sensor_positions", [[0.0, 0.0, 0.3]], "HS.temp_sensor_positions[0]"),
    ("HS.dt_s", 0.1, "unknown key HS.dt_s"),
    ("MC.n_photons", 10, "unknown key MC.n_photons"),
    ("MC.light_source.radius", 0.0, "MC.light_source.radius must be > 0, got 0.0"),
    ("sensors.positions", [[0.0, 0.3, 0.0]], "sensors.positions[0] = [0.0, 0.3, 0.0] cm is "
                                            "outside the tissue"),
    ("sensors.positions", [[0.0, 0.0]], "sensors.positions must be a list of [x, y, z]"),
    ("sensors.noise_var", 0.0, "sensors.noise_var must be > 0, got 0.0"),
    ("sensors.rate", -10, "sensors.rate must be > 0, got -10"),
    ("filter.n_member", 20, "unknown key filter.n_member"),
    ("filter.n_members", 1, "filter.n_members must be >= 2, got 1"),
    ("filter.method", "kalman", "filter.method must be 'enkf' or 'etkf', got 'kalman'"),
    ("filter.estimate", ["mua"], "filter.estimate must be"),
    ("filter.prior_range", [2.0, 0.5], "filter.prior_range must have lo < hi"),
    ("filter.inflation", float("nan"), "filter.inflation must be finite, got nan"),
    ("filter.rtps", 1.5, "filter.rtps must be <= 1"),
    ("filter.rtps", -0.1, "filter.rtps must be >= 0, got -0.1"),
    ("filter.grid", [5, 5, 0], "filter.grid[2] must be >= 1, got 0"),
    ("filter.transforms", "logit", "filter.transforms must be \"log\""),
    ("filter.emulator.n_mua", 2, "filter.emulator.n_mua must be >= 4, got 2"),
    ("filter.emulator.on_demand", "yes", "filter.emulator.on_demand must be true or false, got 'yes'"),
    ("filter.emulator.exact", 1, "filter.emulator.exact must be true or false, got 1"),
    ("filter.emulator.mua_range", [0.0, 20.0], "filter.emulator.mua_range[0] must be > 0"),
    ("filter.bounds.mua", [0.8, 2.0], "filter.bounds.mua = [0.8, 2.0] must contain the prior"),
    ("filter.bounds.VHC", [1.0, 10.0], "filter.bounds.VHC: VHC is not estimated"),
    ("filter.bounds.k", [1.0, 10.0], "unknown key filter.bounds.k"),
    ("filter.prior.mua", [2.0, 0.5], "filter.prior.mua must have lo < hi, got [2.0, 0.5]"),
    ("filter.prior.mus", [-5.0, 200.0], "filter.prior.mus[0] must be > 0, got -5.0"),
    ("filter.prior.mus", [50.0, float("nan")], "filter.prior.mus[1] must be finite, got nan"),
    ("filter.prior.TC", [0.001, 0.01], "filter.prior.TC: TC is not estimated"),
    ("filter.prior.g", [0.8, 0.9], "unknown key filter.prior.g"),
    ("filter.prior.mua", [0.05, 3.0], "filter.emulator.mua_range = [0.1, 20.0] must cover the "
                                      "prior of mua, [0.05, 3] cm^-1 (filter.prior.mua)"),
    ("filter.emulator.mus_range", [60.0, 2000.0], "filter.emulator.mus_range = [60.0, 2000.0] "
                                                  "must cover the prior of mus, [50, 200]"),
    ("G.media.0.mua", 15.0, "filter.emulator.mua_range = [0.1, 20.0] must cover the prior"),
    ("data.columns", ["a", "b"], "data.columns names 2 columns, the config observes 1"),
    ("data.file", 3, "data.file must be a path"),
    ("data.time_offset", float("inf"), "data.time_offset must be finite"),
    ("data.colums", ["a"], "unknown key data.colums"),
    ("run.workers", "two", "run.workers must be an integer >= 1, got 'two'"),
    ("run.workers", 0, "run.workers must be an integer >= 1, got 0"),
    ("paper", {"scenario": "constant"}, "unknown key config.paper"),
    ("HS.theta", 0.2, "HS.theta must be in [0.5, 1]"),
])
def test_bad_config_raises_config_error_naming_key_and_value(path, value, message):
    cfg = with_(path, value)
    with pytest.raises(ConfigError) as exc:
        identify_config_from_dict(cfg)
    assert message in str(exc.value)


@pytest.mark.parametrize("path, typo, closest", [
    ("filter.n_member", 20, "n_members"),  # the longest table, more than a line of keys
    ("MC.n_photon_requested", 10, "n_photons_requested"),
    ("HS.dt_s", 0.1, "dt"),
])
def test_a_misspelt_key_names_the_closest_and_whole_allowed_keys(path, typo, closest):
    with pytest.raises(ConfigError) as exc:
        identify_config_from_dict(with_(path, typo))
    msg = str(exc.value)
    assert msg.startswith(f"unknown key {path}; did you mean {closest!r}? (allowed: ")
    # short enough for the command line's one-line cut (400), and every name whole
    assert len(msg) < 400 and msg.endswith(")") and "..." not in msg
    listed = msg.split("(allowed: ")[1][:-1].split(", ")
    more = int(listed.pop().split()[1]) if listed[-1].endswith(" more") else 0
    keys = {"filter": FILTER_KEYS, "MC": _MC_KEYS, "HS": _HS_KEYS}[path.split(".")[0]]
    assert listed == sorted(keys)[:len(listed)] and len(listed) + more == len(keys)


def test_a_misspelt_key_on_the_command_line(tmp_path, capsys):
    cfg = tmp_path / "typo.toml"
    cfg.write_text(TINY.replace("n_members = 20", "n_member = 20"))
    assert run("identify", cfg, "--out", tmp_path / "o") == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: unknown key filter.n_member; did you mean 'n_members'?")
    assert err.endswith(" more)") and "..." not in err


def test_config_errors_are_value_errors_and_one_line():
    with pytest.raises(ValueError) as exc:
        identify_config_from_dict(with_("G.media.0.g", 2.0))
    assert "\n" not in str(exc.value)


@pytest.mark.parametrize("name", sorted(p.name for p in EX.glob("*.toml")))
def test_every_example_config_loads(name):
    cfg = tomllib.loads((EX / name).read_text())
    if "filter" in cfg or "sensors" in cfg:
        ic = load_identify(EX / name)
        assert ic.n_obs >= 1 and len(ic.grid) == 3
    else:
        load_model(EX / name)
    model_from_config(cfg).HS.validate(model_from_config(cfg).G)


def test_paper_configs_match_the_paper():
    c = load_identify(EX / "paper_constant.toml")
    tv = load_identify(EX / "paper_time_varying.toml")
    ap = load_identify(EX / "paper_all_params.toml")
    assert c.grid == (20, 20, 10) and c.setup_kw["n_members"] == 50
    assert c.setup_kw["sensor_noise_var"] == 0.01  # the paper's D
    assert tv.setup_kw["random_walk_when_off"] == 0.0
    assert ap.setup_kw["estimate"] == ("mua", "mus", "VHC", "TC")
    assert {x.setup_kw["model_error"] for x in (c, tv, ap)} == {"white"}  # the paper's C
    # measured data: the structured model error unless a config says otherwise
    assert identify_config_from_dict(BASE).setup_kw["model_error"] == "structured"
    m = ap.model.G.media[0]
    assert (m.mua, m.mus, m.VHC, m.TC) == (1.0, 100.0, 3.76, 0.0037)


def test_prior_table_sets_each_parameters_own_range():
    cfg = identify_config_from_dict(with_("filter.prior.mus", [80.0, 400.0]))
    assert cfg.setup_kw["prior"] == {"mus": (80.0, 400.0)}
    setup = cfg.setup(absorption=lambda mua, mus: None)
    lo, hi = setup.parameters.prior_bounds()  # mua keeps prior_range times the medium's value
    assert lo.tolist() == [0.5, 80.0] and hi.tolist() == [2.0, 400.0]
    # the default health range reaches ten times beyond the prior
    assert setup.parameters.default_bounds()[1].tolist() == [5.0, 4000.0]
    # explicit bounds must contain the new prior, not the old one
    with pytest.raises(ConfigError, match=r"filter.bounds.mus = \[100.0, 1000.0\] must contain "
                                          r"the prior \[80, 400\] \(filter.prior.mus\)"):
        identify_config_from_dict(with_("filter.prior.mus", [80.0, 400.0],
                                        with_("filter.bounds.mus", [100.0, 1000.0])))


def test_prior_sampling_reaches_the_filter_and_is_checked():
    """[filter] prior_sampling: random unless a config says "stratified" (a Latin
    hypercube); anything else names the key and the value."""
    setup = identify_config_from_dict(BASE).setup(absorption=lambda mua, mus: None)
    assert setup.parameters.prior_sampling == "random"
    setup = identify_config_from_dict(with_("filter.prior_sampling", "stratified")).setup(
        absorption=lambda mua, mus: None)
    assert setup.parameters.prior_sampling == "stratified"
    with pytest.raises(ConfigError, match=r"filter.prior_sampling must be one of "
                                          r"\['random', 'stratified'\], got 'sobol'"):
        identify_config_from_dict(with_("filter.prior_sampling", "sobol"))


def test_hs_theta_is_the_filters_time_scheme():
    """[HS] theta reaches the filter's heat steps; without it the filter's default
    (Crank-Nicolson)."""
    assert "theta" not in identify_config_from_dict(with_("HS.dt", 0.1)).setup_kw
    setup = identify_config_from_dict(with_("HS.theta", 1.0)).setup(
        absorption=lambda mua, mus: None)
    assert setup.heat.theta == 1.0
    setup = identify_config_from_dict(with_("HS.dt", 0.1)).setup(absorption=lambda mua, mus: None)
    assert setup.heat.theta == 0.5


def test_filter_rtps_reaches_the_setup_and_the_filter():
    """[filter] rtps reaches TissueFilterSetup (and so FilterConfig); default 0 (none)."""
    setup = identify_config_from_dict(with_("filter.rtps", 0.3)).setup(
        absorption=lambda mua, mus: None)
    assert setup.model_error.rtps == 0.3
    setup = identify_config_from_dict(with_("HS.dt", 0.1)).setup(absorption=lambda mua, mus: None)
    assert setup.model_error.rtps == 0.0


def test_bounds_become_the_health_check_range():
    cfg = identify_config_from_dict(with_("filter.bounds.mus", [10.0, 1000.0]))
    assert np.array_equal(cfg.param_bounds, [[1.0 / 20, 20.0], [10.0, 1000.0]])
    assert identify_config_from_dict(BASE).param_bounds is None


# ------------------------------------------------------------------ library level: data

def write(tmp_path, text, name="d.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("text, message", [
    ("time,s0\n0.1,1\n0.2,-inf\n", "a temperature is infinite"),
    ("time,s0\n0.1,1\ninf,2\n", "the time must be a finite number"),
    ("time,s0\n0.2,1\n0.1,2\n", "unsorted times: 0.2 then 0.1 s"),
    ("time,s0\n0.1,1\n0.1,2\n", "duplicate times: 0.1 then 0.1 s"),
    ("time,s0,s1\n0.1,1,2\n", "2 data columns, the config observes 1"),
    ("time,s0\n0.1,1,2\n", "expected 2 comma-separated fields, got 3"),
    ("time,s0\n", "has a header but no rows"),
    ("", "is empty"),
    ("a;b\n1;2\n", "the first column must be 'time'"),
    ("time,s0\n0.0,1\n", "times must be > 0 s"),
    ("time,s0\n0.1,warm\n", "field 2 is not a number: 'warm'"),
    ("time,s0,s0\n0.1,1,2\n", "names column 's0' twice"),
])
def test_bad_data_raises_value_error_naming_the_problem(tmp_path, text, message):
    with pytest.raises(ValueError) as exc:
        read_sensor_csv(write(tmp_path, text), 1)
    assert message in str(exc.value) and str(tmp_path) in str(exc.value)


def test_missing_and_undecodable_data_files(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        read_sensor_csv(tmp_path / "nope.csv", 1)
    p = tmp_path / "bin.csv"
    p.write_bytes(b"\xff\xfe\x00time")
    with pytest.raises(ValueError, match="cannot be read as text"):
        read_sensor_csv(p, 1)


def test_irregular_sampling_and_gaps_are_kept(tmp_path):
    times, data, names = read_sensor_csv(
        write(tmp_path, "# camera 3\ntime,s0\n0.1,1.0\n0.35,\n0.4,nan\n\n1.7,2.5\n"), 1)
    assert np.array_equal(times, [0.1, 0.35, 0.4, 1.7]) and names == ["time", "s0"]
    assert np.isnan(data[1:3, 0]).all() and data[3, 0] == 2.5


def test_columns_are_picked_by_name_and_time_offset_drops_readings_before_the_laser(tmp_path):
    p = write(tmp_path, "time,ambient,tip,base\n9.9,20,1,2\n10.0,20,3,4\n10.5,21,5,\n11.0,21,7,8\n")
    times, data, names = read_sensor_csv(p, 2, columns=["base", "tip"], time_offset=10.0)
    assert np.allclose(times, [0.5, 1.0]) and names == ["time", "base", "tip"]
    assert np.isnan(data[0, 0]) and data[0, 1] == 5 and np.array_equal(data[1], [8, 7])
    with pytest.raises(ValueError, match="missing column 'probe'"):
        read_sensor_csv(p, 1, columns=["probe"])
    with pytest.raises(ValueError, match="no reading after the laser's start"):
        read_sensor_csv(p, 1, columns=["tip"], time_offset=20.0)


def test_npz_needs_a_camera(tmp_path):
    np.savez(tmp_path / "f.npz", times=np.array([0.1]), frames=np.zeros((1, 2, 2)))
    with pytest.raises(ValueError, match="needs \\[sensors.camera\\]"):
        identify_config_from_dict(BASE).read_data(tmp_path / "f.npz")


# ------------------------------------------------------------------ command line



@pytest.mark.parametrize("old, new, message", [
    ("dt = 0.1 ", "dt = 5.0 ", "HS.dt = 5.0 s is longer than the whole run"),
    ("dt = 0.1 ", "dt = -0.1 ", "HS.dt must be > 0"),
    ("n_pulses = 1", "n_pulse = 1", "unknown key HS.n_pulse"),
    ("T_initial = 0.0 ", "mesh_divisions = [0, 5, 5]\nT_initial = 0.0 ", "HS.mesh_divisions"),
    ("T_initial = 0.0 ", "T_ambient = \"x\"\nT_initial = 0.0 ", "HS.T_ambient must be a number"),
    ("[0.0, 0.0, 0.1]]", "[0.0, 0.0, 0.3]]", "HS.temp_sensor_positions[1]"),
    ("n_members = 20", "n_member = 20", "unknown key filter.n_member"),  # unused by heat: still checked
    ("[sensors]", "[data]\nfiel = \"x.csv\"\n\n[sensors]", "unknown key data.fiel"),
    ("[sensors]", "[paper]\nscenario = 1\n\n[sensors]", "unknown key config.paper"),
    ("nz = 5", "nz = -5", "G.nz"),
    ("VHC = 3.76 ", "VHC = 0 ", "VHC must be > 0"),
])
def test_heat_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, old, new, message, bad_toml):
    out = tmp_path / "out"
    assert run("heat", bad_toml(old, new), "--out", out) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1
    assert not out.exists()


def test_identify_reads_data_file_columns_and_offset_from_the_config(tmp_path, cache):
    rows = (EX / "tiny_data.csv").read_text().splitlines()[1:]
    lines = ["t_cam,ambient,probe", "4.0,20.0,0.0"]  # the laser starts at 5 s on this clock
    lines += [f"{5 + float(t):.2f},20.0,{v}" for t, v in (r.split(",") for r in rows)]
    (tmp_path / "measured.csv").write_text("\n".join(lines) + "\n")
    cfg = tmp_path / "own.toml"
    cfg.write_text(TINY + "\n[data]\nfile = \"measured.csv\"\ncolumns = [\"probe\"]\n"
                   "time_offset = 5.0\n")
    out = tmp_path / "own"
    # the header's first column is not 'time': refused before anything is built
    assert run("identify", cfg, "--out", out, "--quiet", "--cache-dir", cache) == 2
    (tmp_path / "measured.csv").write_text("\n".join(["time,ambient,probe"] + lines[1:]) + "\n")
    assert run("identify", cfg, "--out", out, "--quiet", "--cache-dir", cache) == 0
    ref = tmp_path / "ref"
    assert run("identify", EX / "tiny.toml", "--data", EX / "tiny_data.csv", "--out", ref,
               "--quiet", "--cache-dir", cache) == 0
    a = np.loadtxt(out / "estimates.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(ref / "estimates.csv", delimiter=",", skiprows=1)
    assert np.allclose(a, b, rtol=1e-6, atol=1e-9)  # the same readings at the same times
    man = json.loads((out / "run.json").read_text())
    assert man["data"] == [str(tmp_path / "measured.csv")]
    assert man["argv"][:2] == ["tissue-enkf", "identify"]


def test_the_health_check_stops_and_the_estimates_up_to_then_are_written(tmp_path, cache,
                                                                         capsys):
    cfg = tmp_path / "stop.toml"
    cfg.write_text(TINY + "\n[filter.bounds]\nmua = [0.5, 2.0]\n")
    rows = (EX / "tiny_data.csv").read_text().splitlines()
    hot = [rows[0]] + [f"{t},{float(v) * 4 + 1:.4f}" if v else f"{t},"  # far too hot
                       for t, v in (r.split(",") for r in rows[1:])]
    (tmp_path / "hot.csv").write_text("\n".join(hot) + "\n")
    out = tmp_path / "out"
    assert run("identify", cfg, "--data", tmp_path / "hot.csv", "--out", out, "--quiet",
               "--cache-dir", cache) == 0
    assert "the filter stopped early" in capsys.readouterr().err
    s = json.loads((out / "summary.json").read_text())
    assert s["stopped"].startswith("filter diverged at step ")
    assert "parameter mua mean" in s["stopped"] and "outside bounds [0.5, 2]" in s["stopped"]
    est = np.loadtxt(out / "estimates.csv", delimiter=",", skiprows=1, ndmin=2)
    k = int(s["stopped"].split("step ")[1].split(" ")[0])
    assert est.shape[0] == k + 1 < 21  # the prior, the steps up to the stop, no more
    assert s["stopped_at_s"] == pytest.approx(est[-1, 0])
    assert s["rejected"]["mua"]["mean"] > 2.0
    assert 0.5 <= s["parameters"]["mua"]["estimate_final"] <= 2.0  # the last accepted step
    assert (out / "run.json").exists() and (out / "figures" / "estimates.png").exists()


@pytest.mark.parametrize("relative", [False, True], ids=["absolute", "relative"])
def test_validate_quick_subset_writes_report_and_manifest(tmp_path, monkeypatch, relative):
    src = Path(__file__).parents[1] / "validation" / "reports" / "fem_convergence.md"
    before = src.read_bytes()
    out = tmp_path / "runs" / "val"
    if relative:  # the scripts run inside the run folder: the same layout as absolute
        monkeypatch.chdir(tmp_path)
    assert run("validate", "--only", "fem_convergence", "--out",
               Path("runs", "val") if relative else out, "--quiet", "--threads", "1") == 0
    assert {p.name for p in out.iterdir()} == {"figures", "fem_convergence.md", "report.md",
                                               "run.json"}
    report = (out / "report.md").read_text()
    assert "| fem_convergence | ok |" in report and "Fitted order" in report
    assert (out / "fem_convergence.md").exists() and (out / "figures" / "fem_convergence.png").exists()
    assert "](figures/fem_convergence.png)" in report
    man = json.loads((out / "run.json").read_text())
    assert man["command"] == "validate" and man["config"]["checks"] == ["fem_convergence"]
    assert man["status"] == {"fem_convergence": "ok"}
    assert src.read_bytes() == before  # nothing written into the source tree


@pytest.mark.parametrize("argv, message", [
    (["--only", "emulator_accuracy"], "runs only with --full"),
    (["--only", "nope"], "no such check"),
    (["--threads", "0"], "--threads must be >= 1"),
    (["--seed", "-2"], "--seed must be >= 0, got -2"),
])
def test_validate_bad_input_exits_2(tmp_path, capsys, argv, message):
    out = tmp_path / "val"
    assert run("validate", *argv, "--out", out) == 2
    assert message in capsys.readouterr().err and not out.exists()
