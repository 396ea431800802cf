"""The second hostile round (issue 51): input that was taken, or refused as a bug.

Each test fails without its fix: numeric strings and non-string names in [[G.media]],
start temperatures below absolute zero or absurdly high, switches that are no booleans,
"1_0" in a CSV file, API fields of the wrong type, a light source the emulator cannot
take, seeds and photon counts beyond 64 bits, bad paper options, and SIGHUP and SIGQUIT,
which left partial directories behind. The last test guards that --out naming a file
leaves the file as it was.
"""

from __future__ import annotations

import copy
import math
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from enkf.app.cli import main
from enkf.app.config import identify_config_from_dict
from enkf.app.readers import read_sensor_csv
from mcmatlab_py import Medium, Model
from mcmatlab_py.config import ConfigError, model_from_config

EX = Path(__file__).parents[1] / "examples"
BASE = tomllib.loads((EX / "tiny.toml").read_text())


def run(*argv) -> int:
    return main([str(a) for a in argv])


def one_error_line(capsys, *needles) -> str:
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    for n in needles:
        assert n in err, err
    return err


def with_(path: str, value) -> dict:
    """The tiny config with ``value`` at the dotted ``path`` ('G.media.0.mua')."""
    cfg = copy.deepcopy(BASE)
    *head, last = path.split(".")
    node = cfg
    for k in head:
        node = node[int(k)] if isinstance(node, list) else node.setdefault(k, {})
    node[last] = value
    return cfg


def write_toml(tmp_path: Path, old: str, new: str) -> Path:
    text = (EX / "tiny.toml").read_text()
    assert old in text, old
    p = tmp_path / "hostile.toml"
    p.write_text(text.replace(old, new))
    return p


# ------------------------------------------------------------------ [[G.media]]

@pytest.mark.parametrize("key", ["mua", "mus", "g", "n", "VHC", "TC"])
def test_numeric_strings_in_media_are_refused_naming_the_key(key):
    value = str(BASE["G"]["media"][0][key])
    with pytest.raises(ConfigError, match=rf"G\.media\[0\]\.{key} must be a number, got "
                                          rf"'{value}'"):
        model_from_config(with_(f"G.media.0.{key}", value))


@pytest.mark.parametrize("name", [True, 5, 1.5, ["skin"], {"a": 1}])
def test_a_medium_name_must_be_a_string(name):
    with pytest.raises(ConfigError, match=r"G\.media\[0\]\.name must be a string, got "):
        model_from_config(with_("G.media.0.name", name))


def test_the_api_refuses_numeric_strings_in_a_medium():
    with pytest.raises(ValueError, match=r"Medium\('t'\)\.mua must be a number or a function, "
                                         r"got '1\.0'"):
        Medium("t", mua="1.0", mus=10.0)


def test_a_numeric_string_in_media_is_bad_input_on_the_command_line(tmp_path, capsys):
    cfg = write_toml(tmp_path, "mua = 1.0 ", 'mua = "1.0" ')
    assert run("mc", cfg, "--out", tmp_path / "o") == 2
    one_error_line(capsys, "G.media[0].mua must be a number, got '1.0'")
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------ HS.T_initial

@pytest.mark.parametrize("value", [-273.2, -1000.0, 1e4 + 1, 1e300])
def test_t_initial_below_absolute_zero_or_absurd_is_refused(tmp_path, capsys, value):
    with pytest.raises(ConfigError, match=r"HS\.T_initial must be finite and in \[-273\.15, "):
        identify_config_from_dict(with_("HS.T_initial", value))
    cfg = write_toml(tmp_path, "T_initial = 0.0 ", f"T_initial = {value!r} ")
    assert run("heat", cfg, "--out", tmp_path / "o") == 2
    one_error_line(capsys, "HS.T_initial", repr(value))
    assert not (tmp_path / "o").exists()


def test_t_initial_at_the_limits_is_taken():
    for value in (-273.15, 1e4):
        assert identify_config_from_dict(with_("HS.T_initial", value)).setup_kw is not None


# ------------------------------------------------------------------ switches

@pytest.mark.parametrize("path", [
    "MC.matched_interfaces", "MC.russian_roulette", "MC.use_light_collector",
    "MC.request_collected_photons", "MC.calc_normalized_irradiance",
    "MC.calc_normalized_fluence_rate", "MC.deposition_criteria.only_collected",
    "MC.deposition_criteria.evaluate_only_at_end_of_life",
])
@pytest.mark.parametrize("value", ["abc", math.nan, 2, 0, "true"])
def test_switches_must_be_toml_booleans(path, value):
    with pytest.raises(ConfigError) as exc:
        model_from_config(with_(path, value))
    assert str(exc.value).startswith(f"{path} must be true or false, got ")


def test_the_smoothers_gaussian_restart_switch_must_be_a_boolean():
    cfg = with_("filter.smoother_restarts", "laser_off")
    cfg["filter"]["smoother_restart_gaussian"] = 1
    with pytest.raises(ConfigError, match="filter.smoother_restart_gaussian must be true or "
                                          "false, got 1"):
        identify_config_from_dict(cfg)


# ------------------------------------------------------------------ CSV numbers

@pytest.mark.parametrize("value", ["1_0", "0x10", "\u0663", "1e"])
def test_csv_numbers_that_only_python_reads_are_refused(tmp_path, value):
    p = tmp_path / "d.csv"
    p.write_text(f"time,probe\n0.1,1.0\n0.2,{value}\n")
    with pytest.raises(ValueError, match=rf"d\.csv:3: field 2 is not a number: '{value}'"):
        read_sensor_csv(p, 1)


def test_csv_numbers_as_programs_write_them_are_read(tmp_path):
    p = tmp_path / "d.csv"
    p.write_text("time,probe\n0.1,1.5\n.2,-2.\n3e-1,+4E+1\n4e-1,-nan\n5e-1,\n")
    times, data, _ = read_sensor_csv(p, 1)
    assert times.tolist() == [0.1, 0.2, 0.3, 0.4, 0.5]
    assert data[:3, 0].tolist() == [1.5, -2.0, 40.0] and math.isnan(data[3, 0])


# ------------------------------------------------------------------ API types, 64-bit limits

def _small_model() -> Model:
    m = Model()
    m.G.nx = m.G.ny = m.G.nz = 4
    m.G.media = [Medium("t", mua=1.0, mus=10.0)]
    m.MC.n_photons_requested, m.MC.seed = 200, 1
    return m


@pytest.mark.parametrize("field, value, message", [
    ("G.geom_func", 5, r"G\.geom_func must be a function .* got 5"),
    ("G.media", Medium("t", mua=1.0, mus=10.0), r"G\.media must be a list of Medium, got "
                                                r"Medium\(name='t'"),
    ("MC.seed", 2**64, r"MC\.seed must be <= .* got 18446744073709551616"),
    ("MC.n_photons_requested", 2**70, r"MC\.n_photons_requested must be <= .* got "
                                      r"1180591620717411303424"),
])
def test_api_fields_of_the_wrong_type_are_named(field, value, message):
    m = _small_model()
    part, name = field.split(".")
    setattr(getattr(m, part), name, value)
    with pytest.raises(ValueError, match=message):
        m.run_monte_carlo()


@pytest.mark.parametrize("old, new, needle", [
    ("seed = 1\n", "seed = 1e300\n", "MC.seed must be <= "),
    ("n_photons_requested = 20_000", "n_photons_requested = 1e300",
     "MC.n_photons_requested must be <= "),
])
def test_mc_refuses_seeds_and_photons_beyond_64_bits(tmp_path, capsys, old, new, needle):
    assert run("mc", write_toml(tmp_path, old, new), "--out", tmp_path / "o") == 2
    one_error_line(capsys, needle, "1e+300")
    assert not (tmp_path / "o").exists()


def test_mc_refuses_a_photon_count_beyond_64_bits(tmp_path, capsys):
    assert run("mc", EX / "tiny.toml", "--photons", str(2**70), "--out", tmp_path / "o") == 2
    one_error_line(capsys, "--photons must be <= ")


# ------------------------------------------------------------------ the emulator, paper options

def test_mcmatlabs_pencil_code_is_the_emulators_pencil():
    from mcmatlab_py.emulator import EmulatorSpec

    ic = identify_config_from_dict(with_("MC.light_source.source_type", 0))
    assert EmulatorSpec.from_model(ic.model).source_type == "pencil"


def test_a_source_the_emulator_cannot_take_is_bad_input(tmp_path, capsys):
    cfg = write_toml(tmp_path, 'source_type = "tophat"', "source_type = 1")  # isotropic
    assert run("identify", cfg, "--data", EX / "tiny_data.csv", "--out", tmp_path / "o") == 2
    one_error_line(capsys, "MC.light_source.source_type = 1")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("option, value, needle", [
    ("--emulator-photons", "-5", "--emulator-photons must be >= 1, got -5"),
    ("--emulator-photons", "0", "--emulator-photons must be >= 1, got 0"),
    ("--emulator-table", "2", "--emulator-table must be >= 4, got 2"),
])
def test_paper_refuses_bad_emulator_options(tmp_path, capsys, option, value, needle):
    assert run("paper", "constant", option, value, "--out", tmp_path / "o") == 2
    one_error_line(capsys, needle)
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------ signals

_SIGNALLED_RUN = """
import os, signal, sys
import mcmatlab_py.plotting as plotting
from enkf.app.cli import main

def plot_na_slices(model, path):  # the run is writing its outputs: the signal arrives
    os.kill(os.getpid(), signal.{name})

plotting.plot_na_slices = plot_na_slices
sys.exit(main(["mc", {config!r}, "--out", {out!r}, "--photons", "100", "--quiet"]))
"""


@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGQUIT, signal.SIGTERM])
def test_hangup_and_quit_clean_up_as_sigterm(tmp_path, sig):
    out = tmp_path / "out"
    code = _SIGNALLED_RUN.format(name=sig.name, config=str(EX / "tiny.toml"), out=str(out))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 128 + sig, proc.stderr
    assert f"terminated ({sig.name})" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists() and not list(tmp_path.glob(".*partial"))


# ------------------------------------------------------------------ --out a file

@pytest.mark.parametrize("argv", [
    ["mc", EX / "tiny.toml"], ["heat", EX / "tiny.toml"],
    ["identify", EX / "tiny.toml", "--data", EX / "tiny_data.csv"],
    ["identify", EX / "tiny.toml", "--follow", EX / "tiny_data.csv"],
    ["paper", "constant"], ["validate", "--only", "no_such_check"],
])
@pytest.mark.parametrize("force", [[], ["--force"]])
def test_out_naming_a_file_is_refused_and_the_file_left_untouched(tmp_path, capsys, argv,
                                                                    force):
    f = tmp_path / "notes.txt"
    f.write_text("years of work")
    before = f.stat()
    assert run(*argv, "--out", f, *force) == 2
    one_error_line(capsys, "exists and is not a directory")
    after = f.stat()
    assert f.read_text() == "years of work"
    assert (after.st_ino, after.st_mtime_ns, after.st_mode) == (before.st_ino,
                                                                 before.st_mtime_ns,
                                                                 before.st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
