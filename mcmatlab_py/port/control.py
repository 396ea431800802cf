"""MATLAB's control flow to Python: ``for``, ``while``, ``if``, ``break``, ``continue`` and
``return`` (a mixin of :class:`~mcmatlab_py.port.translate.Translator`, which gives
``block``, ``ex`` and ``src``)."""

from __future__ import annotations

from .expr import E, _minus_one, _plus_one, py_name, wrap

__all__ = ["INDENT", "ControlTranslator"]

INDENT = "    "


class ControlTranslator:
    """The statements that hold other statements, and the jumps out of them."""

    def _st_Break_Statement(self, node, scope, indent):
        return [f"{indent}break"]

    def _st_Continue_Statement(self, node, scope, indent):
        return [f"{indent}continue"]

    def _st_Return_Statement(self, node, scope, indent):
        outs = getattr(self, "_outputs", [])
        return [f"{indent}return {', '.join(outs)}".rstrip()]

    # -- compound statements -------------------------------------------------------------
    def _st_General_For_Statement(self, node, scope, indent):
        from miss_hit_core import m_ast

        var = node.n_ident.t_ident.value
        rng = node.n_expr
        first, last = self.src.span(node)
        if isinstance(rng, m_ast.Range_Expression):
            a, b = self.ex(rng.n_first, scope), self.ex(rng.n_last, scope)
            s = self.ex(rng.n_stride, scope) if rng.n_stride is not None else None
            if a.kind == "int" and b.kind == "int" and (s is None or s.kind == "int"):
                stop = (_plus1(b) if s is None or not s.code.startswith("-") else
                        _minus_one(b).code)
                header = f"range({a.code}, {stop}" + (f", {s.code})" if s else ")")
                if a.code == "0" and s is None:
                    header = f"range({stop})"
                scope.kinds[var] = "int"
            else:
                header = self.ex(rng, scope).code
                scope.kinds[var] = "scalar"
        else:
            header = self.ex(rng, scope).code
            scope.kinds[var] = None
        body = self.block(node.n_body, scope, indent + INDENT, first, last)
        return [f"{indent}for {py_name(var)} in {header}:"] + (body or [f"{indent}{INDENT}pass"])

    def _st_While_Statement(self, node, scope, indent):
        first, last = self.src.span(node)
        cond = self.condition(node.n_guard, scope)
        body = self.block(node.n_body, scope, indent + INDENT, first, last)
        return [f"{indent}while {cond}:"] + (body or [f"{indent}{INDENT}pass"])

    def _st_If_Statement(self, node, scope, indent):
        lines = []
        actions = node.l_actions
        for k, action in enumerate(actions):
            first, _ = self.src.span(action)
            nxt = self.src.span(actions[k + 1])[0] if k + 1 < len(actions) else \
                self.src.span(node)[1]
            kind = action.kind()
            if kind == "else":
                head = f"{indent}else:"
            else:
                word = "if" if kind == "if" else "elif"
                head = f"{indent}{word} {self.condition(action.n_expr, scope)}:"
            body = self.block(action.n_body, scope, indent + INDENT, first, nxt)
            lines += [head] + (body or [f"{indent}{INDENT}pass"])
        return lines

    def condition(self, node, scope) -> str:
        """An ``if``/``while`` guard: MATLAB's ``~x`` is Python's ``not x`` here."""
        from miss_hit_core import m_ast

        if isinstance(node, m_ast.Unary_Operation) and node.t_op.value in ("~", "!"):
            return f"not {wrap(self.ex(node.n_expr, scope), 5)}"
        return self.ex(node, scope).code


def _plus1(e: E) -> str:
    return _plus_one(e).code
