"""``replay``: the live page over a recorded run (an edge module)."""

from __future__ import annotations

import math
from pathlib import Path

from .common import shorten

__all__ = ["cmd_replay", "check_port"]


def check_port(option: str, port: int) -> int:
    if not 0 <= port <= 65535:
        raise ValueError(f"{option} must be a port number in [0, 65535], got {shorten(port)}")
    return port


def cmd_replay(args) -> int:
    from .frames import require
    from .live_page import serve

    run_dir = Path(args.run_dir)
    if not run_dir.is_dir():
        raise ValueError(f"replay: {str(run_dir)!r} is not a run directory")
    if not (run_dir / "estimates.csv").is_file():
        raise ValueError(f"replay: {str(run_dir)!r} has no estimates.csv (a run of "
                         "tissue-enkf identify?)")
    if not (math.isfinite(args.speed) and args.speed > 0):
        raise ValueError(f"--speed must be a finite number > 0, got {shorten(args.speed)}")
    check_port("--port", args.port)
    require("bokeh", "the replay page")

    def announce(url):
        print(f"replay of {run_dir} at {url} ({args.speed:g} x the data's pace): Ctrl-C "
              "closes it", flush=True)
    try:
        serve(run_dir, args.port, replay_speed=args.speed, announce=announce)
    except KeyboardInterrupt:
        pass
    return 0
