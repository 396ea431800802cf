"""Run directories that appear whole or not at all, and replace an old run atomically.

A run writes into a hidden sibling ``.NAME.PID.partial``. When everything is written it
is renamed ``.NAME.PID.INO.done`` (complete; ``INO`` is the directory's own inode
number) and then put in place:

- no ``NAME`` yet: renamed to ``NAME``;
- ``--force`` over an old run: swapped with ``NAME`` in one step (Linux's
  ``renameat2(RENAME_EXCHANGE)``), so that ``NAME`` is at every moment the old whole
  run or the new whole run; the old one, now under the ``.done`` name, is renamed
  ``.NAME.PID.old`` and removed last. Where the swap is not available (another
  system, a file system without it), ``NAME`` is renamed ``.NAME.PID.old`` and the new
  run renamed to ``NAME``: two renames, between which only a power cut or SIGKILL can
  come (Ctrl-C and the terminating signals wait for the second).

An interrupted run (Ctrl-C, SIGTERM, SIGHUP, SIGQUIT) removes its partial directory
itself. A process killed outright (SIGKILL, power loss) leaves hidden directories named
after it; the next run beside them (:func:`remove_stale_partials`) removes its
``.partial`` (unfinished) and ``.old`` directories, puts a ``.done`` run in place when
``NAME`` is missing, and keeps it (with a warning) when ``NAME`` holds another run: a
complete run is never deleted. A ``.done`` directory whose inode is not the one in its
name is the old run that a swap moved there: it is removed.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import signal
import sys
import threading
import warnings
from pathlib import Path

from ..tissue.outputs import write_json

__all__ = ["atomic_dir", "check_out_dir", "remove_stale_partials", "signals_deferred", "write_json"]

_HIDDEN = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.(?:(?P<ino>\d+)\.done|partial|old)$")
#: the signals that would end a run; they wait while a finished run is put in place
_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
                 if hasattr(signal, n))


def check_out_dir(out: str | Path, force: bool, whole: bool = True) -> Path:
    """Refuse an existing non-empty ``out`` unless ``force``; ValueError names it.

    With ``force`` the working directory, its parents and the home directory are refused,
    and, when the whole directory is to be replaced (``whole``), one that holds no
    ``run.json`` (no output of ours). Nothing is changed on disk."""
    out = Path(out)
    if (out.exists() or out.is_symlink()) and not out.is_dir():
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
    """Clean up after the processes that were killed beside ``parent``'s runs.

    For each hidden ``.NAME.PID.*`` directory whose process is gone: an unfinished
    ``.partial`` and a replaced ``.old`` run are removed; a complete ``.done`` run is put
    in place as ``NAME`` when there is none, and otherwise kept, with a warning that
    names it. Returns the paths removed."""
    parent = Path(parent)
    removed = []
    if not parent.is_dir():
        return removed
    for p in sorted(parent.iterdir()):
        m = _HIDDEN.match(p.name)
        if not m or not p.is_dir() or p.is_symlink():
            continue
        pid = int(m["pid"])
        if pid == os.getpid() or _alive(pid):
            continue
        if m["ino"] is not None and p.stat().st_ino == int(m["ino"]):
            target = parent / m["name"]
            if not (target.exists() or target.is_symlink()):
                os.rename(p, target)  # its process was killed between two renames
                warnings.warn(f"{target}: the complete run of process {pid} (killed while it "
                              "was put in place) is now in place", RuntimeWarning, stacklevel=2)
            else:
                warnings.warn(f"{p} holds the complete run of process {pid}, killed before it "
                              f"replaced {target}: kept (rename it to use it, or delete it)",
                              RuntimeWarning, stacklevel=2)
            continue
        shutil.rmtree(p, ignore_errors=True)
        removed.append(p)
    return removed


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _exchange(a: Path, b: Path) -> bool:
    """Swap the paths ``a`` and ``b`` atomically (Linux ``renameat2(RENAME_EXCHANGE)``);
    False where this system or file system cannot."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):  # a C library older than glibc 2.28
        return False
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


@contextlib.contextmanager
def signals_deferred():
    """Hold back Ctrl-C and the terminating signals inside the block; one that came is
    delivered on leaving it (its handler then raises there)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got = []
    old = {}
    try:
        for s in _SIGNALS:
            if signal.getsignal(s) is signal.SIG_IGN:
                continue  # ignored by the process (nohup, a background job): stays so
            old[s] = signal.signal(s, lambda signum, frame: got.append(signum))
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
    if got:
        signal.raise_signal(got[0])


def _put_in_place(tmp: Path, out: Path) -> Path | None:
    """Move the finished ``tmp`` to ``out``; returns the old run's path (to remove) or None."""
    done = tmp.parent / f".{out.name}.{os.getpid()}.{tmp.stat().st_ino}.done"
    os.rename(tmp, done)  # complete from here on: no later run deletes it
    if not (out.exists() or out.is_symlink()):
        os.rename(done, out)
        return None
    old = tmp.parent / f".{out.name}.{os.getpid()}.old"
    if _exchange(done, out):
        os.rename(done, old)  # the old run, under the name of the new one since the swap
    else:
        os.rename(out, old)
        os.rename(done, out)
    return old


@contextlib.contextmanager
def atomic_dir(out: str | Path, force: bool = False):
    """Yield a hidden partial directory beside ``out``; move it into place only on success.

    An interrupted or failed run leaves ``out`` as it was (nothing half-written); a
    successful one replaces it atomically (see the module's notes), the old run being
    removed last. The directory gets the permissions of the umask, as ``mkdir`` would
    give it. A signal that comes while the finished run is put in place is handled once
    it is there; the exception then carries ``outcome``, which says so.
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
    old, placed = None, False
    try:
        with signals_deferred():
            old = _put_in_place(tmp, out)
            placed = True
        _remove(old)
    except BaseException as exc:
        if placed:
            exc.outcome = f"the run had finished: {out} holds it whole"
            _remove(old)  # a second signal here leaves it hidden: the next run removes it
        raise


def _remove(old: Path | None) -> None:
    if old is not None and old.is_symlink():  # --out was a link: the link goes, not what
        old.unlink()  # it pointed to
    elif old is not None:
        shutil.rmtree(old, ignore_errors=True)
