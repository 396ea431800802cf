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
    assert cfg.setup(lambda mua, mus: None).parameters.nominal == {"mua": 1.0, "mus": 100.0, "VHC": 3.76,
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
    assert out.setup(lambda mua, mus: None).parameters.nominal["mua"] == m.mua


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
    from enkf.tissue import identify

    cfg = identify_config_from_dict(tiny_two_layer())
    emu = cfg.emulator(cache_dir=tmp_path, progress=False)
    assert not emu.have.any()  # on demand: the points come with the members' first loads
    setup = cfg.setup(emu)
    times, data = twin(cfg, emu, [1.3, 80.0])
    est = identify(setup, times, data)
    assert est.diverged is None
    assert (tmp_path / f"emulator-{cfg_key(cfg)}.npz").exists() and emu.have.any()
    lo, hi = setup.parameters.prior_bounds()
    assert np.all((lo <= est.param_mean[-1]) & (est.param_mean[-1] <= hi))
    assert est.param_std[-1, 0] < est.param_std[0, 0]  # the data told something about mua


def cfg_key(cfg):
    from mcmatlab_py.emulator import cache_key

    spec = EmulatorSpec.from_model(cfg.model, medium=cfg.medium,
                                   mesh_divisions=tuple(cfg.grid), **cfg.emulator_kw)
    return cache_key(spec, cfg.emulator_method)


# ---------------------------------------------------------------- both layers estimated
def both_layers(cfg=None):
    cfg = cfg or tiny_two_layer()
    cfg["filter"].update(medium=["dermis", "epidermis"], estimate=["mua", "mus", "mua2", "mus2"])
    return cfg


def test_lagrange_weights_are_exact_for_polynomials_of_their_degree():
    from mcmatlab_py.emulator.media import lagrange_weights

    nodes = np.log([2.5, 5.0, 10.0])
    x = np.linspace(nodes[0], nodes[-1], 7)
    w = lagrange_weights(x, nodes)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-14)
    f = lambda t: 3.0 - 2.0 * t + 0.7 * t ** 2  # noqa: E731
    np.testing.assert_allclose(w @ f(nodes), f(x), rtol=1e-12)
    np.testing.assert_allclose(lagrange_weights(nodes, nodes), np.eye(3), atol=1e-14)


def test_two_media_emulator_equals_each_node_table_at_its_node(tmp_path):
    from mcmatlab_py.emulator.media import TwoMediaEmulator

    spec = layered()  # medium 1 estimated first, medium 0 (the top layer) second
    emu = TwoMediaEmulator.build(spec, 0, (2.5, 10.0), (75.0, 300.0), cache_dir=tmp_path,
                                 progress=False, method="white", n_nodes=3)
    assert emu.n_media_estimated == 2 and len(emu.tables) == 9 and emu.complete
    # the node (5, 150) is the spec's own epidermis: its table is the one-medium emulator's
    one = AbsorptionEmulator.build(spec, cache_dir=tmp_path, progress=False, method="white")
    mua, mus = np.array([0.7, 1.3]), np.array([60.0, 170.0])
    np.testing.assert_allclose(emu.unique(mua, mus, [5.0, 5.0], [150.0, 150.0]),
                               one.unique(mua, mus), rtol=1e-12)
    # a stronger epidermis absorber heats the top layer more and the dermis less
    top = spec.medium_map.ravel() == 0
    na = emu(np.full(3, 1.0), np.full(3, 100.0), [2.5, 4.0, 9.0], [150.0] * 3)
    na = na.reshape(3, -1)
    up, down = na[:, top].sum(axis=1), na[:, ~top].sum(axis=1)
    assert np.all(np.diff(up) > 0) and np.all(np.diff(down) < 0)
    with pytest.raises(ValueError, match=r"mua2 = 12.0 cm\^-1 is outside the emulator's nodes"):
        emu.unique(mua[:1], mus[:1], [12.0], [150.0])
    with pytest.raises(ValueError, match="other than the first estimated one"):
        TwoMediaEmulator.build(spec, 1, (2.5, 10.0), (75.0, 300.0), cache_dir=tmp_path)
    with pytest.raises(ValueError, match="n_nodes must be >= 2"):
        TwoMediaEmulator.build(spec, 0, (2.5, 10.0), (75.0, 300.0), n_nodes=1)
    with pytest.raises(ValueError, match=r"mus2_range must be \(lo, hi\)"):
        TwoMediaEmulator.build(spec, 0, (2.5, 10.0), (300.0, 75.0))


def test_config_estimates_both_layers():
    out = identify_config_from_dict(both_layers())
    assert (out.medium, out.second_medium) == (0, 1)
    assert out.setup_kw["estimate"] == ("mua", "mus", "mua2", "mus2")
    # the epidermis's prior, (2.5, 10) x (75, 300), widened 1.5 times each way
    assert out.media_nodes["n_nodes"] == 4
    np.testing.assert_allclose(out.media_nodes["mua2_range"], (2.5 / 1.5, 15.0))
    np.testing.assert_allclose(out.media_nodes["mus2_range"], (50.0, 450.0))
    setup = out.setup(lambda *a: None)
    assert setup.parameters.nominal["mua2"] == 5.0 and setup.parameters.nominal["mus2"] == 150.0
    lo, hi = setup.parameters.prior_bounds()
    np.testing.assert_allclose(lo, [0.5, 50.0, 2.5, 75.0])
    cfg = both_layers()
    cfg["filter"]["prior"] = {"mua2": [3.0, 8.0]}
    cfg["filter"]["emulator"].update(media_nodes=3, mus2_range=[60.0, 400.0])
    out = identify_config_from_dict(cfg)
    assert out.media_nodes == {"n_nodes": 3, "mua2_range": (2.0, 12.0),
                               "mus2_range": (60.0, 400.0)}


@pytest.mark.parametrize("change, message", [
    (lambda c: c["filter"].update(estimate=["mua", "mus"]),
     r"filter.medium names two media: filter.estimate must hold mua2 and mus2"),
    (lambda c: c["filter"].update(medium="dermis"),
     r"filter.estimate = \['mua', 'mus', 'mua2', 'mus2'\] holds mua2, mus2: name the second"),
    (lambda c: c["filter"].update(medium=["dermis", "dermis"]), "names one medium twice"),
    (lambda c: c["filter"].update(medium=["dermis", "epidermis", 0]), "a list of two"),
    (lambda c: c["filter"].update(medium=["dermis", "vessel"]),
     "filter.medium = 'vessel' is not a medium of G.media"),
    (lambda c: c["filter"]["emulator"].update(mua2_range=[3.0, 10.0]),
     r"filter.emulator.mua2_range = \[3.0, 10.0\] must cover the prior of mua2, \[2.5, 10\] "
     r"cm\^-1 \(filter.prior_range times G.media\[1\].mua\)"),
    (lambda c: c["filter"]["emulator"].update(media_nodes=1), "filter.emulator.media_nodes"),
    (lambda c: c["filter"]["emulator"].update(exact=True), "not built for two estimated media"),
    (lambda c: c["filter"]["prior"].update(mus2=[-1.0, 2.0]) if "prior" in c["filter"]
     else c["filter"].update(prior={"mus2": [-1.0, 2.0]}), "filter.prior.mus2"),
    (lambda c: c["filter"].update(parameter_model="coagulation"), "not built for a second"),
])
def test_config_errors_for_both_layers(change, message):
    cfg = both_layers()
    change(cfg)
    with pytest.raises(ConfigError, match=message):
        identify_config_from_dict(cfg)


def test_the_second_medium_keys_need_two_media():
    cfg = tiny_two_layer()
    cfg["filter"]["emulator"]["media_nodes"] = 3
    with pytest.raises(ConfigError, match=r"filter.emulator.media_nodes is for a second"):
        identify_config_from_dict(cfg)


def twin(cfg, emu, theta):
    """20 readings at 10 Hz of the config's filter model at ``theta``, noise sd 0.1."""
    from enkf.tissue import TissueForwardModel, observation_operator

    setup = cfg.setup(emu)
    model = TissueForwardModel(setup)
    P, _, _ = observation_operator(setup, model.mesh)
    times = np.round(np.arange(1, 21) * 0.1, 10)
    T = np.zeros((1, model.mesh.p.shape[1]))
    clean = []
    for t0, t1 in zip(np.r_[0.0, times[:-1]], times, strict=True):
        T = model(T, np.array([theta]), float(t0), float(t1))
        clean.append((P @ T.T)[:, 0])
    return times, np.array(clean) + 0.1 * np.random.default_rng(0).standard_normal((20, 1))


def test_identify_both_layers_end_to_end(tmp_path):
    """A tiny run estimating dermis and epidermis: twin data at (1.3, 80) and (6, 120)."""
    from enkf.tissue import TissueForwardModel, identify

    cfg = identify_config_from_dict(both_layers())
    emu = cfg.emulator(cache_dir=tmp_path, progress=False)
    assert not emu.complete  # on demand, node by node
    setup = cfg.setup(emu)
    times, data = twin(cfg, emu, [1.3, 80.0, 6.0, 120.0])
    est = identify(setup, times, data)
    assert est.diverged is None and est.names == ("mua", "mus", "mua2", "mus2")
    assert all(t.have.any() for t in emu.tables)  # every node's table was read
    assert est.param_std[-1, 0] < est.param_std[0, 0]  # the data told something about mua
    with pytest.raises(ValueError, match=r"but it \(AbsorptionEmulator\) takes \('mua', 'mus'\): "
                       "use mcmatlab_py.emulator.media.TwoMediaEmulator"):
        setup.absorption = emu.tables[0]
        TissueForwardModel(setup)
    setup.parameters.estimate = ("mua", "mus")  # and the other way round: a one-medium estimate
    setup.absorption = emu
    with pytest.raises(ValueError, match=r"takes \('mua', 'mus', 'mua2', 'mus2'\): use a "
                       "one-medium absorption model"):
        TissueForwardModel(setup)


def test_the_command_line_estimates_both_layers(tmp_path):
    """``tissue-enkf identify`` with ``filter.medium = ["dermis", "epidermis"]``: four
    parameters in summary.json, each with its medium's name."""
    from enkf.app.cli import main

    text = (EX / "two_layer.toml").read_text()
    for old, new in (("nx = 50", "nx = 10"), ("ny = 50", "ny = 10"), ("nz = 60", "nz = 10"),
                     ("z_max = 0.008     # cm", "z_max = 0.024     # cm"),
                     ("grid = [20, 20, 10]", "grid = [5, 5, 5]"),
                     ("n_members = 50", "n_members = 20"),
                     ("n_photons = 100_000", "n_photons = 3000"),
                     ("n_mua = 8", "n_mua = 4"), ("n_mus = 8", "n_mus = 4"),
                     ("duration_on = 5.0", "duration_on = 1.0"),
                     ("duration_off = 10.0", "duration_off = 1.0"),
                     ('medium = "dermis"', 'medium = ["dermis", "epidermis"]'),
                     ('estimate = ["mua", "mus"]', 'estimate = ["mua", "mus", "mua2", "mus2"]')):
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp_path / "both.toml"
    path.write_text(text)
    # twin data of the filter's own model at dermis (1.3, 80), epidermis (6, 120)
    cfg = identify_config_from_dict(both_layers())
    times, data = twin(cfg, cfg.emulator(cache_dir=tmp_path / "cache", progress=False),
                       [1.3, 80.0, 6.0, 120.0])
    np.savetxt(tmp_path / "d.csv", np.column_stack([times, data]), delimiter=",",
               header="time,T1", comments="")
    out = tmp_path / "run"
    with pytest.warns(RuntimeWarning, match="one surface sensor hardly determines the second"):
        assert main(["identify", str(path), "--data", str(tmp_path / "d.csv"), "--out",
                     str(out), "--quiet", "--cache-dir", str(tmp_path / "cache")]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert list(s["parameters"]) == ["mua", "mus", "mua2", "mus2"] and s["stopped"] is None
    assert [p["medium"] for p in s["parameters"].values()] == ["dermis"] * 2 + ["epidermis"] * 2
    points = json.loads((out / "run.json").read_text())["emulator_points"]
    assert 0 < points["built"] <= points["table"] == 16 * 16  # 4 x 4 nodes of 4 x 4 tables


@pytest.mark.slow
def test_two_media_emulator_between_nodes_agrees_with_direct_monte_carlo(tmp_path):
    """Off the nodes, at the edge of the second medium's prior and inside it: the absorbed
    power per depth layer agrees with direct Monte Carlo of the layered block within 4.5
    standard errors. The errors come from the photon counts: the sd of independent direct
    runs with a table's photons (the emulator's noise, 1.5 times for the interpolation's
    weights) and of the reference's (10 times the photons)."""
    import dataclasses

    from mcmatlab_py.emulator.exact import direct_member
    from mcmatlab_py.emulator.media import TwoMediaEmulator

    spec = layered(n_photons=20_000)
    emu = TwoMediaEmulator.build(spec, 0, (2.5, 10.0), (75.0, 300.0), cache_dir=tmp_path,
                                 progress=False, method="white")
    for mua2, mus2 in ((4.0, 200.0), (9.0, 80.0)):
        at = dataclasses.replace(spec, media=((mua2, mus2, 0.8, 1.3), spec.media[1]))
        # 8 independent direct runs with a table's photons: the sd of one
        runs = np.array([direct_member(at, s, (1.2, 90.0)).sum(axis=(0, 1)) for s in range(8)])
        se_one = runs.std(axis=0, ddof=1)
        ref = direct_member(dataclasses.replace(at, n_photons=10 * spec.n_photons), 99,
                            (1.2, 90.0)).sum(axis=(0, 1))  # 10 runs' photons
        got = emu([1.2], [90.0], [mua2], [mus2])[0].sum(axis=(0, 1))
        tol = 4.5 * np.sqrt((1.5 * se_one) ** 2 + se_one ** 2 / 10)
        assert np.all(np.abs(got - ref) <= tol), (mua2, mus2, got, ref, tol)
