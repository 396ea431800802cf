"""Convert a MCmatlab model script (``.m``) into a Python script that uses mcmatlab_py.

>>> result = port_model(open("Example4_BloodVessel.m").read())  # doctest: +SKIP
>>> print(result.script)  # doctest: +SKIP
>>> result.unconverted  # [(line, MATLAB text, why)]  # doctest: +SKIP

The command line: ``tissue-enkf port MODEL.m [-o OUT.py]``. What converts and what needs a
hand: ``docs/porting.md``. The MATLAB parser is MISS_HIT's (the ``port`` extra).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .parse import INSTALL_HINT, MatlabSyntaxError, ParserMissingError, read_matlab

__all__ = ["INSTALL_HINT", "MatlabSyntaxError", "ParserMissingError", "PortResult", "port_file",
           "port_model", "read_matlab"]


@dataclass
class PortResult:
    """A converted script and the MATLAB lines it keeps as comments."""

    script: str  #: the Python script
    #: (line, MATLAB text, why) of every statement kept as a comment instead of converted
    unconverted: list[tuple[int, str, str]] = field(default_factory=list)

    def report(self) -> str:
        """The unconverted lines, one per line: ``line N: text  (why)``."""
        return "\n".join(f"line {n}: {' '.join(t.split())}  ({why})"
                         for n, t, why in self.unconverted)


def port_model(text: str, name: str = "model.m") -> PortResult:
    """Convert the MCmatlab model script ``text`` (the contents of ``name``).

    Raises :class:`ParserMissingError` (an ``ImportError``) without ``miss_hit_core`` and
    :class:`MatlabSyntaxError` (a ``ValueError``) for text that is not MATLAB.
    """
    from .assemble import assemble
    from .parse import parse_matlab
    from .translate import Translator

    if not isinstance(text, str):
        raise TypeError(f"port_model: text must be a str, got {type(text).__name__}")
    src = parse_matlab(text, name)
    tr = Translator(src)
    defs, body = tr.translate(src.tree)
    script = assemble(name, tr, defs, body)
    return PortResult(script=script, unconverted=sorted(tr.unconverted))


def port_file(path) -> PortResult:
    """:func:`port_model` of the file at ``path`` (UTF-8 or Latin-1)."""
    from pathlib import Path

    p = Path(path)
    return port_model(read_matlab(p.read_bytes()), p.name)
