"""MCmatlab's media function to a list of :class:`~mcmatlab_py.Medium`, and 0-based media.

``mediaProperties(j).mua = ...`` statements, grouped by ``j``, become one ``Medium(...)``
each, one keyword per line with the line's comment; nested functions (``@func_mua2``)
become nested ``def``\\ s; MCmatlab 3's properties given as text (``'10 + FR/1000'``)
become lambdas of ``(wavelength, FR, T, FD)`` (optical) or ``(T, FD)`` (thermal).
"""

from __future__ import annotations

from .expr import ATOM, LAMBDA, PRIMARY, E, Scope, int_literal, py_name
from .names import OPTICAL_ARGS, THERMAL_ARGS, Unconvertible, medium_field

__all__ = ["MediaTranslator"]

INDENT = "    "


def _medium_target(node, outs: list[str]):
    """(j node, field) of ``out(j).field = ...``, else None."""
    from miss_hit_core import m_ast

    if not isinstance(node, m_ast.Simple_Assignment_Statement):
        return None
    lhs = node.n_lhs
    if not (isinstance(lhs, m_ast.Selection) and isinstance(lhs.n_prefix, m_ast.Reference)):
        return None
    ref = lhs.n_prefix
    if not (isinstance(ref.n_ident, m_ast.Identifier) and ref.n_ident.t_ident.value in outs
            and len(ref.l_args) == 1):
        return None
    return ref.l_args[0], lhs.n_field.t_ident.value


class MediaTranslator:
    """Media and geometry functions (mixed into :class:`~mcmatlab_py.port.translate.Translator`)."""

    _shift_media: str | None = None
    _media_name: str | None = None  #: the media function being translated

    # -- geometry: media numbered from 0 -------------------------------------------------
    def literal_media(self, body, out: str) -> bool:
        """True when every assignment to ``out`` puts a literal medium number (or fills with
        ``k*ones(size(X))``): those numbers can be written one lower."""
        from miss_hit_core import m_ast

        found = []

        class V(m_ast.AST_Visitor):
            def visit(self, n, parent, relation):
                if isinstance(n, m_ast.Simple_Assignment_Statement):
                    lhs = n.n_lhs
                    base = lhs.n_ident if isinstance(lhs, m_ast.Reference) else lhs
                    if isinstance(base, m_ast.Identifier) and base.t_ident.value == out:
                        found.append(_shifted_medium(n.n_rhs, isinstance(lhs, m_ast.Identifier))
                                     is not None)
                elif isinstance(n, m_ast.Compound_Assignment_Statement):
                    if any(getattr(x, "t_ident", None) is not None and x.t_ident.value == out
                           for x in n.l_lhs):
                        found.append(False)

        body.visit(None, V(), "root")
        return bool(found) and all(found)

    def value(self, rhs, scope, node) -> E:
        from miss_hit_core import m_ast

        out = self._shift_media
        if out is not None:
            lhs = node.n_lhs
            base = lhs.n_ident if isinstance(lhs, m_ast.Reference) else lhs
            if isinstance(base, m_ast.Identifier) and base.t_ident.value == out:
                shifted = _shifted_medium(rhs, isinstance(lhs, m_ast.Identifier))
                k, like = shifted
                if like is None:
                    return E(str(k - 1), ATOM, "int")
                grid = self.ex(like, scope).code
                scope.kinds[out] = "voxels"
                self.imports.add("np")
                if k == 1:
                    return E(f"np.zeros({grid}.shape, dtype=int)", PRIMARY, "voxels")
                return E(f"np.full({grid}.shape, {k - 1})", PRIMARY, "voxels")
        return self.ex(rhs, scope)

    # -- media ---------------------------------------------------------------------------
    def is_media_function(self, fn) -> bool:
        outs = [o.t_ident.value for o in fn.n_sig.l_outputs]
        return bool(outs) and any(_medium_target(s, outs) is not None
                                  for s in fn.n_body.l_statements)

    def fr_in_text(self, fn) -> bool:
        """Whether MCmatlab 3 iterated ``fn``'s media on the fluence rate: an optical property
        (mua, mus, g) given as text that holds ``FR`` (MCmatlab 3's test, by substring)."""
        from miss_hit_core import m_ast

        outs = [o.t_ident.value for o in fn.n_sig.l_outputs]
        found = []

        class V(m_ast.AST_Visitor):
            def visit(self, n, parent, relation):
                target = _medium_target(n, outs)
                if target is not None and target[1] in ("mua", "mus", "g") and isinstance(
                        n.n_rhs, m_ast.Char_Array_Literal) and "FR" in n.n_rhs.t_string.value:
                    found.append(n)

        fn.n_body.visit(None, V(), "root")
        return bool(found)

    def media_call(self, fname: str, params: str, model: str) -> str:
        n = len(self.functions[fname].n_sig.l_inputs)
        if n == 0:
            return f"{py_name(fname)}()"
        if n == 1:
            return f"{py_name(fname)}({params})"
        # MCmatlab 3: mediaPropertiesFunc(wavelength, parameters)
        return f"{py_name(fname)}({model}.MC.wavelength, {params})"

    def media_function(self, fn, indent: str) -> list[str]:
        """The media function as a ``def`` returning ``[Medium(...), ...]``."""
        from miss_hit_core import m_ast

        self.imports.add("Medium")
        name = fn.n_sig.n_name.t_ident.value
        self._media_name = name
        params = [p.t_ident.value for p in fn.n_sig.l_inputs]
        outs = [o.t_ident.value for o in fn.n_sig.l_outputs]
        scope = Scope(role="media")
        for p in params:
            scope.kinds[p] = None
        first, last = self.src.span(fn)
        inner = indent + INDENT
        lines = [f"{indent}def {py_name(name)}({', '.join(py_name(p) for p in params)}):"
                 + self.trailing(first, first)]
        lines.append(f'{inner}"""The media: MCmatlab\'s medium j is media[j - 1] here."""')
        for nested in getattr(fn, "l_nested", []):
            saved = getattr(self, "_outer_scope", None)
            self._outer_scope = scope
            try:
                lines += self.function(nested, inner) + [""]
            finally:
                self._outer_scope = saved
        media: dict[int, list[str]] = {}
        heads: dict[int, list[str]] = {}
        j = None
        pending: list[str] = []
        prev = first
        for node in fn.n_body.l_statements:
            s_first, s_last = self.src.span(node)
            comments = self.comments_before(prev, s_first, "")
            prev = s_last
            target = _medium_target(node, outs)
            if target is not None:
                j_node, field = target
                k = int_literal(j_node)
                if k is None and isinstance(j_node, m_ast.Identifier) and \
                        j_node.t_ident.value == "j":
                    k = j
                if k is None:
                    lines += self.kept(node, "a medium index that is not a number or j", inner)
                    continue
                entry = media.setdefault(k, [])
                heads.setdefault(k, [])
                heads[k] += pending
                pending = []
                entry += [c.strip() for c in comments if c.strip()]
                entry += self.medium_property(node, field, scope, s_first, s_last)
                continue
            if isinstance(node, m_ast.Simple_Assignment_Statement) and isinstance(
                    node.n_lhs, m_ast.Identifier):
                lhs = node.n_lhs.t_ident.value
                rhs = node.n_rhs
                if lhs in outs and isinstance(rhs, m_ast.Selection):
                    # mediaProperties = MCmatlab.mediumProperties: the list below; the comments
                    # above it speak of that line
                    self.trailing(s_first, s_last)
                    continue
                if lhs == "j":
                    k = int_literal(rhs)
                    if k is None and isinstance(rhs, m_ast.Binary_Operation) and \
                            rhs.t_op.value == "+" and int_literal(rhs.n_rhs) is not None and j:
                        k = j + int_literal(rhs.n_rhs)
                    if k is not None:
                        j = k
                        self.trailing(s_first, s_last)
                        pending += [c.strip() for c in comments if c.strip()]
                        continue
            lines += [inner + c.strip() if c.strip() else "" for c in comments]
            lines += self.statement(node, scope, inner)
        if not media:
            raise Unconvertible(f"{name} sets no mediaProperties(j).<field>")
        if sorted(media) != list(range(1, len(media) + 1)):
            raise Unconvertible(f"media numbered {sorted(media)}: MCmatlab needs 1, 2, ...")
        lines.append(f"{inner}media = [")
        for k in sorted(media):
            entry = media[k]
            named = [e for e in entry if e.startswith("name=")]
            rest = [e for e in entry if not e.startswith("name=")]
            label = named[0][len("name="):] if named else f'"medium {k}"'
            for c in heads[k]:
                lines.append(f"{inner}{INDENT}{c}")
            lines.append(f"{inner}{INDENT}Medium(  # MCmatlab's medium {k}, media[{k - 1}] here")
            lines.append(f"{inner}{INDENT * 2}{label},")
            for e in rest:
                lines.append(f"{inner}{INDENT * 2}{e}")
            lines.append(f"{inner}{INDENT}),")
        lines.append(f"{inner}]")
        lines.append(f"{inner}return media")
        self.function_kinds[name] = "media"
        return lines

    def medium_property(self, node, field: str, scope, first: int, last: int) -> list[str]:
        """``mediaProperties(j).field = value`` as ``kwarg=value,  # comment`` (or kept)."""
        from miss_hit_core import m_ast

        rhs = node.n_rhs
        try:
            if field == "PY":
                e = self.power_yield(rhs, scope)
                return [f"QY={e.code},{self.trailing(first, last)}  # (MCmatlab 3's power yield "
                        "PY as photons: QY = PY * FMC.wavelength / MC.wavelength)"]
            kw = medium_field(field)
            if isinstance(rhs, m_ast.Char_Array_Literal) and kw != "name":
                e = self.text_property(rhs.t_string.value, kw, scope)
            elif isinstance(rhs, m_ast.Matrix_Expression):
                e = self._ex_Matrix_Expression(rhs, scope)
            else:
                e = self.ex(rhs, scope)
        except Unconvertible as err:
            return [c for c in self.kept(node, str(err), "")]
        text = f"{kw}={e.code}," if kw != "name" else f"name={e.code}"
        return [text + self.trailing(first, last)]

    def power_yield(self, rhs, scope) -> E:
        """MCmatlab 3's power yield PY (W emitted per W absorbed) as the quantum yield QY of
        the excitation wavelength, read from the one model that uses this media function."""
        from miss_hit_core import m_ast

        why = "MCmatlab 3's power yield PY: give QY = PY * FMC.wavelength / MC.wavelength " \
              "(photons instead of power)"
        models = sorted(m for m, f in self.media_funcs.items() if f == self._media_name)
        if len(models) != 1:
            raise Unconvertible(why)
        if isinstance(rhs, m_ast.Char_Array_Literal):
            body = f"({self.text_expression(rhs.t_string.value, OPTICAL_ARGS, scope).code})"
        else:
            e = self.ex(rhs, scope)
            if e.kind not in ("int", "scalar"):
                raise Unconvertible(why)
            body = e.code
        args = ", ".join(OPTICAL_ARGS)
        return E(f"lambda {args}: {body} * {models[0]}.FMC.wavelength / wavelength", LAMBDA,
                 "function")

    def text_property(self, text: str, kw: str, scope) -> E:
        """MCmatlab 3's ``'10 + FR/1000'``: a lambda of the state variables."""
        args = THERMAL_ARGS if kw in ("VHC", "TC") else OPTICAL_ARGS
        body = self.text_expression(text, args, scope)
        return E(f"lambda {', '.join(args)}: {body.code}", LAMBDA, "function")

    def text_expression(self, text: str, args, scope) -> E:
        """The MATLAB expression ``text`` of the variables ``args``, in Python."""
        from .parse import MatlabSyntaxError, parse_expression

        try:
            node = parse_expression(text)
        except MatlabSyntaxError as err:
            raise Unconvertible(f"the text {text!r} is not a MATLAB expression") from err
        inner = Scope(parent=scope, role="function")
        for a in args:
            inner.kinds[a] = None
        return self.ex(node, inner)


def _shifted_medium(rhs, whole: bool):
    """(k, grid node or None) for ``k``, ``ones(size(X))`` (k = 1), ``k*ones(size(X))``."""
    from miss_hit_core import m_ast

    k = int_literal(rhs)
    if k is not None:
        return k, None
    if not whole:
        return None

    def ones_like(n):
        if (isinstance(n, m_ast.Reference) and isinstance(n.n_ident, m_ast.Identifier)
                and n.n_ident.t_ident.value == "ones" and len(n.l_args) == 1):
            a = n.l_args[0]
            if (isinstance(a, m_ast.Reference) and isinstance(a.n_ident, m_ast.Identifier)
                    and a.n_ident.t_ident.value == "size" and len(a.l_args) == 1):
                return a.l_args[0]
        return None

    like = ones_like(rhs)
    if like is not None:
        return 1, like
    if isinstance(rhs, m_ast.Binary_Operation) and rhs.t_op.value in ("*", ".*"):
        for a, b in ((rhs.n_lhs, rhs.n_rhs), (rhs.n_rhs, rhs.n_lhs)):
            k, like = int_literal(a), ones_like(b)
            if k is not None and like is not None:
                return k, like
    return None


