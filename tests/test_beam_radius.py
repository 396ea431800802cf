"""The beam radius as an input the ensemble carries (issue #18): the emulator over the
radius, the config, the forward model's checks, and a twin that recovers the radius."""

from __future__ import annotations

import copy
import json
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

from enkf.app.config import ConfigError, identify_config_from_dict
from mcmatlab_py.emulator import AbsorptionEmulator, EmulatorSpec
from mcmatlab_py.emulator.media import BeamRadiusEmulator

EX = Path(__file__).parents[1] / "examples"


@pytest.fixture(scope="module")
def tiny():
    return tomllib.loads((EX / "tiny.toml").read_text())


def _cfg(tiny, estimate=("mua", "mus", "beam_radius"), **emulator):
    cfg = copy.deepcopy(tiny)
    cfg["filter"]["estimate"] = list(estimate)
    cfg["filter"]["emulator"].update(emulator)
    return cfg


def spec(**kw):
    base = dict(nx=10, ny=10, nz=5, Lx=0.5, Ly=0.5, Lz=0.25, g=0.9, n=1.3, source_type="tophat",
                radius=0.1, n_mua=4, n_mus=4, n_photons=4000, mesh_divisions=(5, 5, 5))
    return EmulatorSpec(**{**base, **kw})


def test_beam_radius_emulator_is_each_node_table_at_its_node(tmp_path):
    s = spec()
    emu = BeamRadiusEmulator.build(s, (0.08, 0.125), n_nodes=3, cache_dir=tmp_path,
                                   progress=False, method="white")
    assert emu.extra_names == ("beam_radius",) and len(emu.tables) == 3 and emu.complete
    np.testing.assert_allclose(emu.radius_nodes, [0.08, 0.1, 0.125])
    # the middle node is the spec's own beam: its table is the one-radius emulator's
    one = AbsorptionEmulator.build(s, cache_dir=tmp_path, progress=False, method="white")
    mua, mus = np.array([0.7, 1.3]), np.array([60.0, 170.0])
    np.testing.assert_allclose(emu.unique(mua, mus, [0.1, 0.1]), one.unique(mua, mus),
                               rtol=1e-12)
    assert emu.ranges["beam_radius"] == (0.08, 0.125)
    # the same power through a wider beam: less at the centre, more beyond the narrow edge
    na = emu(np.ones(3), np.full(3, 100.0), [0.085, 0.1, 0.12]).reshape(3, 6, 6, 6)
    centre, rim = na[:, 2:4, 2:4, 0].sum(axis=(1, 2)), na[:, 0, :, 0].sum(axis=1)
    assert np.all(np.diff(centre) < 0) and np.all(np.diff(rim) > 0)
    with pytest.raises(ValueError, match=r"beam_radius = 0.13 cm is outside the emulator's nodes"):
        emu.unique(mua[:1], mus[:1], [0.13])
    emu.out_of_range = "clamp"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        emu.unique(mua[:1], mus[:1], [0.13])
    assert any("clamped" in str(w.message) for w in caught)


@pytest.mark.parametrize("kw, message", [
    (dict(n_nodes=1), "n_nodes must be >= 2"),
    (dict(radius_range=(0.12, 0.08)), r"radius_range must be \(lo, hi\)"),
])
def test_beam_radius_emulator_refuses_bad_nodes(kw, message):
    with pytest.raises(ValueError, match=message):
        BeamRadiusEmulator.build(spec(), kw.pop("radius_range", (0.08, 0.12)), **kw)


def test_beam_radius_emulator_needs_a_beam_with_a_radius():
    with pytest.raises(ValueError, match="'tophat' or 'gaussian' beam, not of "
                                         "spec.source_type = 'pencil'"):
        BeamRadiusEmulator.build(spec(source_type="pencil"), (0.08, 0.12))


def test_config_carries_the_beam_radius(tiny):
    out = identify_config_from_dict(_cfg(tiny))
    assert out.setup_kw["estimate"] == ("mua", "mus", "beam_radius")
    # the prior is +-10% of MC.light_source.radius, the nodes that widened 1.1 times
    assert out.beam_nodes["n_nodes"] == 4
    np.testing.assert_allclose(out.beam_nodes["radius_range"], (0.09 / 1.1, 0.11 * 1.1))
    setup = out.setup(lambda *a: None)
    assert setup.parameters.nominal["beam_radius"] == 0.1
    lo, hi = setup.parameters.prior_bounds()
    np.testing.assert_allclose(lo, [0.5, 50.0, 0.09])
    np.testing.assert_allclose(hi, [2.0, 200.0, 0.11])
    cfg = _cfg(tiny, radius_nodes=3, radius_range=[0.07, 0.13])
    cfg["filter"]["prior"] = {"beam_radius": [0.08, 0.12]}
    out = identify_config_from_dict(cfg)
    assert out.beam_nodes == {"n_nodes": 3, "radius_range": (0.07, 0.13)}
    np.testing.assert_allclose(out.setup(lambda *a: None).parameters.prior_bounds()[0][2], 0.08)


@pytest.mark.parametrize("change, message", [
    (dict(radius_range=[0.095, 0.12]),
     r"filter.emulator.radius_range = \[0.095, 0.12\] must cover the prior of beam_radius, "
     r"\[0.09, 0.11\] cm"),
    (dict(radius_nodes=1), "filter.emulator.radius_nodes must be >= 2"),
    (dict(exact=True), "filter.emulator.exact = true is not built for an estimated beam radius"),
])
def test_config_refuses_bad_beam_radius_settings(tiny, change, message):
    with pytest.raises(ConfigError, match=message):
        identify_config_from_dict(_cfg(tiny, **change))


def test_config_refuses_radius_keys_without_the_radius_and_a_pencil_beam(tiny):
    with pytest.raises(ConfigError, match="filter.emulator.radius_range is for an estimated "
                                          "beam radius"):
        identify_config_from_dict(_cfg(tiny, ("mua", "mus"), radius_range=[0.05, 0.2]))
    cfg = _cfg(tiny)
    cfg["MC"]["light_source"]["source_type"] = "pencil"
    with pytest.raises(ConfigError, match="source_type = 'pencil' has no radius"):
        identify_config_from_dict(cfg)
    cfg = _cfg(tiny)
    cfg["filter"]["parameter_model"] = "trend"
    with pytest.raises(ConfigError, match="is not built for the beam's radius"):
        identify_config_from_dict(cfg)


def test_forward_model_says_which_absorption_model_the_radius_needs(tiny):
    from enkf.tissue import TissueForwardModel

    out = identify_config_from_dict(_cfg(tiny))
    one = lambda mua, mus: np.zeros((np.size(mua), 5, 5, 5))  # noqa: E731
    with pytest.raises(ValueError, match="use mcmatlab_py.emulator.media.BeamRadiusEmulator"):
        TissueForwardModel(out.setup(one))


def test_twin_recovers_a_wider_beam(tmp_path, tiny):
    """Frames of a camera made by the filter's own model at radius 0.107 cm (mua 1, mus
    100): the filter with the radius estimated holds all three in their +-2 sd bands, and
    the frames narrow the radius's prior (uniform 0.09-0.11 cm)."""
    from enkf.tissue import TissueForwardModel, identify, observation_operator

    cfg = _cfg(tiny)
    cfg["G"].update(nx=20, ny=20, nz=10)
    cfg["HS"].update(duration_on=2.0, duration_off=1.0)
    cfg["sensors"] = {"positions": [], "camera": {"x_range": [-0.2, 0.2], "y_range": [-0.2, 0.2],
                                                  "shape": [8, 8], "noise_var": 0.01}}
    cfg["filter"].update(n_members=40, grid=[10, 10, 5])
    out = identify_config_from_dict(cfg)
    emu = out.emulator(cache_dir=tmp_path, progress=False)
    setup = out.setup(emu, seed=3)
    model = TissueForwardModel(setup)
    P = observation_operator(setup, model.mesh)[0]
    truth = np.array([[1.0, 100.0, 0.107]])
    times = np.round(0.1 * np.arange(1, 31), 10)
    T, rng = np.zeros((1, model.mesh.p.shape[1])), np.random.default_rng(5)
    data, t0 = [], 0.0
    for t in times:
        T = model(T, truth, t0, t)
        data.append((P @ T[0]) + 0.1 * rng.standard_normal(P.shape[0]))
        t0 = t
    est = identify(setup, times, np.array(data), param_bounds=out.param_bounds)
    mean, sd = est.param_mean[-1], est.param_std[-1]
    assert np.all(np.abs(mean - truth[0]) <= 2 * sd), (mean, sd)
    assert sd[2] < 0.5 * 0.02 / np.sqrt(12), sd  # the frames narrowed the radius's prior


def test_the_command_line_carries_the_beam_radius(tmp_path):
    """``tissue-enkf identify`` with ``estimate = ["mua", "mus", "beam_radius"]``: the
    radius in summary.json, estimates.csv and the figure of the estimates."""
    from enkf.app.cli import main

    cfg = tmp_path / "beam.toml"
    cfg.write_text((EX / "tiny.toml").read_text().replace(
        "[filter]\n", '[filter]\nestimate = ["mua", "mus", "beam_radius"]\n', 1))
    out = tmp_path / "id"
    assert main(["identify", str(cfg), "--data", str(EX / "tiny_data.csv"), "--out", str(out),
                 "--quiet", "--cache-dir", str(tmp_path / "cache")]) == 0
    s = json.loads((out / "summary.json").read_text())
    r = s["parameters"]["beam_radius"]
    assert 0.09 / 1.1 <= r["estimate_final"] <= 0.11 * 1.1 and 0 < r["std_final"] < 0.006
    header = (out / "estimates.csv").read_text().splitlines()[0].split(",")
    assert "beam_radius_mean" in header and "beam_radius_std" in header
    assert (out / "figures" / "estimates.png").stat().st_size > 0
