"""validation/registry.toml against the scripts, the reports, the README and `validate`.

Fast: reads files, runs no study.
"""

from __future__ import annotations

import re
import shlex

import pytest

from enkf.app.suite import IN_PROCESS, load_script, select, suite, validation_dir

ROOT = validation_dir()
REG = load_script(ROOT, "registry")
STUDIES = REG.load()


def test_every_entry_names_an_existing_script_once():
    names = [s["name"] for s in STUDIES]
    assert len(names) == len(set(names))
    for s in STUDIES:
        assert (ROOT / f"{s['name']}.py").is_file(), s["name"]
        assert s["establishes"].strip() and s["group"].strip(), s["name"]
        assert all(isinstance(a, str) for a in s["args"] + s.get("quick", [])), s["name"]


def test_every_script_is_a_study_or_a_helper():
    scripts = {p.name for p in ROOT.glob("*.py")}
    studies = {f"{s['name']}.py" for s in STUDIES}
    assert scripts - studies == set(REG.HELPERS)
    assert not studies & set(REG.HELPERS)


def test_every_report_file_belongs_to_one_entry():
    listed = [f for s in STUDIES for f in s["files"]]
    assert len(listed) == len(set(listed))
    on_disk = {p.name for p in (ROOT / "reports").iterdir()}
    assert on_disk == set(listed)
    assert len(on_disk) <= 40
    results = [f for s in STUDIES for f in s.get("results", [])]
    assert len(results) == len(set(results))
    assert {p.name for p in (ROOT / "results").iterdir()} == set(results)
    for s in STUDIES:  # the report at the script's default name comes first
        assert s["files"][0] == f"{s['name']}.md", s["name"]


def _header_commands(text: str) -> list[list[str]]:
    """The command(s) a report's header states, without --out and --cache-dir."""
    head = "\n".join(text.splitlines()[:5])
    m = re.search(r"`(python validation/[^`]*)`", head)
    assert m, "no command in the report's header"
    out = []
    for part in m.group(1).split(";"):
        toks, keep = shlex.split(part), []
        while toks:
            t = toks.pop(0)
            if t in ("--out", "--cache-dir"):
                toks.pop(0)
            else:
                keep.append(t)
        out.append(keep)
    return out


@pytest.mark.parametrize("study", STUDIES, ids=[s["name"] for s in STUDIES])
def test_report_header_states_the_registry_command(study):
    cmds = _header_commands((ROOT / "reports" / study["files"][0]).read_text())
    script = ["python", f"validation/{study['name']}.py"]
    if len(cmds) == 1:
        assert cmds[0] == script + study["args"]
    else:  # a report merged from several runs of the script (drift_bank's --from-json)
        assert all(c[:2] == script for c in cmds)


def test_validate_full_runs_the_registry():
    names = [s["name"] for s in STUDIES]
    assert select(True, None) == names + list(IN_PROCESS)
    checks = suite()
    for s in STUDIES:
        assert checks[s["name"]] == (s.get("quick"), s["args"])
    assert select(False, None) == [s["name"] for s in STUDIES if "quick" in s] + list(IN_PROCESS)


def test_readme_is_rendered_from_the_registry():
    assert (ROOT / "README.md").read_text() == REG.render(STUDIES), (
        "validation/README.md is stale: run python validation/registry.py")
