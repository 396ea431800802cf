"""Text of error messages shared by the packages.

An error line echoes the value it refuses; a value read from a file can be any size (a
100 kB TOML string, a CSV field without its line break), so messages pass such values
through :func:`shorten` and stay one short line. The one implementation lives in
:mod:`fem.checks` (the lowest layer, with the number check that uses it).
"""

from __future__ import annotations

from fem.checks import shorten

__all__ = ["shorten"]
