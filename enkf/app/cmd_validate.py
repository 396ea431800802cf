"""``validate``: the validation suite, into one report."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from .common import EXIT_CHECK_FAILED, apply_threads

__all__ = ["cmd_validate"]

def cmd_validate(args) -> int:
    from .report import manifest
    from .rundir import atomic_dir, check_out_dir
    from .suite import run_suite, select, validation_dir

    check_out_dir(args.out, args.force)
    apply_threads(args.threads)
    validation_dir()
    names = select(args.full, args.only)
    seed = 0 if args.seed is None else args.seed
    t0 = time.perf_counter()
    with atomic_dir(args.out, args.force) as tmp:
        res = run_suite(tmp, full=args.full, only=names, seed=seed, threads=args.threads,
                        progress=not args.quiet)
        manifest(tmp / "run.json", command="validate",
                 config={"full": args.full, "checks": names}, seed=seed,
                 timings={"total": time.perf_counter() - t0,
                          **{n: r["seconds"] for n, r in res.items()}},
                 extra={"status": {n: r["status"] for n, r in res.items()}})
    failed = [n for n, r in res.items() if r["status"] != "ok"]
    print(f"report -> {Path(args.out) / 'report.md'}"
              + (f"; failed: {', '.join(failed)}" if failed else ""), file=sys.stderr)
    return EXIT_CHECK_FAILED if failed else 0
