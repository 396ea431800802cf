"""The MCmatlab-style API contract, bad input, and the ``tissue-enkf mc`` command."""

import json

import numpy as np
import pytest

from enkf.app.cli import main
from mcmatlab_py import Medium, Model

SMALL_TOML = """
[G]
nx = 10
ny = 10
nz = 5
Lx = 0.5
Ly = 0.5
Lz = 0.25

[[G.media]]
name = "standard tissue"
mua = 1.0
mus = 100.0
g = 0.9
n = 1.3

[MC]
n_photons_requested = 2000
seed = 1

[MC.light_source]
source_type = "tophat"
radius = 0.1
"""


def contract_model():
    model = Model()
    model.G.nx, model.G.ny, model.G.nz = 20, 20, 10
    model.G.Lx, model.G.Ly, model.G.Lz = 0.5, 0.5, 0.25
    model.G.media = [Medium("standard tissue", mua=1.0, mus=100.0, g=0.9, n=1.3, VHC=3.76,
                            TC=0.0037)]
    model.G.geom_func = lambda X, Y, Z: np.zeros(X.shape, dtype=int)
    model.MC.n_photons_requested = 2000
    model.MC.seed = 1
    model.MC.matched_interfaces = True
    model.MC.boundary_type = 1
    model.MC.light_source.source_type = "tophat"
    model.MC.light_source.radius = 0.1
    model.MC.progress = False
    return model


def test_contract_names():
    model = contract_model().run_monte_carlo()
    MC = model.MC
    assert MC.NA.shape == MC.NFR.shape == (20, 20, 10)
    assert 0 < MC.absorbed_fraction < 1
    assert MC.specular_reflectance == 0.0
    assert set(MC.escaped) == {"top", "bottom", "sides"}
    assert MC.n_photons == 2000 and MC.photons_per_second > 0
    # NA integrates to the absorbed fraction
    assert MC.NA.sum() * model.G.dx * model.G.dy * model.G.dz == pytest.approx(MC.absorbed_fraction)


def test_simulation_time_requested():
    model = contract_model()
    model.MC.n_photons_requested = None
    model.MC.simulation_time_requested = 0.5 / 60  # minutes, as MCmatlab
    MC = model.run_monte_carlo().MC
    assert MC.n_photons > 0 and MC.n_photons % model.MC.batch_size == 0


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"mua": -1.0}, "mua"),
        ({"mus": float("nan")}, "mus"),
        ({"g": 1.5}, "g"),
        ({"g": -1.5}, "g"),
        ({"n": 0.9}, "n"),
        ({"VHC": 0.0}, "VHC"),
        ({"TC": -0.1}, "TC"),
    ],
)
def test_bad_medium_names_field_and_value(kwargs, field):
    args = {"name": "t", "mua": 1.0, "mus": 10.0, "g": 0.9, "n": 1.3, **kwargs}
    with pytest.raises(ValueError, match=rf"\.{field} must .*got"):
        Medium(**args)


@pytest.mark.parametrize(
    "mutate, pattern",
    [
        (lambda m: setattr(m.G, "nx", 0), r"G\.nx must be >= 1, got 0"),
        (lambda m: setattr(m.G, "Lz", -0.1), r"G\.Lz must be > 0, got -0\.1"),
        (lambda m: setattr(m.G, "media", []), r"G\.media"),
        (lambda m: setattr(m.G, "geom_func", lambda X, Y, Z: np.full(X.shape, 3)),
         r"medium index 3"),
        (lambda m: setattr(m.MC.light_source, "source_type", "laser"), r"source_type.*'laser'"),
        (lambda m: setattr(m.MC, "boundary_type", 7), r"MC\.boundary_type.*got 7"),
        (lambda m: setattr(m.MC.light_source, "radius", -1), r"radius must be > 0, got -1"),
        (lambda m: setattr(m.G.media[0], "mua", -2.0), r"mua must be >= 0, got -2\.0"),
    ],
)
def test_bad_model_raises_value_error(mutate, pattern):
    model = contract_model()
    mutate(model)
    with pytest.raises(ValueError, match=pattern):
        model.run_monte_carlo()


def test_cli_mc_writes_outputs(tmp_path):
    cfg = tmp_path / "m.toml"
    cfg.write_text(SMALL_TOML)
    out = tmp_path / "out"
    assert main(["mc", str(cfg), "--out", str(out), "--quiet", "--seed", "4"]) == 0
    assert {p.name for p in out.iterdir()} == {"NA.npz", "NA.vtu", "NA_slices.png", "summary.json",
                                                "run.json"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["seed"] == 4 and summary["n_photons"] == 2000
    assert summary["energy_balance"] == pytest.approx(1.0)
    with np.load(out / "NA.npz") as f:
        assert f["NA"].shape == (10, 10, 5)
    import pyvista

    grid = pyvista.read(out / "NA.vtu")
    assert grid.n_cells == 500
    np.testing.assert_allclose(np.asarray(grid.cell_data["NA"]), f_na(out).ravel())
    # an existing non-empty --out is refused without --force
    assert main(["mc", str(cfg), "--out", str(out), "--quiet"]) == 2


def f_na(out):
    with np.load(out / "NA.npz") as f:
        return f["NA"]


@pytest.mark.parametrize(
    "text, message",
    [
        (SMALL_TOML.replace("mua = 1.0", "mua = -1.0"), "mua must be >= 0, got -1.0"),
        (SMALL_TOML.replace("g = 0.9", "g = 1.2"), "g must be in [-1, 1], got 1.2"),
        (SMALL_TOML.replace("n = 1.3", "n = 0.5"), "n must be >= 1, got 0.5"),
        (SMALL_TOML.replace("nx = 10", "nx = 0"), "G.nx must be >= 1, got 0"),
        (SMALL_TOML.replace("seed = 1", "sead = 1"), "unknown key MC.sead"),
        (SMALL_TOML.replace('"tophat"', '"laser"'), "'laser'"),
        ("this is [not toml", "is not valid TOML"),
    ],
)
def test_cli_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, text, message):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    assert main(["mc", str(cfg), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and message in err and len(err.splitlines()) == 1
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [cfg]


def test_cli_missing_file_exits_2(tmp_path, capsys):
    assert main(["mc", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_config_regions_fill_boxes_with_other_media():
    from mcmatlab_py.config import model_from_config

    cfg = {"G": {"nx": 4, "ny": 4, "nz": 4, "Lx": 1, "Ly": 1, "Lz": 1,
                 "media": [{"mua": 1, "mus": 10}, {"mua": 2, "mus": 20}],
                 "regions": [{"medium": 1, "z_min": 0.5}]}}
    M = model_from_config(cfg).G.medium_map()
    assert (M[:, :, :2] == 0).all() and (M[:, :, 2:] == 1).all()
    cfg["G"]["regions"] = [{"medium": 1, "depth": 0.5}]
    with pytest.raises(ValueError, match="unknown key G.regions\\[0\\].depth"):
        model_from_config(cfg)
