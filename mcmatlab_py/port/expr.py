"""MATLAB expressions to Python (numpy) expressions, on MISS_HIT's syntax tree.

Every expression becomes an :class:`E`: the Python text, its precedence (parentheses are
put where Python's precedence needs them, not where MATLAB's had them) and a rough kind
(``"model"``, ``"int"``, ``"bool"``, ``"voxels"``, ``"matrix"``, ``"str"``, ...) that
picks between MATLAB's meanings: ``A(i)`` indexes a variable or calls a function,
``A * B`` multiplies element-wise unless both are matrices, a single subscript into a 3-D
array is MATLAB's column-major linear index. Indices shift from 1-based to 0-based.
"""

from __future__ import annotations

import codecs
import re
from dataclasses import dataclass, field

from .names import Unconvertible

__all__ = ["E", "ExprTranslator", "Scope"]

# Python's operator precedence, low to high
LAMBDA, OR, AND, NOT, CMP, BOR, BXOR, BAND, ADD, MUL, UNARY, POW, PRIMARY, ATOM = range(1, 15)

_BINARY = {"+": ("+", ADD), "-": ("-", ADD), ".*": ("*", MUL), "./": ("/", MUL),
           "/": ("/", MUL), "*": ("*", MUL), ".^": ("**", POW), "^": ("**", POW),
           "==": ("==", CMP), "~=": ("!=", CMP), "<": ("<", CMP), "<=": ("<=", CMP),
           ">": (">", CMP), ">=": (">=", CMP), "&": ("&", BAND), "|": ("|", BOR),
           "&&": ("and", AND), "||": ("or", OR)}
_CONSTANTS = {"pi": ("np.pi", "scalar"), "Inf": ("np.inf", "scalar"), "inf": ("np.inf", "scalar"),
              "NaN": ("np.nan", "scalar"), "nan": ("np.nan", "scalar"),
              "true": ("True", "bool"), "false": ("False", "bool"),
              "eps": ("np.finfo(float).eps", "scalar")}
#: element-wise functions of one argument: MATLAB name -> numpy name
_ELEMENTWISE = {n: n for n in ("sqrt", "exp", "log", "log10", "log2", "sin", "cos", "tan",
                               "sinh", "cosh", "tanh", "abs", "floor", "ceil", "sign", "round",
                               "fix", "real", "imag", "conj", "isnan", "isinf", "isfinite")}
_ELEMENTWISE.update({"asin": "arcsin", "acos": "arccos", "atan": "arctan", "atan2": "arctan2",
                     "mod": "mod", "rem": "fmod", "hypot": "hypot", "power": "power",
                     "exp10": "exp10"})
_REDUCTIONS = {"sum": "sum", "mean": "mean", "prod": "prod", "any": "any", "all": "all",
               "median": "median", "cumsum": "cumsum"}
_PY_KEYWORDS = {"lambda", "in", "is", "def", "class", "from", "import", "pass", "yield", "with",
                "as", "del", "global", "not", "and", "or", "None", "True", "False", "assert",
                "raise", "except", "finally", "nonlocal", "async", "await", "print", "len",
                "type", "id", "list", "dict", "str", "int", "float", "np", "plt", "copy", "time"}


@dataclass
class E:
    """A translated expression."""

    code: str
    prec: int = ATOM
    kind: str | None = None


@dataclass
class Scope:
    """What the names of one MATLAB function (or the script) are."""

    kinds: dict[str, str | None] = field(default_factory=dict)  #: variable -> kind
    role: str = "script"  #: "script", "geometry", "media" or "function"
    parent: Scope | None = None

    def kind(self, name: str):
        if name in self.kinds:
            return self.kinds[name]
        return self.parent.kind(name) if self.parent is not None else None

    def has(self, name: str) -> bool:
        return name in self.kinds or (self.parent is not None and self.parent.has(name))


def py_name(name: str) -> str:
    """A MATLAB name that is a Python keyword (or shadows what the script imports) gets a ``_``."""
    return name + "_" if name in _PY_KEYWORDS else name


def wrap(e: E, prec: int) -> str:
    return f"({e.code})" if e.prec < prec else e.code


def number(text: str) -> E:
    t = text.strip()
    if t.endswith(("i", "j")):
        return E(t[:-1] + "j", ATOM, "scalar")
    if t.startswith("."):
        t = "0" + t
    t = re.sub(r"\.(?=[eE]|$)", ".0", t)
    is_int = re.fullmatch(r"\d+", t) is not None
    return E(t, ATOM, "int" if is_int else "scalar")


def py_string(value: str, escapes: bool = False) -> E:
    """A Python string literal; ``escapes``: MATLAB's fprintf/sprintf escapes (``\\n``)."""
    if escapes:
        value = codecs.decode(value.replace("\\\\", "\x00"), "unicode_escape").replace("\x00", "\\")
    return E(repr(value) if '"' in value else '"' + repr(value)[1:-1].replace('\\"', '"')
             .replace("\\'", "'") + '"', ATOM, "str")


def int_literal(node) -> int | None:
    """The value of an integer literal node (or of ``-k``), else None."""
    from miss_hit_core import m_ast

    if isinstance(node, m_ast.Number_Literal):
        e = number(node.t_value.value)
        return int(e.code) if e.kind == "int" else None
    if isinstance(node, m_ast.Unary_Operation) and node.t_op.value == "-":
        v = int_literal(node.n_expr)
        return -v if v is not None else None
    return None


def _minus_one(e: E) -> E:
    """``e - 1``, simplified where ``e`` is ``k`` or ``x + 1``."""
    if e.kind == "int" and re.fullmatch(r"-?\d+", e.code):
        return E(str(int(e.code) - 1), ATOM, "int")
    m = re.fullmatch(r"(.+) \+ 1", e.code)
    if m and e.prec == ADD:
        return E(m.group(1), ADD, e.kind)
    return E(f"{wrap(e, ADD)} - 1", ADD, "int")


def _plus_one(e: E) -> E:
    if e.kind == "int" and re.fullmatch(r"-?\d+", e.code):
        return E(str(int(e.code) + 1), ATOM, "int")
    m = re.fullmatch(r"(.+) - 1", e.code)
    if m and e.prec == ADD:
        return E(m.group(1), ADD, e.kind)
    return E(f"{wrap(e, ADD)} + 1", ADD, "int")


class ExprTranslator:
    """Expression translation; :class:`~mcmatlab_py.port.translate.Translator` adds statements."""

    #: names of the file's own functions
    functions: dict

    def __init__(self):
        self.imports: set[str] = set()  # "np", "plt", "copy", "time", "Medium", ...
        self.functions = {}
        self._end: str | None = None  # what 'end' means inside the subscript being translated

    # -- the entry point -------------------------------------------------------------------
    def ex(self, node, scope: Scope) -> E:
        from miss_hit_core import m_ast

        method = getattr(self, "_ex_" + type(node).__name__, None)
        if method is None:
            raise Unconvertible(f"no translation for MATLAB's {type(node).__name__}")
        e = method(node, scope)
        if isinstance(node, m_ast.Expression) and e is not None and "np." in e.code:
            self.imports.add("np")
        return e

    # -- atoms -----------------------------------------------------------------------------
    def _ex_Number_Literal(self, node, scope):
        return number(node.t_value.value)

    def _ex_Char_Array_Literal(self, node, scope):
        return py_string(node.t_string.value.replace("''", "'"))

    def _ex_String_Literal(self, node, scope):
        return py_string(node.t_string.value.replace('""', '"'))

    def _ex_Identifier(self, node, scope):
        name = node.t_ident.value
        if scope.has(name):
            return E(py_name(name), ATOM, scope.kind(name))
        if name in _CONSTANTS:
            code, kind = _CONSTANTS[name]
            return E(code, ATOM, kind)
        if name == "end":
            if self._end is None:
                raise Unconvertible("'end' outside an index")
            return E(self._end, PRIMARY, "int")
        # a function called without parentheses
        return self.call(name, [], scope, node)

    def _ex_Reshape(self, node, scope):
        raise Unconvertible("':' outside an index")

    # -- operators -------------------------------------------------------------------------
    def _ex_Binary_Operation(self, node, scope):
        op = node.t_op.value
        if op not in _BINARY:
            raise Unconvertible(f"MATLAB's operator {op!r} (a matrix division): write it by hand")
        a, b = self.ex(node.n_lhs, scope), self.ex(node.n_rhs, scope)
        py, prec = _BINARY[op]
        kind = None
        if op == "*" and a.kind == "matrix" and b.kind == "matrix":
            py = "@"  # MATLAB's matrix product
            kind = "matrix"
        elif op == "^" and a.kind == "matrix":
            self.imports.add("np")
            return E(f"np.linalg.matrix_power({a.code}, {b.code})", PRIMARY, "matrix")
        if prec == CMP or op in ("&&", "||"):
            kind = "bool"
        elif op in ("&", "|"):
            kind = "bool"
        elif kind is None:
            kinds = {a.kind, b.kind}
            if "voxels" in kinds:
                kind = "voxels"
            elif "matrix" in kinds:
                kind = "matrix"
            elif kinds <= {"int"} and py in ("+", "-", "*"):
                kind = "int"
            elif kinds <= {"int", "scalar"}:
                kind = "scalar"
        left = f"({a.code})" if (a.prec < prec or (prec in (POW, CMP) and a.prec == prec)) else a.code
        right = f"({b.code})" if (b.prec < prec or (b.prec == prec and prec != POW)) else b.code
        return E(f"{left} {py} {right}", prec, kind)

    _ex_Binary_Logical_Operation = _ex_Binary_Operation

    def _ex_Unary_Operation(self, node, scope):
        op = node.t_op.value
        a = self.ex(node.n_expr, scope)
        if op == "-":
            if a.kind in ("int", "scalar") and a.prec == ATOM and not a.code.startswith("-"):
                return E(f"-{a.code}", UNARY, a.kind)
            return E(f"-{wrap(a, UNARY)}", UNARY, a.kind)
        if op == "+":
            return a
        if op in ("~", "!"):
            self.imports.add("np")
            return E(f"np.logical_not({a.code})", PRIMARY, "bool")
        if op in ("'", ".'"):
            if a.kind in ("int", "scalar"):
                return a
            self.imports.add("np")
            return E(f"np.transpose({a.code})", PRIMARY, a.kind)
        raise Unconvertible(f"MATLAB's unary operator {op!r}")

    # -- ranges, matrices, cells -----------------------------------------------------------
    def _ex_Range_Expression(self, node, scope):
        """``a:b`` or ``a:s:b`` as a value: ``np.arange`` (the end included)."""
        first = self.ex(node.n_first, scope)
        last = self.ex(node.n_last, scope)
        self.imports.add("np")
        if node.n_stride is None:
            if first.kind == "int" and last.kind == "int":
                return E(f"np.arange({first.code}, {_plus_one(last).code})", PRIMARY, "vector")
            return E(f"np.arange({first.code}, {wrap(last, ADD)} + 0.5)", PRIMARY, "vector")
        step = self.ex(node.n_stride, scope)
        if {first.kind, step.kind, last.kind} <= {"int"}:
            stop = (_plus_one(last).code if not step.code.startswith("-")
                    else _minus_one(last).code)
            return E(f"np.arange({first.code}, {stop}, {step.code})", PRIMARY, "vector")
        return E(f"np.arange({first.code}, {wrap(last, ADD)} + {wrap(step, MUL)} / 2, "
                 f"{step.code})", PRIMARY, "vector")

    def rows(self, node, scope) -> list[list[E]]:
        return [[self.ex(item, scope) for item in row.l_items] for row in node.n_content.l_items]

    def _ex_Matrix_Expression(self, node, scope, as_setting: bool = False):
        rows = [r for r in self.rows(node, scope) if r]
        if not rows:
            return E("[]", ATOM, "list")
        flat = [e for r in rows for e in r]
        if all(e.kind == "str" for e in flat) and len(rows) == 1:
            return E(" + ".join(wrap(e, ADD) for e in flat), ADD, "str")
        if any(e.kind == "model" for e in flat):
            return E("[" + ", ".join(e.code for e in flat) + "]", ATOM, "models")
        scalar = all(e.kind in ("int", "scalar", "bool") for e in flat)
        if len(rows) == 1:
            body = "[" + ", ".join(e.code for e in rows[0]) + "]"
        else:
            body = "[" + ", ".join("[" + ", ".join(e.code for e in r) + "]" for r in rows) + "]"
        if as_setting and scalar:
            return E(body, ATOM, "list")
        self.imports.add("np")
        if scalar:
            return E(f"np.array({body})", PRIMARY, "matrix" if len(rows) > 1 else "vector")
        if len(rows) == 1 and len(rows[0]) == 1:
            return rows[0][0]
        return E(f"np.block({body})", PRIMARY, "matrix")

    def _ex_Cell_Expression(self, node, scope):
        flat = [e for r in self.rows(node, scope) for e in r]
        return E("[" + ", ".join(e.code for e in flat) + "]", ATOM, "cell")

    def _ex_Cell_Reference(self, node, scope):
        base = self.ex(node.n_ident, scope)
        if len(node.l_args) != 1:
            raise Unconvertible("a cell index with more than one subscript")
        i = self.index(node.l_args[0], scope, base, 0, 1)
        return E(f"{wrap(base, PRIMARY)}[{i}]", PRIMARY, None)

    # -- functions -------------------------------------------------------------------------
    def _ex_Lambda_Function(self, node, scope):
        inner = Scope(parent=scope, role="function")
        params = []
        for p in node.l_parameters:
            name = p.t_ident.value
            inner.kinds[name] = None
            params.append(py_name(name))
        body = self.ex(node.n_body, inner)
        return E(f"lambda {', '.join(params)}: {body.code}", LAMBDA, "function")

    def _ex_Function_Pointer(self, node, scope):
        name = node.n_name.t_ident.value if hasattr(node.n_name, "t_ident") else None
        if name is None:
            raise Unconvertible("a handle to a method")
        if name in self.functions:
            return E(py_name(name), ATOM, "function")
        target = self.builtin_handle(name)
        if target is None:
            raise Unconvertible(f"a handle to {name}, which is neither in this file nor known")
        return E(target, ATOM, "function")

    def builtin_handle(self, name: str) -> str | None:
        if name in _ELEMENTWISE:
            self.imports.add("np")
            return f"np.{_ELEMENTWISE[name]}"
        if name in ("calc_mua", "calc_mus"):
            self.imports.add(name)
            return name
        return None

    # -- indexing --------------------------------------------------------------------------
    def index(self, node, scope, base: E, pos: int, n: int) -> str:
        """One subscript ``node`` (at ``pos`` of ``n``) of ``base``, 0-based."""
        from miss_hit_core import m_ast

        if isinstance(node, m_ast.Reshape):
            return ":"
        if isinstance(node, m_ast.Range_Expression):
            first = self.bound(node.n_first, scope, base, pos, n)
            last = self.bound(node.n_last, scope, base, pos, n)
            step = self.ex(node.n_stride, scope) if node.n_stride is not None else None
            backwards = step is not None and step.code.startswith("-")
            start = "-1" if first is _END else _minus_one(first).code
            if backwards:
                if last is _END:
                    raise Unconvertible("a backwards range that ends at 'end'")
                stop = _minus_one(_minus_one(last)).code
                stop = "" if stop == "-1" else stop
                return f"{start}:{stop}:{step.code}"
            start = "" if start == "0" else start
            stop = "" if last is _END else last.code
            return f"{start}:{stop}" + (f":{step.code}" if step is not None else "")
        e = self.bound(node, scope, base, pos, n)
        if e is _END:
            return "-1"
        if e.kind == "bool":
            return e.code
        return _minus_one(e).code

    def bound(self, node, scope, base: E, pos: int, n: int):
        """A subscript expression in which ``end`` is the size of ``base`` along ``pos``."""
        from miss_hit_core import m_ast

        if isinstance(node, m_ast.Identifier) and node.t_ident.value == "end":
            return _END
        if (isinstance(node, m_ast.Binary_Operation) and node.t_op.value == "-"
                and isinstance(node.n_lhs, m_ast.Identifier) and node.n_lhs.t_ident.value == "end"
                and int_literal(node.n_rhs) is not None and int_literal(node.n_rhs) > 0):
            return E(f"-{int_literal(node.n_rhs)}", ATOM, "int")  # end-k: Python's -k
        if not _contains_end(node):
            return self.ex(node, scope)
        saved = self._end
        self._end = (f"{wrap(base, PRIMARY)}.size" if n == 1
                     else f"{wrap(base, PRIMARY)}.shape[{pos}]")
        try:
            e = self.ex(node, scope)
        finally:
            self._end = saved
        # a mask such as X < Z(end) stays a mask: its 'end' belongs to the inner index
        return E(e.code, e.prec, "bool" if e.kind == "bool" else "int")


_END = E("end", ATOM, "end")  # a subscript that is MATLAB's bare 'end'


def _contains_end(node) -> bool:
    from miss_hit_core import m_ast

    found = []

    class V(m_ast.AST_Visitor):
        def visit(self, n, parent, relation):
            if isinstance(n, m_ast.Identifier) and n.t_ident.value == "end":
                found.append(n)

    node.visit(None, V(), "root")
    return bool(found)
