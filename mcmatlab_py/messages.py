"""Text of error messages shared by the packages (a leaf module: imports nothing).

An error line echoes the value it refuses; a value read from a file can be any size (a
100 kB TOML string, a CSV field without its line break), so messages pass such values
through :func:`shorten` and stay one short line.
"""

from __future__ import annotations

__all__ = ["shorten"]


def shorten(value, limit: int = 80) -> str:
    """``value`` as text (a ``str`` as it is, anything else as its ``repr``), on one line
    and cut to ``limit`` characters followed by ``...`` and the full length.

    Pass ``repr(value)`` to keep the quotes of a string: ``shorten(repr("x" * 10**5))``
    gives ``'xxx...x... (100002 characters)``.
    """
    text = value if isinstance(value, str) else repr(value)
    text = text.replace("\r", " ").replace("\n", " ")
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"
