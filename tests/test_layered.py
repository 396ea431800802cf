"""Identification on a geometry with several media (issue #19, part 2): the config's
``filter.medium``, the layered emulator's spec and cache, and a tiny run end to end.

The Monte Carlo parity of the layered white build against direct Monte Carlo is in
``tests/test_white.py`` (``test_white_equals_direct_two_layers*``)."""

import copy
import hashlib
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from enkf.app.config import identify_config_from_dict, load_identify
from mcmatlab_py.config import ConfigError
from mcmatlab_py.emulator import CACHE_VERSION, AbsorptionEmulator, EmulatorSpec
from mcmatlab_py.model import MonteCarloSimulation

EX = Path(__file__).parents[1] / "examples"
TWO = tomllib.loads((EX / "two_layer.toml").read_text())


def tiny_two_layer():
    """two_layer.toml on 10 x 10 x 10 voxels (0.024 cm: the epidermis is the top layer),
    a 5 x 5 x 5 filter mesh and a 4 x 4 white table with few photons."""
    cfg = copy.deepcopy(TWO)
    cfg["G"].update(nx=10, ny=10, nz=10)
    cfg["G"]["regions"][0]["z_max"] = 0.024
    cfg["filter"].update(grid=[5, 5, 5], n_members=20)
    cfg["filter"]["emulator"].update(n_photons=3000, n_mua=4, n_mus=4)
    cfg["HS"].update(duration_on=1.0, duration_off=1.0)
    del cfg["data"]
    return cfg


def test_the_example_estimates_the_dermis_under_the_known_epidermis():
    cfg = load_identify(EX / "two_layer.toml")
    assert cfg.medium == 0 and cfg.emulator_method == "white"
    assert cfg.setup(lambda mua, mus: None).nominal == {"mua": 1.0, "mus": 100.0, "VHC": 3.76,
                                                         "TC": 0.0037}
    spec = EmulatorSpec.from_model(cfg.model, medium=cfg.medium, mesh_divisions=(20, 20, 10),
                                   **cfg.emulator_kw)
    assert spec.estimated == 0 and (spec.g, spec.n) == (0.9, 1.3)
    assert spec.media[1] == (5.0, 150.0, 0.8, 1.3)  # the epidermis keeps its optics
    # 80 micrometres = the top two of the 40 micrometre voxel layers
    assert (spec.medium_map == 1).all(axis=(0, 1)).tolist()[:3] == [True, True, False]
    assert (spec.medium_map[:, :, 2:] == 0).all()
    assert cfg.data.file.name == "two_layer_data.csv" and cfg.data.file.exists()


@pytest.mark.parametrize("value, index", [("epidermis", 1), (1, 1), (0, 0), ("dermis", 0)])
def test_the_estimated_medium_by_name_or_index(value, index):
    cfg = copy.deepcopy(TWO)
    cfg["filter"]["medium"] = value
    # the prior follows the estimated medium: the table must cover the epidermis's
    cfg["filter"]["emulator"].update(mua_range=[0.3, 12.0], mus_range=[30.0, 400.0])
    out = identify_config_from_dict(cfg)
    assert out.medium == index
    m = out.model.G.media[index]
    assert out.setup(lambda mua, mus: None).nominal["mua"] == m.mua


@pytest.mark.parametrize("change, message", [
    (lambda c: c["filter"].update(medium="vessel"),
     r"filter.medium = 'vessel' is not a medium of G.media \['dermis', 'epidermis'\]"),
    (lambda c: c["filter"].update(medium=2), r"filter.medium = 2 is not an index of G.media"),
    (lambda c: c["filter"].update(medium=True), "must be a medium's name or index"),
    (lambda c: c["filter"].pop("medium"), "G.media holds 2 media .* set filter.medium"),
    # a medium of G.media that no region puts into the geometry
    (lambda c: (c["G"]["media"].append({**c["G"]["media"][0], "name": "vessel"}),
                c["filter"].update(medium="vessel")),
     r"filter.medium = 'vessel' \(G.media\[2\]\) fills no voxel of the geometry"),
    (lambda c: c["G"]["media"][1].update(TC=0.005),
     r"G.media\[1\].TC = 0.005 differs from the estimated medium's 0.0037"),
    (lambda c: c["G"]["media"][0].pop("VHC"), r"G.media\[0\].VHC is needed"),
    (lambda c: c["filter"]["emulator"].update(method="fast"),
     "filter.emulator.method must be \"auto\", \"table\" or \"white\""),
    # the prior of the epidermis (2.5-10 cm^-1) is outside the example's table
    (lambda c: c["filter"].update(medium="epidermis"),
     r"filter.emulator.mua_range = \[0.3, 3.0\] must cover the prior of mua, \[2.5, 10\] "
     r"cm\^-1 \(filter.prior_range times G.media\[1\].mua\)"),
])
def test_config_errors_name_the_medium(change, message):
    cfg = copy.deepcopy(TWO)
    change(cfg)
    with pytest.raises(ConfigError, match=message):
        identify_config_from_dict(cfg)


def test_one_medium_configs_need_no_medium_and_keep_their_cache_key():
    base = tomllib.loads((EX / "tiny.toml").read_text())
    assert identify_config_from_dict(copy.deepcopy(base)).medium == 0
    cfg = copy.deepcopy(base)
    cfg["filter"]["medium"] = "standard tissue"
    assert identify_config_from_dict(cfg).medium == 0
    # the key of a one-medium spec is the one computed before several media existed
    spec = EmulatorSpec(nx=8, ny=8, nz=4, Lx=0.5, Ly=0.5, Lz=0.25, g=0.9, n=1.3,
                        source_type="tophat", radius=0.1)
    d = {k: getattr(spec, k) for k in spec.__dataclass_fields__
         if k not in ("media", "estimated", "medium_map")}
    d.update(version=CACHE_VERSION, batch_size=MonteCarloSimulation().batch_size,
             weight_threshold=MonteCarloSimulation().weight_threshold)
    old = hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:24]
    assert spec.key() == old


def layered(**kw):
    M = np.ones((6, 6, 5), dtype=np.int32)
    M[:, :, 0] = 0
    args = dict(nx=6, ny=6, nz=5, Lx=0.5, Ly=0.5, Lz=0.25, g=0.9, n=1.3, source_type="tophat",
                radius=0.1, media=((5.0, 150.0, 0.8, 1.3), (None, None, 0.9, 1.3)), estimated=1,
                medium_map=M, mua_range=(0.5, 2.0), mus_range=(50.0, 200.0), n_mua=4, n_mus=4,
                n_photons=500)
    args.update(kw)
    return EmulatorSpec(**args)


def test_the_cache_key_holds_the_other_media_and_the_geometry():
    spec = layered()
    assert spec.key() != layered(media=((5.5, 150.0, 0.8, 1.3), (None, None, 0.9, 1.3))).key()
    assert spec.key() != layered(media=((5.0, 150.0, 0.8, 1.3), (None, None, 0.8, 1.3))).key()
    M = spec.medium_map.copy()
    M[:, :, 1] = 0  # a thicker epidermis
    assert spec.key() != layered(medium_map=M).key()
    M = spec.medium_map.copy()
    M[0, 1, 2] = 0  # one voxel off the mirror symmetries
    assert layered(medium_map=M).symmetric_axes() == (False, False, False)
    assert spec.symmetric_axes() == (True, True, True)
    # the estimated medium's own values are not part of the key (the table varies them)
    assert spec.key() == layered(media=((5.0, 150.0, 0.8, 1.3), (1.0, 100.0, 0.9, 1.3))).key()
    with pytest.raises(ValueError, match="at least one voxel of the estimated medium"):
        layered(medium_map=np.zeros((6, 6, 5), dtype=np.int32))
    with pytest.raises(ValueError, match="integer indices of shape"):
        layered(medium_map=np.zeros((6, 6, 4), dtype=np.int32))


@pytest.mark.parametrize("method", ["white", "table"])
def test_layered_tables_are_cached_and_corruption_is_rebuilt(tmp_path, method):
    spec = layered()
    emu = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, method=method)
    again = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, method=method)
    np.testing.assert_array_equal(again.log_na, emu.log_na)
    (path,) = tmp_path.glob("emulator-*.npz")
    path.write_bytes(path.read_bytes()[:-100])  # a truncated file
    with pytest.warns(RuntimeWarning, match="corrupted or stale"):
        rebuilt = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False,
                                           method=method)
    np.testing.assert_array_equal(rebuilt.log_na, emu.log_na)  # deterministic for a seed


def test_identify_two_layers_end_to_end(tmp_path):
    """A tiny two-layer run: twin data of the filter's own model at dermis (1.3, 80) cm^-1."""
    from enkf.tissue import TissueForwardModel, identify, observation_operator

    cfg = identify_config_from_dict(tiny_two_layer())
    emu = cfg.emulator(cache_dir=tmp_path, progress=False)
    assert not emu.have.any()  # on demand: the points come with the members' first loads
    setup = cfg.setup(emu)
    model = TissueForwardModel(setup)
    P, _, _ = observation_operator(setup, model.mesh)
    times = np.round(np.arange(1, 21) * 0.1, 10)
    T = np.zeros((1, model.mesh.p.shape[1]))
    clean = []
    for t0, t1 in zip(np.r_[0.0, times[:-1]], times, strict=True):
        T = model(T, np.array([[1.3, 80.0]]), float(t0), float(t1))
        clean.append((P @ T.T)[:, 0])
    data = np.array(clean) + 0.1 * np.random.default_rng(0).standard_normal((20, 1))
    est = identify(setup, times, data)
    assert est.diverged is None
    assert (tmp_path / f"emulator-{cfg_key(cfg)}.npz").exists() and emu.have.any()
    lo, hi = setup.prior_bounds()
    assert np.all((lo <= est.param_mean[-1]) & (est.param_mean[-1] <= hi))
    assert est.param_std[-1, 0] < est.param_std[0, 0]  # the data told something about mua


def cfg_key(cfg):
    from mcmatlab_py.emulator import cache_key

    spec = EmulatorSpec.from_model(cfg.model, medium=cfg.medium,
                                   mesh_divisions=tuple(cfg.grid), **cfg.emulator_kw)
    return cache_key(spec, cfg.emulator_method)
