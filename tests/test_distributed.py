"""Dask: a local cluster of 2 workers gives exactly the single-machine numbers; failures."""

import os
from pathlib import Path

import numpy as np
import pytest

from mcmatlab_py import Medium, Model
from mcmatlab_py.distributed import TaskError, run_tasks, split_range
from mcmatlab_py.emulator import AbsorptionEmulator, DirectMonteCarloAbsorption, EmulatorSpec

distributed = pytest.importorskip("dask.distributed")


def tiny_model(n_photons=20_000, seed=3):
    m = Model()
    m.G.nx, m.G.ny, m.G.nz = 10, 10, 5
    m.G.Lx, m.G.Ly, m.G.Lz = 0.5, 0.5, 0.25
    m.G.media = [Medium("tissue", mua=1.0, mus=100.0, g=0.9, n=1.3)]
    m.G.geom_func = lambda X, Y, Z: np.zeros(X.shape, dtype=int)
    m.MC.n_photons_requested = n_photons
    m.MC.seed = seed
    m.MC.progress = False
    m.MC.light_source.source_type = "tophat"
    m.MC.light_source.radius = 0.1
    return m


@pytest.fixture(scope="module")
def client():
    from mcmatlab_py.distributed import connect

    c = connect(n_workers=2)
    yield c
    c.close()
    c.cluster.close()


def test_monte_carlo_on_the_cluster_equals_this_machine(client):
    here = tiny_model().run_monte_carlo().MC
    there = tiny_model().run_monte_carlo(client=client).MC
    np.testing.assert_array_equal(there.NA, here.NA)
    assert there.escaped == here.escaped and there.n_photons == here.n_photons


def test_emulator_table_on_the_cluster_equals_this_machine(client, tmp_path):
    spec = EmulatorSpec.from_model(tiny_model(), n_photons=2000, n_mua=4, n_mus=4,
                                   mesh_divisions=(5, 5, 5))
    here = AbsorptionEmulator.build(spec, cache_dir=tmp_path / "a", progress=False)
    there = AbsorptionEmulator.build(spec, cache_dir=tmp_path / "b", progress=False,
                                     client=client)
    np.testing.assert_array_equal(there.log_na, here.log_na)
    np.testing.assert_array_equal(there.absorbed, here.absorbed)


def test_exact_mode_members_on_the_cluster(client):
    spec = EmulatorSpec.from_model(tiny_model(), n_photons=3000)
    mua, mus = np.array([0.5, 2.0, 1.0]), np.array([50.0, 150.0, 300.0])
    here = DirectMonteCarloAbsorption(spec)(mua, mus)
    there = DirectMonteCarloAbsorption(spec, client=client)(mua, mus)
    np.testing.assert_array_equal(there, here)


def _fail_once(marker: str, x: int) -> int:
    """Raises on its first call for ``x == 1`` (a marker file records the attempt)."""
    path = Path(marker) / f"{x}.tried"
    if x == 1 and not path.exists():
        path.touch()
        raise RuntimeError("transient failure")
    return 10 * x


def _die_once(marker: str, x: int) -> int:
    """Kills its worker process the first time it sees ``x == 2``."""
    path = Path(marker) / f"{x}.died"
    if x == 2 and not path.exists():
        path.touch()
        os._exit(1)
    return 10 * x


def _bad_item(x: int) -> int:
    if x == 3:
        raise ValueError("data file 3 is unreadable")
    return x


def test_a_failed_task_is_retried(client, tmp_path):
    import functools

    f = functools.partial(_fail_once, str(tmp_path))
    assert run_tasks(f, range(4), client=client, retries=1) == [0, 10, 20, 30]
    g = functools.partial(_fail_once, str(tmp_path / "local"))
    (tmp_path / "local").mkdir()
    assert run_tasks(g, range(4), retries=1) == [0, 10, 20, 30]


def test_a_worker_that_dies_mid_task_has_its_task_rerun(client, tmp_path):
    import functools

    f = functools.partial(_die_once, str(tmp_path))
    assert run_tasks(f, range(4), client=client) == [0, 10, 20, 30]
    assert (tmp_path / "2.died").exists()


@pytest.mark.parametrize("use_client", [False, True])
def test_a_bad_item_is_reported_and_the_others_go_on(client, use_client):
    out = run_tasks(_bad_item, range(5), client=client if use_client else None, retries=0,
                    errors="return")
    assert out[:3] == [0, 1, 2] and out[4] == 4
    assert isinstance(out[3], TaskError) and "unreadable" in str(out[3])
    with pytest.raises(TaskError, match="task 3 failed: ValueError"):
        run_tasks(_bad_item, range(5), client=client if use_client else None, retries=0)


def test_split_range_covers_every_batch_once():
    for n, parts in [(10, 3), (7, 7), (5, 9), (1000, 8)]:
        ranges = split_range(n, parts)
        assert ranges[0][0] == 0 and ranges[-1][1] == n
        assert all(a < b for a, b in ranges)
        assert all(r[1] == s[0] for r, s in zip(ranges[:-1], ranges[1:], strict=True))


@pytest.mark.slow
def test_mc_command_on_a_local_cluster_writes_the_same_maps(tmp_path):
    from enkf.app.cli import main

    cfg = Path(__file__).parents[1] / "examples" / "standard_tissue.toml"
    common = [str(cfg), "--photons", "20000", "--quiet", "--seed", "4"]
    assert main(["mc", *common, "--out", str(tmp_path / "here")]) == 0
    assert main(["mc", *common, "--out", str(tmp_path / "there"), "--workers", "2"]) == 0
    with np.load(tmp_path / "here" / "NA.npz") as a, np.load(tmp_path / "there" / "NA.npz") as b:
        np.testing.assert_array_equal(a["NA"], b["NA"])
    assert main(["mc", *common, "--out", str(tmp_path / "x"), "--workers", "0"]) == 2
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_identify_batch_on_a_local_cluster_equals_this_machine(tmp_path):
    from enkf.app.cli import main

    ex = Path(__file__).parents[1] / "examples"
    bad = tmp_path / "bad.csv"
    bad.write_text("time,sensor_0\n0.2,1\n0.1,2\n")
    common = ["identify", str(ex / "tiny.toml"), "--data", str(ex / "tiny_data.csv"), str(bad),
              "--quiet", "--cache-dir", str(tmp_path / "cache")]
    assert main([*common, "--out", str(tmp_path / "here")]) == 0
    assert main([*common, "--out", str(tmp_path / "there"), "--workers", "2"]) == 0
    here = (tmp_path / "here" / "batch.csv").read_text()
    assert here == (tmp_path / "there" / "batch.csv").read_text()
    assert "unsorted times" in here.splitlines()[2]
