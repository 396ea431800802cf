"""What every study writes: its Markdown report and the per-run numbers as JSON.

Reports live in ``validation/reports/``; the numbers they were written from in
``validation/results/`` under the report's name (:func:`results_path`).
"""

from __future__ import annotations

import json
from pathlib import Path


def results_path(report: Path) -> Path:
    """Where a report's per-run numbers go: ``validation/results/NAME.json`` for a report in
    ``validation/reports/``, else ``NAME.json`` beside the report."""
    report = Path(report)
    if report.resolve().parent.name == "reports":
        folder = report.resolve().parent.parent / "results"
        folder.mkdir(exist_ok=True)
        return folder / f"{report.stem}.json"
    return report.with_suffix(".json")


def write_results(report: Path, rows) -> Path:
    """``rows`` as JSON at :func:`results_path` of ``report``; returns that path."""
    path = results_path(report)
    path.write_text(json.dumps(rows, indent=1))
    return path


def results_note(report: Path) -> str:
    """The report's line that says where its per-run numbers are."""
    path = results_path(report)
    where = (f"validation/results/{path.name}" if path.parent.name == "results" else path.name)
    return f"Per-run numbers: `{where}`."


def write_report(path: Path, lines: list, rows: list) -> None:
    """``lines`` into ``path`` (Markdown) with a pointer to ``rows``, written as JSON at
    :func:`results_path`."""
    path = Path(path)
    lines = [*lines, "", results_note(path)]
    path.write_text("\n".join(lines) + "\n")
    write_results(path, rows)
