"""Cache faults and Dask (issue 51): a valid run survives its cache, and ends its processes.

A directory or FIFO in place of a cache table, and a full disk (an ENOSPC injected into
the write), give one warning naming the path: the run goes on without the cache, with
the same numbers, and leaves no half-written file; the temporary cache that stands in
is removed when the process exits. Table points built before an interrupt are kept,
so that a rerun builds only the rest. Dask: a local cluster's worker processes have
ended when the client is closed; a scheduler address where nothing (or something other
than Dask) answers is refused in one line.
"""

from __future__ import annotations

import errno
import os
import socket
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest

import mcmatlab_py.emulator.absorption as emulator_module
from mcmatlab_py.emulator import AbsorptionEmulator, EmulatorSpec, cache_key


def small_spec(**kw):
    args = dict(nx=6, ny=6, nz=4, Lx=0.5, Ly=0.5, Lz=0.25, g=0.9, n=1.3, source_type="tophat",
                radius=0.1, mua_range=(0.5, 4.0), mus_range=(50.0, 400.0), n_mua=4, n_mus=4,
                n_photons=1000, seed=3)
    args.update(kw)
    return EmulatorSpec(**args)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The table built with a working cache."""
    return AbsorptionEmulator.build(small_spec(), cache_dir=tmp_path_factory.mktemp("ok"),
                                    progress=False)


def build(cache, **kw):
    return AbsorptionEmulator.build(small_spec(), cache_dir=cache, progress=False, **kw)


def entry(cache: Path) -> Path:
    return cache / f"emulator-{cache_key(small_spec())}.npz"


@pytest.mark.parametrize("kind", ["directory", "fifo"])
def test_a_directory_or_fifo_in_place_of_a_table_is_left_alone(tmp_path, reference, kind):
    cache = tmp_path / "cache"
    cache.mkdir()
    path = entry(cache)
    if kind == "directory":
        path.mkdir()
        (path / "mine.txt").write_text("x")
    else:
        os.mkfifo(path)  # opened for reading, it would wait for a writer forever
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        emu = build(cache)
    messages = [str(w.message) for w in rec]
    assert len(messages) == 1, messages
    assert f"the cache entry {str(path)!r} cannot be used (it is a " in messages[0]
    assert "removed when this run ends" in messages[0]
    np.testing.assert_array_equal(emu.log_na, reference.log_na)
    assert (path / "mine.txt").exists() if kind == "directory" else path.is_fifo()


def test_a_full_disk_gives_one_warning_and_the_same_numbers(tmp_path, reference, monkeypatch):
    def full(file, **arrays):
        Path(file).write_bytes(b"PK\x03\x04 half a table")  # written in part, then ENOSPC
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(emulator_module.np, "savez", full)
    cache = tmp_path / "cache"
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        emu = build(cache, on_demand=True)
        emu.fill(np.ones_like(emu.have))  # two fills: still one warning
        emu.fill(np.ones_like(emu.have))
    messages = [str(w.message) for w in rec]
    assert messages == [f"the emulator cache {str(entry(cache))!r} cannot be written (No space "
                        "left on device): the run goes on without it"]
    np.testing.assert_array_equal(emu.log_na, reference.log_na)
    assert list(cache.iterdir()) == []  # no half-written table
    monkeypatch.undo()
    np.testing.assert_array_equal(build(cache).log_na, reference.log_na)  # a later run


def test_the_temporary_cache_is_removed_at_exit(tmp_path):
    blocker = tmp_path / "cache"
    blocker.write_text("a file where the folder should be")
    code = ("import warnings, mcmatlab_py.emulator as e\n"
            "from pathlib import Path\n"
            "with warnings.catch_warnings(record=True) as rec:\n"
            "    warnings.simplefilter('always')\n"
            f"    d = e.usable_cache_dir(Path({str(blocker)!r}))\n"
            "(d / 'table.npz').write_bytes(b'x')\n"
            "print(d)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    tmp = Path(proc.stdout.strip())
    assert tmp.name.startswith("tissue-enkf-cache-") and not tmp.exists()


def test_points_built_before_an_interrupt_are_kept(tmp_path, reference, monkeypatch):
    cache = tmp_path / "cache"
    real = emulator_module.table_point
    calls = []

    def interrupted(spec, point):
        if len(calls) == 5:
            raise KeyboardInterrupt
        calls.append(point)
        return real(spec, point)

    monkeypatch.setattr(emulator_module, "table_point", interrupted)
    with pytest.raises(KeyboardInterrupt):
        build(cache)
    with np.load(entry(cache)) as f:
        assert f["have"].sum() == 5
    calls.clear()
    monkeypatch.setattr(emulator_module, "table_point", lambda spec, point: (
        calls.append(point), real(spec, point))[1])
    emu = build(cache)  # the rerun builds the other 11 points only
    assert len(calls) == 11
    np.testing.assert_array_equal(emu.log_na, reference.log_na)
    assert not [p for p in cache.iterdir() if p.name != entry(cache).name]


# ----------------------------------------------------------------------------- Dask

distributed = pytest.importorskip("dask.distributed")


def _ended(pid: int) -> bool:
    import psutil

    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def test_the_local_clusters_processes_end_with_the_client():
    from mcmatlab_py.distributed import close, connect

    client = connect(n_workers=1)
    pids = [w.pid for w in client.cluster.workers.values()]
    assert pids and not any(_ended(p) for p in pids)
    close(client)
    assert all(_ended(p) for p in pids)


def test_a_worker_that_outlives_its_clusters_close_is_ended():
    """A cluster whose close returns before its worker processes end (seen: 1 to 3 s)."""
    from mcmatlab_py.distributed import close, connect

    client = connect(n_workers=1)
    cluster = client.cluster
    pids = [w.pid for w in cluster.workers.values()]
    real_close = cluster.close
    cluster.close = lambda *a, **kw: None
    try:
        close(client, timeout=1.0)
        assert pids and all(_ended(p) for p in pids)
    finally:
        real_close()


@pytest.fixture
def not_dask():
    """An address where a server answers in HTTP."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(5)
    stop = threading.Event()

    def serve():
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                continue
            conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: 5\r\n\r\nhello" * 10)
            conn.close()
    th = threading.Thread(target=serve, daemon=True)
    th.start()
    yield f"tcp://127.0.0.1:{srv.getsockname()[1]}"
    stop.set()
    th.join()
    srv.close()


def closed_port() -> str:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return f"tcp://127.0.0.1:{port}"


def test_a_scheduler_address_without_dask_is_refused_naming_it(not_dask):
    from mcmatlab_py.distributed import connect

    for address in (not_dask, closed_port()):
        with pytest.raises(ValueError, match=f"no Dask scheduler answered at {address} "
                                             "within 2 s"):
            connect(address, timeout=2)


def test_the_tool_refuses_a_scheduler_that_is_not_dask(tmp_path, capsys, not_dask):
    from enkf.app.cli import main

    ex = Path(__file__).parents[1] / "examples"
    assert main(["mc", str(ex / "tiny.toml"), "--out", str(tmp_path / "o"), "--photons", "100",
                 "--scheduler", not_dask]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: no Dask scheduler answered at {not_dask}") and \
        err.count("\n") == 1, err
    assert "MemoryError" in err and not (tmp_path / "o").exists()
