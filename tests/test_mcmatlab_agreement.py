"""The gallery against MCmatlab's own engine, number for number (``validation/mcmatlab_agreement.py``).

``validation/data/mcmatlab/<example>.json`` holds MCmatlab's numbers for each example of the
gallery, run by GNU Octave with MCmatlab's C engines on a reduced model (the grid and photon
count stored with them): the mean and standard error over independent batches of each
number the study compares (absorbed power per medium and depth slab, escape per face, the
fluence rate over blocks of the cuboid, far field, light collector, fluorescence). Here one
batch of ours, with a quarter of the photons, is held against them.

Tolerance: 5 combined standard errors, ours scaled from MCmatlab's by the photon count (the
per-packet variance is the same where the two engines agree). Five, not three: about 700
numbers are checked, and MCmatlab's standard errors come from 20 batches (Student's t with 19
degrees of freedom puts 8e-5 of each number beyond 5, about 0.06 failures in all by chance).
Heat runs are left to the study (their solvers differ in discretisation; the report measures
it); the Monte Carlo stages of the heat examples are checked. Numbers the report explains
(MCmatlab's conventions, measured there) are left out.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "validation"))

import mcmatlab_agreement as ma  # noqa: E402

CASES = [c for c in ma.CASES.values() if (ma.DATA / f"{c.name}.json").exists()]


def test_the_references_are_there():
    """Every example of the gallery is compared, or the study says why not."""
    assert len(CASES) >= 24, [c.name for c in CASES]
    gallery = {p.stem.split("_")[0] for p in ma.GALLERY.glob("*.py")}
    assert gallery <= set(ma.CASES) | set(ma.NOT_COMPARED), gallery - set(ma.CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_ours_agrees_with_mcmatlab(case):
    try:
        case.run_kw()
    except KeyError:
        pytest.skip(f"{case.name} reads files from MCmatlab's folder: set MCM_ROOT")
    rows = ma.ci_check(case, z=5.0, heat=False)
    assert rows, f"{case.name}: nothing compared"
    bad = [f"{name}: ours {ours:.6g}, MCmatlab {ref:.6g}, tolerance {tol:.3g}"
           for name, ours, ref, tol in rows if not abs(ours - ref) <= tol]
    assert not bad, f"{case.name}:\n" + "\n".join(bad)


def test_a_difference_is_caught():
    """A reference moved by 2% of the absorbed power fails the check of Example 1."""
    import copy
    import json

    case = ma.CASES["ex01"]
    ref = json.loads((ma.DATA / "ex01.json").read_text())
    moved = copy.deepcopy(ref)
    moved["stages"][0]["numbers"]["absorbed"]["mean"] *= 1.02
    rows = {name: (ours, r, tol) for name, ours, r, tol in ma.ci_check(case, ref=moved)}
    ours, r, tol = rows["stage 1: absorbed"]
    assert abs(ours - r) > tol


def test_a_fresh_run_explains_chance_but_not_a_recurring_difference():
    """``confirm``'s fresh run: a light number beyond 3 SE whose fresh run agrees is chance;
    one that differs again, or a heat number, stays a difference; agreeing numbers stay so."""
    case = ma.Case("t", "t", "T", (2, 2, 2), 10)

    def stages(kind, **numbers):
        return [{"kind": kind, "numbers": {k: {"mean": m, "se": 0.01} for k, m in
                                           numbers.items()}}]

    ref = stages("MC", a=1.0, b=1.0, c=1.0)
    ours = stages("MC", a=1.1, b=1.1, c=1.0)  # a and b 7 SE off, c agrees
    fresh = {"mcmatlab": stages("MC", a=1.0, b=1.0, c=1.0),
             "ours": stages("MC", a=1.01, b=1.2, c=1.0)}  # a agrees now, b does not
    rows = {r["name"]: r for r in ma.compare(ref, ours, case, fresh)}
    assert rows["a"]["verdict"] == "explained (chance)"
    assert abs(rows["a"]["z_fresh"] - 0.01 / (0.01 * 2 ** 0.5)) < 1e-9
    assert rows["b"]["verdict"] == "DIFFER" and rows["b"]["z_fresh"] > 3
    assert rows["c"]["verdict"] == "agree" and "z_fresh" not in rows["c"]
    assert [r["verdict"] for r in ma.compare(ref, ours, case)] == ["DIFFER", "DIFFER", "agree"]
    heat = ma.compare(stages("HS", **{"sensor 1 rise": 1.0}), stages("HS", **{"sensor 1 rise": 1.5}),
                      case, {"mcmatlab": stages("HS", **{"sensor 1 rise": 1.0}),
                             "ours": stages("HS", **{"sensor 1 rise": 1.0})})
    assert heat[0]["verdict"] == "DIFFER"
