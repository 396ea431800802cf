"""--force replaces a run atomically (issue 51): at every moment --out holds the old whole
run or the new whole run, whatever kills the process, and a complete run is never
deleted by the next one.

A child process (``os.fork``: the modules are already imported) replaces a run and is
killed with SIGKILL at its k-th file-system step, for every k; the parent then checks what
is on disk, and what the next run beside it makes of it.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from enkf.app import rundir
from enkf.app.cli import main
from enkf.app.rundir import atomic_dir, remove_stale_partials

EX = Path(__file__).parents[1] / "examples"
RUN = {"run.json": '{"command": "x"}', "estimates.csv": "time\n1\n", "figures/a.png": "png"}

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")


def write_run(d: Path, tag: str) -> None:
    for name, text in RUN.items():
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_text(f"{tag}:{text}")


def which_run(d: Path) -> str | None:
    """'old' or 'new' when ``d`` holds that run whole; None when it is missing; fails on a
    half or mixed run."""
    if not d.exists():
        return None
    tags = {(d / n).read_text().split(":")[0] if (d / n).exists() else "missing" for n in RUN}
    files = sorted(str(p.relative_to(d)) for p in d.rglob("*") if p.is_file())
    assert len(tags) == 1 and tags != {"missing"} and files == sorted(RUN), (tags, files)
    return tags.pop()


def replace_killed_at(parent: Path, k: int, exchange: bool) -> int:
    """Replace ``parent/out`` (old) by a new run in a child killed at its k-th step; returns
    the child's status (0: it finished before step k)."""
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        try:
            n = [0]

            def step(fn):
                def wrapped(*a, **kw):
                    n[0] += 1
                    if n[0] == k:
                        os.kill(os.getpid(), signal.SIGKILL)
                    return fn(*a, **kw)
                return wrapped

            rundir.os.rename = step(os.rename)
            rundir.shutil.rmtree = step(shutil.rmtree)
            rundir._exchange = step(rundir._exchange if exchange else lambda a, b: False)
            with atomic_dir(parent / "out", force=True) as tmp:
                write_run(tmp, "new")
                step(lambda: None)()  # killed half way through writing
            os._exit(0)
        except BaseException:  # noqa: BLE001 - a child reports by its status only
            os._exit(3)
    _, status = os.waitpid(pid, 0)
    return status


@pytest.mark.parametrize("exchange", [True, False], ids=["swap", "two-renames"])
def test_a_replacement_killed_at_any_step_leaves_a_whole_run(tmp_path, exchange):
    seen = set()
    for k in range(1, 30):
        parent = tmp_path / f"k{k}"
        (parent / "out").mkdir(parents=True)
        write_run(parent / "out", "old")
        status = replace_killed_at(parent, k, exchange)
        if status == 0:
            assert which_run(parent / "out") == "new"
            assert [p.name for p in parent.iterdir()] == ["out"]
            break
        assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, status
        now = which_run(parent / "out")
        if exchange:  # the swap: never a moment without --out
            assert now in ("old", "new")
        # the next run beside it: the stale directories go, a complete one is never lost
        complete = [p for p in parent.iterdir() if p.name.endswith(".done")
                    and p.name.split(".")[-2] == str(p.stat().st_ino)]
        with warnings.catch_warnings(record=True) as rec:
            warnings.simplefilter("always")
            remove_stale_partials(parent)
        assert len(rec) == len(complete), [str(w.message) for w in rec]
        after = which_run(parent / "out")
        assert after in ("old", "new") and (now is None or after == now)
        left = [p for p in parent.iterdir() if p.name != "out"]
        if after == "old" and left:  # killed after the run was complete, before it was placed
            assert len(left) == 1 and left[0].name.endswith(".done")
            assert which_run(left[0]) == "new"
        else:
            assert not left, left
        seen.add(after)
    else:
        pytest.fail("the replacement never finished")
    assert seen == {"old", "new"}  # both sides of the swap were reached


def dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_a_complete_run_of_a_dead_process_is_put_in_place_or_kept(tmp_path):
    pid = dead_pid()
    done = tmp_path / "placeholder"
    done.mkdir()
    write_run(done, "new")
    named = tmp_path / f".out.{pid}.{done.stat().st_ino}.done"
    done.rename(named)
    (tmp_path / "other").mkdir()
    write_run(tmp_path / "other", "old")
    other = tmp_path / f".other.{pid}.{(tmp_path / 'other').stat().st_ino}.done"
    (tmp_path / "other").rename(other)
    (tmp_path / "other").mkdir()  # "other" exists again: its complete run is kept
    write_run(tmp_path / "other", "old")
    with pytest.warns(RuntimeWarning) as rec:
        assert remove_stale_partials(tmp_path) == []
    assert which_run(tmp_path / "out") == "new" and not named.exists()
    assert which_run(other) == "old" and which_run(tmp_path / "other") == "old"
    assert any("is now in place" in str(w.message) for w in rec)
    assert any(str(other) in str(w.message) and "kept" in str(w.message) for w in rec)


def test_a_swapped_out_old_run_of_a_dead_process_is_removed(tmp_path):
    """After the swap the old run sits under the new one's .done name, with another inode."""
    pid = dead_pid()
    old = tmp_path / f".out.{pid}.{(tmp_path).stat().st_ino}.done"  # an inode not its own
    old.mkdir()
    write_run(old, "old")
    (tmp_path / "out").mkdir()
    write_run(tmp_path / "out", "new")
    assert remove_stale_partials(tmp_path) == [old]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_ctrl_c_while_the_old_run_is_removed_keeps_the_new_one(tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    argv = ["mc", str(EX / "tiny.toml"), "--out", str(out), "--photons", "200", "--quiet"]
    assert main(argv) == 0
    first = (out / "run.json").read_text()
    real = shutil.rmtree
    calls = []

    def interrupted_rmtree(path, *a, **kw):
        if str(path).endswith(".old") and not calls:
            calls.append(path)
            (Path(path) / "NA.vtu").unlink()  # half deleted, then Ctrl-C
            raise KeyboardInterrupt
        return real(path, *a, **kw)

    monkeypatch.setattr(rundir.shutil, "rmtree", interrupted_rmtree)
    assert main([*argv, "--force", "--seed", "7"]) == 130
    err = capsys.readouterr().err
    assert f"interrupted: the run had finished: {out} holds it whole" in err
    assert (out / "run.json").read_text() != first and (out / "NA.vtu").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # the rest of the old run removed


@pytest.fixture
def ctrl_c_raises():
    """Ctrl-C raises KeyboardInterrupt, as in a terminal, also where the tests were started
    as a background job (whose SIGINT is ignored)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_a_signal_while_the_run_is_put_in_place_waits_for_it(tmp_path, monkeypatch,
                                                             ctrl_c_raises):
    (tmp_path / "out").mkdir()
    write_run(tmp_path / "out", "old")
    real = rundir._exchange

    def exchange_with_a_signal(a, b):
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C between two steps of the replacement
        return real(a, b)

    monkeypatch.setattr(rundir, "_exchange", exchange_with_a_signal)
    with pytest.raises(KeyboardInterrupt) as info:
        with atomic_dir(tmp_path / "out", force=True) as tmp:
            write_run(tmp, "new")
    assert "holds it whole" in info.value.outcome
    assert which_run(tmp_path / "out") == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_signal_the_process_ignores_stays_ignored():
    """A run started with Ctrl-C ignored (a background job, nohup for SIGHUP) keeps it
    ignored while its output is put in place: nothing is held back or delivered later."""
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with rundir.signals_deferred():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            os.kill(os.getpid(), signal.SIGINT)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
