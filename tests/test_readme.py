"""README.md: its shape, and every command and code block in it run as pasted.

The tour's commands run in a scratch folder holding a copy of ``examples/``, with
``.venv/bin/`` standing for the environment that runs the tests.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, re.S)


def _commands(block: str) -> list[str]:
    """The block's command lines, without trailing comments."""
    out = []
    for line in block.splitlines():
        line = re.sub(r"\s+#.*$", "", line).strip()
        if line and not line.startswith("#"):
            out.append(line)
    return out


def test_readme_opens_with_two_commands():
    lines = README.splitlines()
    assert len(lines) <= 150, f"README.md has {len(lines)} lines, the limit is 150"
    first = _blocks("bash")[0]
    assert README.index("```bash") < README.index("\n## "), "the commands come first"
    setup, tests = _commands(first)
    assert setup.startswith("python3 -m venv .venv && ") and "tissue-enkf" in setup
    assert tests.startswith("python3 -m venv .venv && ") and "pytest" in tests
    # the main job installs the project alone, without the test and viewer extras
    assert '.venv/bin/pip install -e . ' in setup


def test_readme_links_exist():
    for path in sorted(set(re.findall(r"`((?:docs|validation|examples|benchmarks)/[\w./-]+)`",
                                      README))):
        assert (ROOT / path).exists(), f"README.md names {path}, which does not exist"


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    d = tmp_path_factory.mktemp("readme")
    shutil.copytree(ROOT / "examples", d / "examples")
    return d


def _run(line: str, cwd: Path) -> None:
    bindir = Path(sys.executable).parent
    line = re.sub(r"(^|\s)\.venv/bin/", lambda m: f"{m.group(1)}{bindir}/", line)
    r = subprocess.run(line, shell=True, cwd=cwd, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, f"{line}\nexit {r.returncode}\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}"


@pytest.mark.slow
@pytest.mark.parametrize("line", _commands(_blocks("bash")[1]))
def test_readme_tour_command(line, scratch):
    _run(line, scratch)


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(_blocks("python"))))
def test_readme_python_block(index, scratch):
    script = scratch / f"block{index}.py"
    script.write_text(_blocks("python")[index])
    _run(f"{sys.executable} {script}", scratch)
