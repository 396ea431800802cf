"""``tissue-enkf validate``: run the validation scripts and collect one Markdown report.

Each script of ``validation/`` runs in its own process (as a user would run it) with
its report written into the run directory, never into the source tree; the report
``report.md`` starts with a table of every check, its status and its time, then holds
each script's report and the figures (``figures/``). ``--quick`` (the default) runs small versions in
a few minutes; ``--full`` the published sizes (hours).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["IN_PROCESS", "load_script", "run_suite", "select", "suite", "validation_dir"]

#: the checks that run in this process and have no script: "sensitivity" (a figure)
IN_PROCESS: dict[str, tuple[list, list]] = {"sensitivity": ([], [])}


def suite() -> dict[str, tuple[list | None, list]]:
    """name -> (quick arguments, full arguments); quick None: only in the full suite.

    The studies of ``validation/registry.toml`` as ``validation/registry.py`` reads them
    (``args``: the command that made each report; ``quick``: the quick suite's, where a
    study has them), then ``IN_PROCESS``. "{seed}" in the arguments stands for --seed.
    """
    studies = load_script(validation_dir(), "registry").load()
    return {**{s["name"]: (s.get("quick"), s["args"]) for s in studies}, **IN_PROCESS}


def validation_dir() -> Path:
    """The source tree's ``validation/`` folder; ValueError if this is not a checkout."""
    root = Path(__file__).resolve().parents[2] / "validation"
    if not root.is_dir():
        raise ValueError(f"tissue-enkf validate runs the scripts of the source tree's validation/ "
                         f"folder, not found at {root} (an installed copy has none): run it "
                         "from a git checkout installed with pip install -e .")
    return root


def select(full: bool, only: list[str] | None) -> list[str]:
    """The checks to run; ValueError names a check that is not in the chosen suite."""
    col = 1 if full else 0
    checks = suite()
    names = [n for n, a in checks.items() if a[col] is not None]
    if not only:
        return names
    for n in only:
        if n not in checks:
            raise ValueError(f"--only {n!r}: no such check (choose from {', '.join(checks)})")
        if checks[n][col] is None:
            raise ValueError(f"--only {n!r} runs only with --full (it takes hours)")
    return list(dict.fromkeys(only))


def _demote(markdown: str) -> str:
    """Headings two levels down, so that a script's report sits under its section."""
    out, fence = [], False
    for line in markdown.splitlines():
        fence ^= line.startswith("```")
        out.append("##" + line if line.startswith("#") and not fence else line)
    return "\n".join(out)


def load_script(root: Path, name: str):
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"validation_{name}", root / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _convergence_figure(root: Path, out: Path) -> list[str]:
    """The modal-decay errors of fem_convergence against h, log-log, with fitted slopes."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = np.array(load_script(root, "fem_convergence").modal(), float)
    h = rows[:, 1]
    fig, ax = plt.subplots(figsize=(5, 4), constrained_layout=True)
    for col, label in ((2, "L2"), (3, "max"), (4, "interior max")):
        slope = np.polyfit(np.log(h), np.log(rows[:, col]), 1)[0]
        ax.loglog(h, rows[:, col], "o-", label=f"{label} (slope {slope:.2f})")
    ax.loglog(h, rows[0, 2] * (h / h[0]) ** 2, "k--", lw=0.8, label="h$^2$")
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())  # no crowded labels
    ax.set(xlabel="h [cm]", ylabel="error [K]", title="FEM: modal decay in a box")
    ax.legend(fontsize=8)
    (out / "figures").mkdir(exist_ok=True)
    fig.savefig(out / "figures" / "fem_convergence.png", dpi=110)
    plt.close(fig)
    return ["", "![FEM convergence](figures/fem_convergence.png)"]


def _sensitivity(out: Path, full: bool) -> list[str]:
    from .. import paper

    grid = (100, 100, 50) if full else (40, 40, 20)
    res = paper.sensitivity_study(grid, 10**6 if full else 200_000, progress=False)
    (out / "figures").mkdir(exist_ok=True)
    paper.plot_sensitivity(out / "figures" / "sensitivity.png", res)
    peak_mua = {v: float(np.max(T)) for v, T in res["mua"].items()}
    peak_mus = {v: float(np.max(T)) for v, T in res["mus"].items()}
    lines = [f"The paper's sensitivity study on {grid[0]} x {grid[1]} x {grid[2]} voxels: the "
             "surface temperature rises with mua strongly and with mus weakly, as in the "
             "paper's figure.", "", "| mua | peak T | | mus | peak T |", "|---|---|---|---|---|"]
    for (a, ta), (b, tb) in zip(peak_mua.items(), peak_mus.items(), strict=True):
        lines.append(f"| {a:g} | {ta:.2f} | | {b:g} | {tb:.2f} |")
    return lines + ["", "![sensitivity](figures/sensitivity.png)"]


def run_suite(out: Path, *, full: bool = False, only: list[str] | None = None, seed: int = 0,
              threads: int | None = None, progress: bool = True) -> dict:
    """Run the checks into ``out`` (an existing empty folder); write ``report.md``.

    Returns ``{name: {"status": "ok" | "exit status k" | "error: ...", "seconds": s}}``.
    """
    from mcmatlab_py.progress import Progress

    # the scripts run with ``out`` as their folder: a relative --out would be read from
    # there again and land in out/out/
    out = Path(out).resolve()
    root = validation_dir()
    names = select(full, only)
    checks = suite()
    env = dict(os.environ)
    if threads is not None:
        env["NUMBA_NUM_THREADS"] = str(threads)
    results, sections = {}, []
    bar = Progress(len(names), "validate", enabled=progress, delay=0.0)
    for i, name in enumerate(names):
        bar.update(i, f"({name})")
        t0 = time.perf_counter()
        if name == "sensitivity":
            try:
                body, status = _sensitivity(out, full), "ok"
            except Exception as err:  # noqa: BLE001 - a failed check is reported, not raised
                body, status = [f"error: {err}"], f"error: {type(err).__name__}"
        else:
            report = out / f"{name}.md"
            extra = [a.replace("{seed}", str(seed)) for a in checks[name][1 if full else 0]]
            cmd = [sys.executable, str(root / f"{name}.py"), *extra, "--out", str(report)]
            res = subprocess.run(cmd, capture_output=True, text=True, cwd=str(out), env=env)
            status = "ok" if res.returncode == 0 else f"exit status {res.returncode}"
            if report.exists() and res.returncode == 0:
                body = [_demote(report.read_text())]
                if name == "fem_convergence":
                    body += _convergence_figure(root, out)
            else:
                body = ["```", (res.stdout + res.stderr).strip()[-3000:], "```"]
        results[name] = {"status": status, "seconds": time.perf_counter() - t0}
        sections += [f"## {name} ({status}, {results[name]['seconds']:.0f} s)", "", *body, ""]
    bar.update(len(names))
    bar.close()
    kind = "Full" if full else "Quick"
    lines = ["# tissue-enkf validation report", "",
             f"{kind} suite, run by `tissue-enkf validate{' --full' if full else ''}` "
             f"(seed {seed}). Each section below is the report of one script of "
             "`validation/` (run it alone with `python validation/NAME.py`; its first lines "
             "say what it checks against).", "", "| check | status | time (s) |", "|---|---|---|"]
    lines += [f"| {n} | {r['status']} | {r['seconds']:.1f} |" for n, r in results.items()]
    (out / "report.md").write_text("\n".join(lines + [""] + sections) + "\n")
    return results
