"""The MCmatlab example gallery (``examples/mcmatlab/``): every script runs and passes its check.

Each ``ex*.py`` and ``test1_*.py`` script there is imported by path and run with
``run(quick=True)``; its ``check(result)`` returns ``{name: entry}``, one entry per
physical number, with ``value`` and either ``expected`` and ``tol`` (|value - expected|
<= tol) or ``min`` and/or ``max``. The script states why its tolerances are what they
are (Monte Carlo numbers: from the photon count). Scripts added later are picked up.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest

GALLERY = Path(__file__).parents[1] / "examples" / "mcmatlab"
SCRIPTS = sorted([*GALLERY.glob("ex*.py"), *GALLERY.glob("test1_*.py")])


def load(path: Path):
    """Import a gallery script by path (it is not part of a package)."""
    spec = importlib.util.spec_from_file_location(f"gallery_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _bound(entry: dict, key: str) -> float | None:
    value = entry.get(key)
    if value is None:
        return None
    value = float(value)
    assert math.isfinite(value), f"{key} = {value} must be finite"
    return value


def assert_entry(name: str, entry: dict) -> None:
    """One check: ``expected`` +- ``tol``, or within [``min``, ``max``]."""
    value = float(entry["value"])
    what = f"{name} ({entry.get('what', '')})"
    assert math.isfinite(value), f"{what}: value {value}"
    if "expected" in entry:
        tol = _bound(entry, "tol")
        assert tol is not None and tol > 0, f"{what}: needs a tolerance > 0, got {tol}"
        expected = _bound(entry, "expected")
        assert abs(value - expected) <= tol, f"{what}: {value!r} not within {tol:g} of {expected!r}"
    else:
        lo, hi = _bound(entry, "min"), _bound(entry, "max")
        assert lo is not None or hi is not None, f"{what}: needs expected/tol or min/max"
        assert lo is None or value >= lo, f"{what}: {value!r} < min {lo!r}"
        assert hi is None or value <= hi, f"{what}: {value!r} > max {hi!r}"


def test_the_gallery_is_there():
    assert len(SCRIPTS) >= 4, [p.name for p in SCRIPTS]


@pytest.mark.parametrize("path", SCRIPTS, ids=[p.stem for p in SCRIPTS])
def test_gallery_script(path):
    module = load(path)
    for name in ("run", "check"):
        assert callable(getattr(module, name, None)), f"{path.name} has no {name}()"
    checks = module.check(module.run(quick=True))
    assert isinstance(checks, dict) and 1 <= len(checks), f"{path.name}: check() returned {checks!r}"
    for name, entry in checks.items():
        assert_entry(name, entry)


@pytest.mark.parametrize("entry, ok", [
    ({"value": 1.0, "expected": 1.0, "tol": 1e-9}, True),
    ({"value": 1.1, "expected": 1.0, "tol": 0.05}, False),
    ({"value": 0.5, "min": 0.1, "max": 2.0}, True),
    ({"value": 3.0, "max": 2.0}, False),
    ({"value": 0.0, "min": 0.1}, False),
    ({"value": 1.0, "expected": 1.0, "tol": 0.0}, False),  # a tolerance that cannot fail
    ({"value": 1.0}, False),  # no expectation at all
])
def test_assert_entry_can_fail(entry, ok):
    if ok:
        assert_entry("x", entry)
    else:
        with pytest.raises(AssertionError):
            assert_entry("x", entry)


def test_ex23_reads_mcmatlabs_tables(tmp_path):
    # Lucifer Yellow from tables in MCmatlab's layout ('#' lines, then nm and a value),
    # interpolated as MCmatlab's interp1 calls: mua = eps / 100 (10 mM), 1e-8 outside and at
    # least 1e-8; ES 0 outside
    module = load(GALLERY / "ex23_broadband_monte_carlo.py")
    (tmp_path / module.ABSORPTION_TABLE).write_text(
        "# absorption\n##Wavelength (nm)\tMolar Extinction (cm-1/M)\n400\t1000\n500\t3000\n")
    (tmp_path / module.EMISSION_TABLE).write_text("# emission\n500\t2\n600\t4\n")
    mua, ES = module.lucifer_yellow(tmp_path)
    assert mua(450.0) == pytest.approx(20.0) and mua(300.0) == 1e-8 and mua(501.0) == 1e-8
    assert ES(550.0) == pytest.approx(3.0) and ES(499.0) == 0.0 and ES(650.0) == 0.0
    medium = module.media(tmp_path)[5]
    assert medium.value("mua", 450.0) == pytest.approx(20.0)
