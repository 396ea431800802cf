"""Property tests: random configs and data files either load or fail with the clear error."""

import copy
import tomllib
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from enkf.app.config import check_identify_keys, identify_config_from_dict
from enkf.app.readers import read_sensor_csv
from mcmatlab_py.config import ConfigError, model_from_config, read_toml

EX = Path(__file__).parents[1] / "examples"
BASE = tomllib.loads((EX / "tiny.toml").read_text())

values = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
    st.lists(st.floats(-10, 10), max_size=4),
    st.lists(st.lists(st.floats(-1, 1), min_size=3, max_size=3), max_size=3),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)


def paths(d, prefix=()):
    for k, v in d.items():
        yield prefix + (k,)
        if isinstance(v, dict):
            yield from paths(v, prefix + (k,))
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for i, item in enumerate(v):
                yield from paths(item, prefix + (k, i))


ALL_PATHS = list(paths(BASE))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(ALL_PATHS), values, st.booleans())
def test_a_mutated_config_loads_or_fails_clearly(path, value, new_key):
    cfg = copy.deepcopy(BASE)
    node = cfg
    for k in path[:-1]:
        node = node[k]
    key = path[-1] if not new_key else f"{path[-1]}_x"
    if isinstance(node, dict):
        node[key] = value
    try:
        identify_config_from_dict(cfg)
    except ConfigError as err:  # a ValueError naming the key
        assert str(err)


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=200))
def test_random_bytes_as_toml_fail_clearly(tmp_path_factory, data):
    p = tmp_path_factory.mktemp("t") / "c.toml"
    p.write_bytes(data)
    try:
        identify_config_from_dict(read_toml(p))
    except ConfigError as err:
        assert str(err)


cells = st.one_of(st.just(""), st.just("nan"), st.just("inf"), st.just("abc"),
                  st.floats(-1e3, 1e3).map(lambda v: f"{v:.3f}"))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(cells, min_size=1, max_size=4), max_size=6),
       st.sampled_from(["time,sensor_0", "time,a,b", "t_ms,x", "", "time"]))
def test_random_csv_loads_or_fails_clearly(tmp_path_factory, rows, header):
    p = tmp_path_factory.mktemp("d") / "d.csv"
    p.write_text("\n".join([header] + [",".join(r) for r in rows]) + "\n")
    try:
        times, data, names = read_sensor_csv(p, 1)
    except ValueError as err:
        assert str(err)
        return
    assert np.all(np.diff(times) > 0) and times[0] > 0 and np.all(np.isfinite(times))
    assert data.shape == (len(times), 1) and not np.any(np.isinf(data))


EXTRA_PATHS = [("data", "file"), ("data", "columns"), ("data", "time_offset"),
               ("filter", "bounds", "mua"), ("filter", "bounds", "VHC"), ("filter", "bounds"),
               ("HS", "mesh_divisions"), ("HS", "T_ambient"), ("HS", "heat_transfer_coefficient"),
               ("HS", "heat_boundary_type"), ("sensors", "rate"), ("run", "workers"),
               ("run", "scheduler"), ("data",), ("run",)]


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(EXTRA_PATHS), values)
def test_the_optional_tables_load_or_fail_clearly(path, value):
    cfg = copy.deepcopy(BASE)
    node = cfg
    for k in path[:-1]:
        node = node.setdefault(k, {})
    node[path[-1]] = value
    try:
        identify_config_from_dict(cfg)
    except ConfigError as err:
        assert str(err) and "\n" not in str(err)
    # the `heat` command's reading of the same file: the model, then the other tables' keys
    try:
        model = model_from_config(cfg)
        check_identify_keys(cfg)
        model.HS.validate(model.G)
    except ValueError as err:
        assert str(err)


HEADERS = ["", "[G]", "[[G.media]]", "[MC]", "[MC.light_source]", "[HS]", "[sensors]",
           "[filter]", "[filter.emulator]", "[filter.bounds]", "[data]", "[run]", "[G.x]"]
KEYS = ["nx", "Lx", "mua", "mus", "g", "n", "VHC", "TC", "dt", "P", "positions", "n_members",
        "grid", "method", "file", "columns", "mua_range", "seed", "radius", "unknown"]
VALUES = ["1", "0", "-1", "0.5", "nan", "inf", "-inf", "1e400", "\"x\"", "[1, 2, 3]", "[]",
          "[[0.0, 0.0, 0.0]]", "true", "{a = 1}", "\"etkf\"", "[0.5, 2.0]"]


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(HEADERS),
                          st.lists(st.tuples(st.sampled_from(KEYS), st.sampled_from(VALUES)),
                                   max_size=4)), max_size=8),
       st.booleans())
def test_random_toml_text_loads_or_fails_clearly(tmp_path_factory, tables, on_top_of_tiny):
    text = "\n".join(f"{h}\n" + "\n".join(f"{k} = {v}" for k, v in kv) for h, kv in tables)
    p = tmp_path_factory.mktemp("t") / "c.toml"
    p.write_text(((EX / "tiny.toml").read_text() + "\n" if on_top_of_tiny else "") + text)
    try:
        identify_config_from_dict(read_toml(p))
    except ConfigError as err:
        assert str(err)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.lists(cells, min_size=3, max_size=3), max_size=5),
       st.lists(st.sampled_from(["a", "b", "c", "time", ""]), max_size=3),
       st.one_of(st.none(), st.floats(-1, 1)))
def test_csv_with_columns_and_offset_loads_or_fails_clearly(tmp_path_factory, rows, cols, offset):
    p = tmp_path_factory.mktemp("d") / "d.csv"
    p.write_text("\n".join(["time,a,b"] + [",".join(r) for r in rows]) + "\n")
    try:
        times, data, names = read_sensor_csv(p, len(cols), columns=cols, time_offset=offset)
    except ValueError as err:
        assert str(err)
        return
    assert np.all(np.diff(times) > 0) and times[0] > 0 and data.shape == (len(times), len(cols))
    assert names == ["time", *cols]
