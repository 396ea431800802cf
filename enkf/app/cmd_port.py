"""``port``: a MCmatlab model script (``.m``) converted to a Python script of mcmatlab_py."""

from __future__ import annotations

import sys
from pathlib import Path

from .common import EXIT_BAD_INPUT

__all__ = ["cmd_port"]


def cmd_port(args) -> int:
    """Convert ``args.model``; write the script to ``args.output`` (or print it) and list on
    stderr the MATLAB lines kept as comments. Exit 0, or 2 for a bad path, text that is not
    MATLAB, or a missing parser (with the command that installs it)."""
    from mcmatlab_py.port import ParserMissingError, port_file

    model = Path(args.model)
    if not model.is_file():
        raise ValueError(f"port: MODEL {str(model)!r} is not a file")
    if model.suffix.lower() != ".m":
        raise ValueError(f"port: MODEL must be a MATLAB script (.m), got {str(model)!r}")
    out = Path(args.output) if args.output else None
    if out is not None:
        if out.resolve() == model.resolve():
            raise ValueError(f"port: --output {str(out)!r} is the MODEL itself")
        if out.suffix != ".py":
            raise ValueError(f"port: --output must name a .py file, got {str(out)!r}")
        if out.exists() and not args.force:
            raise ValueError(f"port: --output {str(out)!r} exists (--force replaces it)")
    try:
        result = port_file(model)
    except ParserMissingError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if out is None:
        sys.stdout.write(result.script)
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(result.script)
    where = str(out) if out is not None else "stdout"
    n = len(result.unconverted)
    print(f"{model} -> {where}: " + ("every statement converted" if not n else
          f"{n} statement{'s' * (n != 1)} kept as comments:"), file=sys.stderr)
    if n:
        print(result.report(), file=sys.stderr)
    return 0
