"""The registry of validation studies (``registry.toml``) and the README rendered from it.

``registry.toml`` lists each study: its script ``validation/NAME.py``, the arguments that
made its report (``args``), the quick suite's arguments (``quick``, where it has them),
its report's files in ``validation/reports/`` and what it establishes.
``tissue-enkf validate --full`` reads the same file (``enkf.app.suite``).

    python validation/registry.py            # writes validation/README.md
"""

from __future__ import annotations

import shlex
import tomllib
from pathlib import Path

HERE = Path(__file__).resolve().parent
REGISTRY = HERE / "registry.toml"
README = HERE / "README.md"

#: modules of validation/ that studies import; they write no report of their own
HELPERS = {
    "independent_models.py": "the independent forward models A, B, C and D (A with 10 times "
                             "the photons) of the paper's block (plain numpy and scipy, no "
                             "code shared with the filter's model), and their cached truths",
    "independent_mc.py": "a minimal Monte Carlo of a half-space that shares no code with "
                         "`mcmatlab_py` (the reference of `mc_outputs` at n = 1)",
    "reporting.py": "a report's Markdown with its per-run numbers as JSON beside it",
    "registry.py": "this registry's reader and the renderer of this README",
}


def load(path: Path = REGISTRY) -> list[dict]:
    """The studies of ``registry.toml``, in its order."""
    return tomllib.loads(Path(path).read_text())["study"]


def command(study: dict) -> str:
    """The shell command that regenerates the study's report in ``validation/reports/``."""
    return shlex.join(["python", f"validation/{study['name']}.py", *study["args"]])


def render(studies: list[dict]) -> str:
    """``validation/README.md``."""
    lines = [
        "# Validation studies",
        "",
        "<!-- rendered from registry.toml by `python validation/registry.py`; edit those -->",
        "",
        "Each study is one script, `validation/NAME.py`, that checks one part of the project "
        "against an analytic, published or independent result and writes one report into "
        "`validation/reports/` (a Markdown file whose header states the command that made "
        "it, with its figures beside it where it has them) and, where it has them, its per-run "
        "numbers as JSON into `validation/results/`. "
        "The command under each study regenerates its report; on 2 cores most take from "
        "minutes to a few hours.",
        "",
        "```bash",
        ".venv/bin/tissue-enkf validate --out runs/validation        # quick versions, minutes",
        ".venv/bin/tissue-enkf validate --full --out runs/validation # every study below, hours",
        "```",
        "",
        "`validate` runs the scripts into its run folder (`report.md` collects them) and never "
        "writes into `validation/reports/`; `--full` runs every study with the arguments "
        "below, the quick suite the studies marked *quick*, at small sizes. Both also draw "
        "the paper's sensitivity figure, which has no stored report.",
        "",
        "The targets the identification studies measure against: constant optics, mua within "
        "5% and mus within 25 cm^-1 at 15 s; drifting optics, mua's RMSE over the run <= 0.3 "
        "cm^-1 and mus within 10% at 15 s; the temperature's +-2 sd band holds the truth on "
        ">= 90% of the steps; over many seeds, >= 90% of them (18 of 20) meet each target.",
        "",
    ]
    groups: dict[str, list[dict]] = {}
    for s in studies:
        groups.setdefault(s["group"], []).append(s)
    for group, members in groups.items():
        lines += [f"## {group}", ""]
        for s in members:
            report = ", ".join(f"[{f}](reports/{f})" for f in s["files"])
            quick = " (quick suite: `" + " ".join(s["quick"]) + "`)" if "quick" in s else ""
            results = "".join(f"; numbers: [{f}](results/{f})" for f in s.get("results", []))
            lines += [f"### {s['name']}", "", " ".join(s["establishes"].split()), "",
                      f"`{command(s)}`{quick}", "", f"Report: {report}{results}", ""]
    lines += ["## Helper modules", "",
              *(f"- `{name}`: {text}." for name, text in HELPERS.items()), ""]
    return "\n".join(lines)


if __name__ == "__main__":
    README.write_text(render(load()))
    print(f"written: {README}")
