"""MATLAB source to a syntax tree, through MISS_HIT's parser (``pip install 'tissue-enkf[port]'``).

MISS_HIT (``miss_hit_core`` on PyPI, GPL-3.0-or-later, an optional extra that this package
does not ship) parses all of MCmatlab's examples: 26 ``Example*.m`` and ``Test1``, 4 to 60
ms each (``validation/reports/port_examples.md``). This module keeps the parser's tokens
as well, for the comments (which the tree drops) and for the lines each statement spans.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["INSTALL_HINT", "ParsedSource", "ParserMissingError", "parse_matlab", "read_matlab"]

INSTALL_HINT = ("the MATLAB parser is an optional extra: pip install 'tissue-enkf[port]' "
                "(or pip install miss_hit_core)")


class ParserMissingError(ImportError):
    """``miss_hit_core`` is not installed."""


class MatlabSyntaxError(ValueError):
    """The source is not MATLAB that MISS_HIT can parse."""


@dataclass
class ParsedSource:
    """A parsed MATLAB file: its tree, its lines, and per-line comments."""

    tree: object  #: miss_hit's ``Script_File`` or ``Function_File``
    lines: list[str]  #: the source lines (index 0 is line 1)
    #: line -> (comment text without ``%``, True if the line holds nothing else)
    comments: dict[int, tuple[str, bool]] = field(default_factory=dict)
    #: id(statement node) -> (first line, last line)
    spans: dict[int, tuple[int, int]] = field(default_factory=dict)

    def span(self, node) -> tuple[int, int]:
        """First and last line of a statement (of its tokens)."""
        if id(node) in self.spans:
            return self.spans[id(node)]
        line = node.loc().line
        return line, line

    def text(self, first: int, last: int) -> str:
        return "\n".join(self.lines[first - 1:last])


def _miss_hit():
    try:
        from miss_hit_core import config, errors
        from miss_hit_core.m_language import MATLAB_Latest_Language
        from miss_hit_core.m_lexer import MATLAB_Lexer, Token_Buffer
        from miss_hit_core.m_parser import MATLAB_Parser
    except ImportError as err:
        raise ParserMissingError(INSTALL_HINT) from err
    return config, errors, MATLAB_Latest_Language, MATLAB_Lexer, Token_Buffer, MATLAB_Parser


def read_matlab(raw: bytes) -> str:
    """Decode a ``.m`` file: UTF-8, else Latin-1 (MCmatlab's examples hold a Latin-1 µ)."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def parse_matlab(text: str, filename: str = "model.m") -> ParsedSource:
    """Parse MATLAB ``text``; raises :class:`MatlabSyntaxError` naming the line on bad syntax."""
    config, errors, language, lexer_cls, buffer_cls, parser_cls = _miss_hit()
    if not text.endswith("\n"):
        text += "\n"
    mh = errors.Message_Handler("debug")
    mh.register_file(filename)
    cfg = config.Config()
    try:
        lexer = lexer_cls(language(), mh, text, filename)
        tbuf = buffer_cls(lexer, cfg)
        tree = parser_cls(mh, tbuf, cfg).parse_file()
    except errors.Error as err:
        msg = getattr(err, "message", str(err))
        loc = getattr(err, "location", None)
        where = f" at line {loc.line}" if loc is not None and loc.line else ""
        raise MatlabSyntaxError(f"{filename}: not MATLAB that can be parsed{where}: {msg}") from err

    src = ParsedSource(tree=tree, lines=text.splitlines())
    code_lines = set()
    for tok in tbuf.tokens:
        line = tok.location.line
        if tok.kind == "COMMENT":
            body = tok.raw_text.lstrip()
            body = body[1:] if body.startswith("%") else body
            src.comments[line] = (body.rstrip(), False)
        elif tok.kind not in ("NEWLINE", "CONTINUATION"):
            code_lines.add(line)
        node = tok.ast_link
        while node is not None:
            first, last = src.spans.get(id(node), (line, line))
            src.spans[id(node)] = (min(first, line), max(last, line))
            node = node.n_parent
    for line, (body, _) in list(src.comments.items()):
        src.comments[line] = (body, line not in code_lines)
    return src


def parse_expression(text: str):
    """The syntax tree of one MATLAB expression (MCmatlab 3's media properties given as text)."""
    src = parse_matlab(f"x__ = {text};\n", "expression")
    return src.tree.n_statements.l_statements[0].n_rhs
