"""Run directories that appear whole or not at all.

A run writes into a hidden sibling ``.NAME.PID.partial`` and renames it to ``NAME`` only
when everything is written. An interrupted run (Ctrl-C, SIGTERM) removes its partial
directory itself; one killed outright (SIGKILL, power loss) leaves it behind, hidden and
named after its process, and the next run beside it removes every partial directory
whose process is gone (:func:`remove_stale_partials`).
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
from pathlib import Path

from ..tissue.outputs import write_json

__all__ = ["atomic_dir", "check_out_dir", "remove_stale_partials", "write_json"]

_PARTIAL = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.partial$")


def check_out_dir(out: str | Path, force: bool, whole: bool = True) -> Path:
    """Refuse an existing non-empty ``out`` unless ``force``; ValueError names it.

    With ``force`` the working directory, its parents and the home directory are refused,
    and, when the whole directory is to be replaced (``whole``), one that holds no
    ``run.json`` (no output of ours)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {str(out)!r} exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            raise ValueError(f"--out {str(out)!r} exists and is not empty (use --force to "
                             "replace it)")
        here = Path.cwd().resolve()
        target = out.resolve()
        if target == here or target in here.parents or target == Path.home().resolve():
            raise ValueError(f"--out {str(out)!r} is the working directory, one of its parents "
                             "or the home directory: --force will not replace it")
        if whole and not (out / "run.json").exists():
            raise ValueError(f"--out {str(out)!r} holds no run.json, so it is no output of "
                             "tissue-enkf: --force replaces only those (choose another --out)")
    return out


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True


def remove_stale_partials(parent: str | Path) -> list[Path]:
    """Remove the ``.NAME.PID.partial`` directories in ``parent`` whose process is gone;
    the removed paths are returned."""
    parent = Path(parent)
    removed = []
    if not parent.is_dir():
        return removed
    for p in parent.iterdir():
        m = _PARTIAL.match(p.name)
        if m and p.is_dir() and int(m["pid"]) != os.getpid() and not _alive(int(m["pid"])):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_dir(out: str | Path, force: bool = False):
    """Yield a hidden partial directory beside ``out``; move it into place only on success.

    An interrupted or failed run leaves ``out`` as it was (nothing half-written). The
    directory gets the permissions of the umask, as ``mkdir`` would give it.
    """
    out = check_out_dir(out, force)
    out.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_partials(out.parent)
    tmp = out.parent / f".{out.name}.{os.getpid()}.partial"
    shutil.rmtree(tmp, ignore_errors=True)  # our own pid's leftover (a reused pid)
    tmp.mkdir(mode=0o777 & ~_umask())
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if out.exists():
        shutil.rmtree(out)
    tmp.rename(out)
