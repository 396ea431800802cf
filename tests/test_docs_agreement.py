"""The gallery pages' statement of the agreement with MCmatlab's engine is read from the
report that ``validation/mcmatlab_agreement.py compare`` writes: every gallery script is
either in its summary table or named with the reason it was not compared."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))
tissue_docs = pytest.importorskip("tissue_docs", reason="the docs extra (sphinx) is not installed")

REPORT = (ROOT / "validation" / "reports" / "mcmatlab_agreement.md").read_text(encoding="utf-8")


@pytest.mark.parametrize("script", sorted((ROOT / "examples" / "mcmatlab").glob("*.py")),
                         ids=lambda p: p.stem)
def test_every_gallery_example_has_its_agreement(script):
    lines = tissue_docs.agreement_of(script.stem.split("_")[0], REPORT)
    assert lines, f"{script.stem} is neither compared nor named as not compared in the report"
    assert lines[0].startswith(("On ", "Not compared"))


def test_counts_are_read_from_the_summary_row():
    report = ("| ex99 | Example99_Made | 2x2x2 | 1e+03 x (2, 2) | 10 | 7 | 2 | 1 |\n\n"
              "### ex99: Example99_Made\n\nGrid 2x2x2.\n\nWhy two differ.\n\n| stage | number |\n")
    lines = tissue_docs.agreement_of("ex99", report)
    assert "10 numbers" in lines[0] and "**7 agree**" in lines[0] and "1 differ unexplained" in lines[0]
    assert "* Why two differ." in lines
    assert tissue_docs.agreement_of("ex98", report) == []
