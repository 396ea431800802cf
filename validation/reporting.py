"""What every study writes: its Markdown report and, beside it, the per-run numbers as JSON."""

from __future__ import annotations

import json
from pathlib import Path


def write_report(path: Path, lines: list, rows: list) -> None:
    """``lines`` into ``path`` (Markdown) with a pointer to ``rows``, written as the JSON
    file of the same name beside it."""
    path = Path(path)
    lines = [*lines, "", f"Per-run numbers: `validation/reports/{path.with_suffix('.json').name}`."]
    path.write_text("\n".join(lines) + "\n")
    path.with_suffix(".json").write_text(json.dumps(rows, indent=1))
