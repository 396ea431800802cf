"""The emulator's cache: where tables are kept (:func:`default_cache_dir`), their keys, and
files written atomically and read back only when whole (also used for the paper's truth
runs)."""

from __future__ import annotations

import hashlib
import os
import warnings
from pathlib import Path

import numpy as np

from ..files import file_kind, npz_headers
from .spec import EmulatorSpec
from .white import white_supported

__all__ = ["METHODS", "WHITE_VERSION", "cache_key", "default_cache_dir", "entry_problem",
           "load_cached", "load_table", "resolve_method", "store_atomically", "store_table",
           "usable_cache_dir"]

#: build methods of :meth:`AbsorptionEmulator.build`: direct Monte Carlo per table point, or
#: one perturbation ("white") Monte Carlo run per mus column (:mod:`mcmatlab_py.emulator.white`)
#: ("auto": white where the white kernel applies, see :func:`resolve_method`, else table)
METHODS = ("table", "white", "auto")
WHITE_VERSION = 5  #: bumped when the white kernel's numbers change


def default_cache_dir() -> Path:
    """``$TISSUE_ENKF_CACHE``, else ``~/.cache/tissue-enkf``."""
    env = os.environ.get("TISSUE_ENKF_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "tissue-enkf"


def resolve_method(spec: EmulatorSpec, method: str) -> str:
    """The build method for ``spec``: ``method`` itself, or for ``"auto"`` ``"white"``
    where :func:`white_supported` allows it, else ``"table"``."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if method == "auto":
        return "table" if white_supported(spec) else "white"
    return method


def cache_key(spec: EmulatorSpec, method: str = "table") -> str:
    """The cache key of a table: the spec's, and for ``"white"`` the method as well (the
    ``"table"`` key is the spec's own, so the tables cached before methods existed stay);
    ``"auto"`` is first resolved (:func:`resolve_method`)."""
    method = resolve_method(spec, method)
    if method == "table":
        return spec.key()
    text = f"{spec.key()}-{method}-{WHITE_VERSION}"
    return f"{method}-" + hashlib.sha256(text.encode()).hexdigest()[:24]


def _checksum(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def entry_problem(path: Path) -> str | None:
    """Why the cache entry ``path`` cannot be used (``"it is a directory"``), or None when
    it is a regular file or absent (it is then written)."""
    import stat

    try:
        mode = os.stat(path).st_mode  # a FIFO is not opened: that could wait forever
    except FileNotFoundError:
        return None
    except OSError as err:
        return err.strerror or type(err).__name__
    return None if stat.S_ISREG(mode) else f"it is {file_kind(mode)}, not a regular file"


def usable_cache_dir(cache: Path, entry: str | None = None) -> Path:
    """``cache`` if a table can be written there (and its file ``entry``, when given, is a
    regular file or absent); else a temporary folder, removed when this process exits,
    with a warning that says why (the table is then rebuilt by the next run)."""
    import atexit
    import shutil
    import tempfile

    why = None if entry is None else entry_problem(cache / entry)
    if why is not None:
        why = f"the cache entry {str(cache / entry)!r} cannot be used ({why})"
    else:
        try:
            cache.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=cache, prefix=".probe-"):
                pass
            return cache
        except OSError as err:
            why = (f"the cache folder {str(cache)!r} cannot be written "
                   f"({err.strerror or type(err).__name__})")
    tmp = Path(tempfile.mkdtemp(prefix="tissue-enkf-cache-"))
    atexit.register(shutil.rmtree, tmp, True)
    warnings.warn(f"{why}; what would be cached goes to {tmp}, removed when this run ends "
                  "(set TISSUE_ENKF_CACHE or --cache-dir to a writable folder)",
                  RuntimeWarning, stacklevel=3)
    return tmp


def store_atomically(path: Path, what: str = "emulator cache", **arrays) -> bool:
    """Write ``arrays`` to the NPZ file ``path`` atomically (a temporary file beside it,
    renamed over it: a reader never sees half a file, and an interrupted or failed write
    leaves nothing). A write that fails (a full disk, no permission, a directory in its
    place) gives one warning naming the path and returns False: a cache that cannot be
    written never stops a valid run."""
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.npz")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(tmp, **arrays)
        os.replace(tmp, path)
        return True
    except OSError as err:
        warnings.warn(f"the {what} {str(path)!r} cannot be written "
                      f"({err.strerror or type(err).__name__}): the run goes on without it",
                      RuntimeWarning, stacklevel=3)
        return False
    finally:  # interrupted (Ctrl-C, SIGTERM) or failed: no half-written file stays
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass


def load_cached(path: Path, what: str = "cache") -> dict | None:
    """The arrays of the cached NPZ file ``path``, or None when there is none to use: absent,
    not a regular file (left alone, never opened: a FIFO would wait), or unreadable
    (removed: it is computed again). A forged header is refused before anything is
    allocated."""
    if not path.exists() or entry_problem(path) is not None:
        return None
    try:
        npz_headers(path, what)
        with np.load(path, allow_pickle=False) as f:
            return {k: f[k] for k in f.files}
    except Exception:  # noqa: BLE001 - any unreadable file is treated as corrupted
        try:
            path.unlink(missing_ok=True)
        except OSError:
            pass
        return None


def store_table(path: Path, key: str, emu) -> bool:
    """Write the table of ``emu`` (an :class:`~mcmatlab_py.emulator.AbsorptionEmulator`)
    (and which points it holds) atomically; points another process
    added to the file meanwhile are kept. False (after a warning) when it cannot be
    written."""
    on_disk = load_table(path, emu.spec, key, quiet=True)
    if on_disk is not None:
        extra = on_disk["have"] & ~emu.have
        emu.log_na[extra] = on_disk["log_na"][extra]
        emu.absorbed[extra] = on_disk["absorbed"][extra]
        emu.have |= extra
    return store_atomically(path, log_na=emu.log_na, absorbed=emu.absorbed, have=emu.have,
                            build_seconds=emu.build_seconds, key=key,
                            checksum=_checksum(emu.log_na, emu.absorbed, emu.have))


def load_table(path: Path, spec: EmulatorSpec, key: str, quiet: bool = False):
    if not path.exists() or entry_problem(path) is not None:
        return None
    orbits = spec.orbits()[0].size
    try:
        # from the headers: a forged one that declares a huge shape is not allocated
        heads = npz_headers(path, "emulator cache")
        expect = {"log_na": (spec.n_mua, spec.n_mus, orbits), "absorbed": (spec.n_mua, spec.n_mus),
                  "have": (spec.n_mua, spec.n_mus)}
        if any(k in heads and heads[k][0] != shape for k, shape in expect.items()):
            raise ValueError("a table of another shape")
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in ("log_na", "absorbed", "build_seconds", "key", "checksum")}
            if "have" in f:
                data["have"] = f["have"]
                check = _checksum(data["log_na"], data["absorbed"], data["have"])
            else:  # written before on-demand tables: complete
                data["have"] = np.ones((spec.n_mua, spec.n_mus), dtype=bool)
                check = _checksum(data["log_na"], data["absorbed"])
        ok = (str(data["key"]) == key
              and data["log_na"].shape == (spec.n_mua, spec.n_mus, spec.orbits()[0].size)
              and data["have"].shape == (spec.n_mua, spec.n_mus) and data["have"].dtype == bool
              and str(data["checksum"]) == check)
    except Exception:  # noqa: BLE001 - any unreadable file is treated as corrupted
        ok = False
    if not ok:
        if quiet:
            return None
        warnings.warn(f"emulator cache {path} is corrupted or stale: rebuilding", RuntimeWarning,
                      stacklevel=3)
        try:
            path.unlink(missing_ok=True)
        except OSError:  # no permission: the rebuilt table replaces it, or is not stored
            pass
        return None
    return data
