"""Sphinx helpers of the tissue-enkf site: the gallery's coverage and quick runs, the studies.

* Every script in ``examples/mcmatlab/`` must have its page ``docs/gallery/<stem>.md``
  and every such page its script: a missing one is a warning, so ``sphinx-build -W``
  fails on it.
* Every gallery script runs with ``--quick`` when the site is built (its figures into
  ``docs/_quick/<stem>/``, rerun only when the script changed), and ``{quick-figures}
  <stem>`` shows them on the example's page: the page is made from the script itself,
  beside the stored full-size figures. A script that fails is a warning. Environment
  ``TISSUE_DOCS_QUICK=0`` skips the runs (the pages then say so).
* ``{validation-studies}`` lists the studies of ``validation/`` from its registry
  (``validation/registry.toml``: group, what each establishes, its arguments, its report
  files, which are copied into the site as downloads); without a registry, each script
  with a report in ``validation/reports/`` and the first sentence of its docstring.
  Nothing is run.
* ``{mcmatlab-agreement} <stem>`` states, on an example's page, how its numbers compare
  with MCmatlab's own engine: the example's row and explanations in
  ``validation/reports/mcmatlab_agreement.md`` (written by
  ``validation/mcmatlab_agreement.py compare``). Nothing is run.
"""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
import tomllib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.application import Sphinx
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

logger = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples" / "mcmatlab"
VALIDATION = ROOT / "validation"


def gallery_scripts() -> list[Path]:
    """The gallery's scripts, as ``tests/test_gallery.py`` finds them."""
    return sorted([*EXAMPLES.glob("ex*.py"), *EXAMPLES.glob("test1_*.py")])


def check_gallery(app: Sphinx) -> None:
    pages = {p.stem for p in (Path(app.srcdir) / "gallery").glob("*.md")}
    scripts = {p.stem for p in gallery_scripts()}
    for stem in sorted(scripts - pages):
        logger.warning("examples/mcmatlab/%s.py has no gallery page docs/gallery/%s.md", stem, stem)
    for stem in sorted(pages - scripts):
        logger.warning("docs/gallery/%s.md names no script in examples/mcmatlab/", stem)


def _quick_dir(app: Sphinx) -> Path:
    return Path(app.srcdir) / "_quick"


def run_quick(app: Sphinx) -> None:
    """Run every gallery script with ``--quick`` into ``_quick/<stem>/`` (2 at a time)."""
    if os.environ.get("TISSUE_DOCS_QUICK", "1") == "0":
        return
    todo = []
    for script in gallery_scripts():
        out = _quick_dir(app) / script.stem
        stamp = out / ".made"
        if stamp.exists() and stamp.stat().st_mtime >= script.stat().st_mtime:
            continue
        todo.append((script, out, stamp))

    def one(item):
        script, out, stamp = item
        out.mkdir(parents=True, exist_ok=True)
        for old in out.glob("*.png"):
            old.unlink()
        env = dict(os.environ, MPLBACKEND="Agg")
        r = subprocess.run([sys.executable, str(script), "--quick", "--out", str(out)],
                           cwd=out, env=env, capture_output=True, text=True)
        if r.returncode == 0:
            stamp.write_text(r.stdout)
        return script, r

    with ThreadPoolExecutor(max_workers=2) as pool:
        for script, r in pool.map(one, todo):
            if r.returncode != 0:
                logger.warning("examples/mcmatlab/%s --quick failed (exit %d): %s", script.name,
                               r.returncode, r.stderr.strip().splitlines()[-1:] or "")


class QuickFigures(SphinxDirective):
    """The figures of ``examples/mcmatlab/<stem>.py --quick``, made when the site is built,
    with what the script printed."""

    required_arguments = 1
    has_content = False

    def run(self) -> list[nodes.Node]:
        stem = self.arguments[0]
        script = EXAMPLES / f"{stem}.py"
        if not script.exists():
            logger.warning("quick-figures: no script examples/mcmatlab/%s.py", stem,
                           location=self.get_location())
            return []
        self.env.note_dependency(str(script))
        out = _quick_dir(self.env.app) / stem
        stamp = out / ".made"
        if not stamp.exists():
            return [nodes.paragraph(text=f"(The quick run of {stem}.py is made when the site is "
                                         "built; this build skipped it.)")]
        lines = [f"Made by this build: `python examples/mcmatlab/{stem}.py --quick` "
                 "(small grid, few photons), which printed:", "", "```text",
                 *[ln for ln in stamp.read_text().strip().splitlines()
                   if not ln.startswith("figures in ")], "```", ""]
        for png in sorted(out.glob("*.png")):
            lines += [f"```{{image}} /_quick/{stem}/{png.name}", f":alt: {png.stem}",
                      ":width: 48%", "```", ""]
        container = nodes.container()
        self.state.nested_parse(StringList(lines, source=str(script)), self.content_offset,
                                container)
        return container.children


def _first_sentence(path: Path) -> str:
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    para = " ".join(doc.split("\n\n")[0].split())
    return re.sub(r"\s*\(issues? #?\d+[^)]*\)", "", para)


def _studies() -> list[dict]:
    """The studies: from ``validation/registry.toml`` where it exists, else every script
    of ``validation/`` with a report in ``validation/reports/``."""
    registry = VALIDATION / "registry.toml"
    if registry.exists():
        with registry.open("rb") as f:
            return tomllib.load(f)["study"]
    reports = VALIDATION / "reports"
    out = []
    for script in sorted(VALIDATION.glob("*.py")):
        found = [p.name for p in [*sorted(reports.glob(f"{script.stem}.md")),
                                  *sorted(reports.glob(f"{script.stem}_*.md"))]]
        if found:  # else a helper module (reference models, report writing), not a study
            out.append({"name": script.stem, "group": "Studies", "args": [], "files": found,
                        "establishes": _first_sentence(script)})
    return out


class ValidationStudies(SphinxDirective):
    """The validation studies by group: what each establishes, its command, its report
    (copied into the site as a download). Read when the site is built; nothing is run."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        here = Path(self.env.doc2path(self.env.docname)).parent
        reports = VALIDATION / "reports"
        if (VALIDATION / "registry.toml").exists():
            self.env.note_dependency(str(VALIDATION / "registry.toml"))
        lines: list[str] = []
        group = None
        for study in _studies():
            if study.get("group") != group:
                group = study.get("group")
                lines += [f"```{{rubric}} {group}", "```", ""]
            script = VALIDATION / f"{study['name']}.py"
            self.env.note_dependency(str(script))
            command = " ".join(["python", f"validation/{script.name}", *study.get("args", [])])
            links = ", ".join(
                f"{{download}}`{name} <{os.path.relpath(reports / name, here)}>`"
                for name in study.get("files", []) if (reports / name).exists())
            what = " ".join(str(study.get("establishes", "")).split())
            lines += [f"`{study['name']}`", f": {what}", "",
                      f"  `{command}`" + (f"; report: {links}" if links else ""), ""]
        if not lines:
            return [nodes.paragraph(text="No study with a report in validation/reports/.")]
        container = nodes.container()
        self.state.nested_parse(StringList(lines, source="validation/"), self.content_offset, container)
        return container.children


AGREEMENT = VALIDATION / "reports" / "mcmatlab_agreement.md"


def agreement_rows(report: str) -> dict[str, list[str]]:
    """The summary table of the agreement report: example key -> its eight cells."""
    rows = {}
    for line in report.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 8 and re.fullmatch(r"(ex\d+|test\d+)", cells[0]):
            rows[cells[0]] = cells
    return rows


def agreement_of(key: str, report: str) -> list[str]:
    """The lines (MyST) that say how example ``key`` (``ex04``, ``test1``) compares with
    MCmatlab's engine in the report's text ``report``: its counts and its explanations,
    or why it was not compared; ``[]`` when the report does not name it."""
    rows = agreement_rows(report)
    if key in rows:
        _, script, grid, photons, n, agree, explained, differ = rows[key]
        lines = [f"On {grid} voxels, {photons} photons per call and batches (MCmatlab's, "
                 f"ours), {n} numbers of `{script}.m` compared: **{agree} agree** within 3 "
                 f"combined standard errors, {explained} differ for a reason the report "
                 f"measures, {differ} differ unexplained.", ""]
        section = re.search(rf"^### {key}: .*?$(.*?)(?=^\| stage |^### |\Z)", report,
                            flags=re.M | re.S)
        if section:
            paragraphs = [" ".join(p.split()) for p in section.group(1).split("\n\n")]
            lines += [f"* {p}" for p in paragraphs if p and not p.startswith("Grid ")] + [""]
        return lines
    skipped = re.search(rf"\b{key} \((.*?)\)(?:; |\s*$)", report, flags=re.M)
    if skipped:
        return [f"Not compared with MCmatlab's engine: {skipped.group(1)}", ""]
    return []


class MCmatlabAgreement(SphinxDirective):
    """How one gallery example's numbers compare with MCmatlab's engine, from the report of
    ``validation/mcmatlab_agreement.py`` (read when the site is built; nothing is run)."""

    required_arguments = 1
    has_content = False

    def run(self) -> list[nodes.Node]:
        key = self.arguments[0].split("_")[0]
        if not AGREEMENT.exists():
            return [nodes.paragraph(text="(No report validation/reports/mcmatlab_agreement.md.)")]
        self.env.note_dependency(str(AGREEMENT))
        lines = agreement_of(key, AGREEMENT.read_text(encoding="utf-8"))
        if not lines:
            logger.warning("mcmatlab-agreement: %s is not in %s", key, AGREEMENT.name,
                           location=self.get_location())
            return []
        here = Path(self.env.doc2path(self.env.docname)).parent
        lines += [f"The numbers, stage by stage: {{download}}`mcmatlab_agreement.md "
                  f"<{os.path.relpath(AGREEMENT, here)}>` (section {key}); how they were made: "
                  "[Agreement with MCmatlab's engine](../agreement.md).", ""]
        container = nodes.container()
        self.state.nested_parse(StringList(lines, source=str(AGREEMENT)), self.content_offset,
                                container)
        return container.children


class MCmatlabAgreementTable(SphinxDirective):
    """Every gallery example's agreement with MCmatlab's engine in one table, each row
    linked to its page (from the report; nothing is run)."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        if not AGREEMENT.exists():
            return [nodes.paragraph(text="(No report validation/reports/mcmatlab_agreement.md.)")]
        self.env.note_dependency(str(AGREEMENT))
        rows = agreement_rows(AGREEMENT.read_text(encoding="utf-8"))
        lines = ["| example | numbers | agree | explained | differ |", "|---|---:|---:|---:|---:|"]
        for script in gallery_scripts():
            key = script.stem.split("_")[0]
            link = f"[{script.stem}](gallery/{script.stem}.md)"
            if key in rows:
                n, agree, explained, differ = rows[key][4:]
                lines.append(f"| {link} | {n} | {agree} | {explained} | {differ} |")
            else:
                lines.append(f"| {link} | not compared (see its page) | | | |")
        container = nodes.container()
        self.state.nested_parse(StringList(lines + [""], source=str(AGREEMENT)),
                                self.content_offset, container)
        return container.children


def setup(app: Sphinx) -> dict:
    app.connect("builder-inited", check_gallery)
    app.connect("builder-inited", run_quick)
    app.add_directive("validation-studies", ValidationStudies)
    app.add_directive("quick-figures", QuickFigures)
    app.add_directive("mcmatlab-agreement", MCmatlabAgreement)
    app.add_directive("mcmatlab-agreement-table", MCmatlabAgreementTable)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
