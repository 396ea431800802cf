"""Checks of user-given numbers, shared by every package (fem is the lowest layer).

One implementation: :func:`check_number` refuses what is not a real number (a string
such as ``"0.5"``, a bool, None), what is not finite, not an integer when one is needed,
or outside a physically sensible range, with a ``ValueError`` (or the caller's subclass)
that names the field and shows the value, cut to one short line by :func:`shorten`.
A misspelt name is answered by :func:`unknown_name_hint`: the closest known name and
the known names, whole.
"""

from __future__ import annotations

import difflib
import math
import numbers

__all__ = ["check_number", "closest_name", "shorten", "unknown_name_hint"]


def shorten(value, limit: int = 80) -> str:
    """``value`` as text (a ``str`` as it is, anything else as its ``repr``), on one line
    and cut to ``limit`` characters followed by ``...`` and the full length.

    Pass ``repr(value)`` to keep the quotes of a string: ``shorten(repr("x" * 10**5))``
    gives ``'xxx...x... (100002 characters)``.
    """
    text = value if isinstance(value, str) else repr(value)
    text = text.replace("\r", " ").replace("\n", " ")
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def closest_name(name: str, known) -> str | None:
    """The name of ``known`` closest to the misspelt ``name`` (:mod:`difflib`'s ratio of
    at least 0.6), or None when none is close."""
    close = difflib.get_close_matches(name, sorted(known), n=1)
    return close[0] if close else None


def unknown_name_hint(name: str, known, limit: int = 240) -> str:
    """``"; did you mean 'x'? (allowed: a, b, ...)"`` for a misspelt ``name``: the closest
    of ``known``, then the names of ``known`` in order, whole, as many as fit in ``limit``
    characters (``"and 7 more"`` for the rest), so that the message stays one line."""
    close = closest_name(name, known)
    names, shown, used = sorted(known), [], 0
    for n in names:
        if shown and used + len(n) + 2 > limit:
            break
        shown.append(n)
        used += len(n) + 2
    rest = f", and {len(names) - len(shown)} more" if len(shown) < len(names) else ""
    return (f"; did you mean {close!r}?" if close else "") + (
        f" (allowed: {', '.join(shown)}{rest})")


def check_number(name: str, value, *, integer: bool = False, lo: float | None = None,
                 hi: float | None = None, lo_open: bool = False, allow_inf: bool = False,
                 error: type[ValueError] = ValueError) -> float | int:
    """``value`` as a float (or an int with ``integer``), or ``error`` naming ``name``.

    Parameters
    ----------
    name : str
        The field as the user wrote it (``"G.Lx"``, ``"filter.n_members"``).
    integer : bool
        Require an integer (a float with no fraction, such as ``3.0``, is accepted).
    lo, hi : float, optional
        The allowed range, inclusive (``lo_open``: ``lo`` itself is refused).
    allow_inf : bool
        Accept +-inf (a perfect reflector's refractive index); NaN never.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        kind = "an integer" if integer else "a number"
        raise error(f"{name} must be {kind}, got {shorten(repr(value))}")
    try:
        v = float(value)
    except OverflowError:  # an integer beyond the floats (10**400): out of any range
        if hi is not None and value > 0:
            raise error(f"{name} must be <= {hi:g}, got {shorten(repr(value))}") from None
        if lo is not None and value < 0:
            raise error(f"{name} must be >= {lo:g}, got {shorten(repr(value))}") from None
        raise error(f"{name} must be finite, got {shorten(repr(value))}") from None
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise error(f"{name} must be finite, got {shorten(repr(value))}")
    if integer and not (math.isfinite(v) and v.is_integer()):
        raise error(f"{name} must be an integer, got {shorten(repr(value))}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise error(f"{name} must be {'>' if lo_open else '>='} {lo:g}, got {shorten(repr(value))}")
    if hi is not None and v > hi:
        raise error(f"{name} must be <= {hi:g}, got {shorten(repr(value))}")
    return int(value) if integer else v
