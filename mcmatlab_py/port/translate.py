"""MATLAB statements and functions to Python, and the converted script put together.

The model script's statements keep their order and their comments; the file's functions
come first (Python needs them defined before use). The geometry function returns 0-based
media; the media function returns a list of :class:`~mcmatlab_py.Medium`. A statement
that cannot be converted is kept as a comment and listed (line, text, why).
"""

from __future__ import annotations

from .calls import CallTranslator, selection_chain
from .control import INDENT, ControlTranslator
from .expr import PRIMARY, E, Scope, _minus_one, int_literal, py_name, wrap
from .media import MediaTranslator
from .names import Unconvertible

__all__ = ["Translator"]


class Translator(ControlTranslator, CallTranslator, MediaTranslator):
    """Translate one parsed MATLAB file (:func:`mcmatlab_py.port.port_model`)."""

    def __init__(self, src):
        super().__init__()
        self.src = src
        self.unconverted: list[tuple[int, str, str]] = []
        self.done_comments: set[int] = set()
        self.needs_ni: set[str] = set()
        self.function_kinds: dict[str, str | None] = {}
        self.media_funcs: dict[str, str] = {}  # model variable -> its media function
        self.roles: dict[str, str] = {}
        self.events: list[tuple[int, str, str]] = []  # (line, "mc" | "hs", model variable)
        self.param_lines: list[tuple[int, str]] = []  # where G.mediaPropParams is set
        self.preamble: list[str] = []
        #: media functions with MCmatlab 3's text properties of FR (mua, mus or g)
        self.fr_text_media: set[str] = set()
        self.sets_fr_iterations: set[str] = set()  #: model variables that set FRdepIterations

    # -- comments ------------------------------------------------------------------------
    def comments_before(self, lo: int, hi: int, indent: str, lead: bool = True) -> list[str]:
        """Full-line comments (and blank lines) on lines lo < line < hi not yet emitted."""
        lines: list[str] = []
        for line in range(lo + 1, hi):
            c = self.src.comments.get(line)
            if line in self.done_comments:
                continue
            if c is not None and c[1]:
                self.done_comments.add(line)
                lines.append(_comment(c[0], indent))
            elif c is None and not self.src.lines[line - 1].strip():
                if (lines or lead) and (not lines or lines[-1] != ""):
                    lines.append("")
        while lines and lines[-1] == "":
            lines.pop()
        return lines

    def trailing(self, first: int, last: int) -> str:
        for line in range(last, first - 1, -1):
            c = self.src.comments.get(line)
            if c is not None and not c[1] and line not in self.done_comments:
                self.done_comments.add(line)
                return f"  # {c[0].strip()}" if c[0].strip() else ""
        return ""

    def kept(self, node, why: str, indent: str) -> list[str]:
        """The MATLAB lines of ``node`` as comments, recorded as not converted."""
        first, last = self.src.span(node)
        text = self.src.text(first, last)
        self.unconverted.append((first, text.strip(), why))
        for line in range(first, last + 1):
            self.done_comments.add(line)
        lines = [f"{indent}# MATLAB (line {first}, not converted: {why}):"]
        lines += [f"{indent}# {t}".rstrip() for t in text.splitlines()]
        return lines

    # -- sequences -----------------------------------------------------------------------
    def block(self, seq, scope: Scope, indent: str, start: int, end: int | None = None):
        """The statements of ``seq`` (a Sequence_Of_Statements), after line ``start``."""
        lines = []
        prev = start
        for k, node in enumerate(seq.l_statements):
            first, last = self.src.span(node)
            lines += self.comments_before(prev, first, indent, lead=k > 0 or start == 0)
            lines += self.statement(node, scope, indent)
            prev = last
        if end is not None:
            lines += self.comments_before(prev, end, indent, lead=False)
        return lines

    def statement(self, node, scope: Scope, indent: str) -> list[str]:
        first, last = self.src.span(node)
        try:
            method = getattr(self, "_st_" + type(node).__name__, None)
            if method is None:
                raise Unconvertible(f"MATLAB's {type(node).__name__.replace('_', ' ').lower()}")
            body = method(node, scope, indent)
        except Unconvertible as err:
            return self.kept(node, str(err), indent)
        if body:
            head_last = first if _compound(node) else last
            tail = self.trailing(first, head_last)
            # a simple statement's comment goes on its own line, not on the quick(...) and
            # settings lines that follow Model() and reset
            k = 0 if _compound(node) else max(
                (i for i, ln in enumerate(body) if not ln.lstrip().startswith(("#@", "quick("))),
                default=len(body) - 1)
            if tail and "  # (" in body[k]:  # the converter's note joins the line's comment
                code, note = body[k].split("  # ", 1)
                body[k] = f"{code}{tail} {note}"
            else:
                body[k] += tail
        return body

    # -- simple statements ---------------------------------------------------------------
    def _st_Simple_Assignment_Statement(self, node, scope, indent):
        from miss_hit_core import m_ast

        lhs, rhs = node.n_lhs, node.n_rhs
        if isinstance(lhs, m_ast.Identifier):
            return self.assign_name(lhs.t_ident.value, rhs, scope, indent, node)
        if isinstance(lhs, m_ast.Selection):
            chain = selection_chain(lhs)
            if scope.kind(chain[0]) == "model":
                return self.assign_model(chain, rhs, scope, indent, node)
            if not scope.has(chain[0]):
                raise Unconvertible(f"a struct ({chain[0]}): use a dict or a dataclass")
            target = self.ex(lhs, scope).code
            return [f"{indent}{target} = {self.ex(rhs, scope).code}"]
        if isinstance(lhs, m_ast.Reference | m_ast.Cell_Reference):
            base = lhs.n_ident
            if isinstance(base, m_ast.Identifier) and not scope.has(base.t_ident.value):
                raise Unconvertible(f"assigns into {base.t_ident.value} before it exists "
                                    "(MATLAB grows arrays; create it first)")
            value = self.value(rhs, scope, node)
            target = self.ex(lhs, scope).code
            return [f"{indent}{target} = {value.code}"]
        raise Unconvertible(f"an assignment to {type(lhs).__name__}")

    def assign_name(self, name, rhs, scope, indent, node):
        from miss_hit_core import m_ast

        e = self.value(rhs, scope, node)
        target = py_name(name)
        if e.kind == "figures":  # model = plot(model, 'MC'): plot returns figures
            return [f"{indent}{e.code}"]
        if e.kind == "model" and isinstance(rhs, m_ast.Identifier):
            self.imports.add("copy")
            e = E(f"copy.deepcopy({e.code})", PRIMARY, "model")  # MATLAB copies the model
        elif e.kind == "model" and e.code.endswith((".run_monte_carlo()",
                                                   ".simulate_heat_distribution()",
                                                   '.run_monte_carlo("fluorescence")')):
            obj = e.code.split(".", 1)[0]
            if obj != target:  # runMonteCarlo returns a new model; the argument stays as it was
                self.imports.add("copy")
                e = E(f"copy.deepcopy({obj}).{e.code.split('.', 1)[1]}", PRIMARY, "model")
        old = scope.kinds.get(name, e.kind)
        scope.kinds[name] = e.kind if old == e.kind or name not in scope.kinds else None
        if name in scope.kinds and old != e.kind and old is not None and e.kind is not None:
            scope.kinds[name] = None
        lines = [f"{indent}{target} = {e.code}"]
        if e.kind == "model" and e.code.startswith(f"{target}.reset("):
            # a fresh part: small again under MCMATLAB_PY_QUICK; a fresh MC needs the settings
            # made after Model() again
            self.imports.add("quick")
            lines.append(f"{indent}quick({target})")
            if e.code in (f"{target}.reset()", f'{target}.reset("MC")'):
                lines.append(f"{indent}#@settings {target}")
        if e.code == "Model()":
            self.imports.add("quick")
            lines.append(f"{indent}quick({target})  # MCMATLAB_PY_QUICK=1: a small grid and few "
                         "photons (tests)")
            lines.append(f"{indent}#@settings {target}")
        if e.kind == "model":
            scope.kinds[name] = "model"
        return lines

    def assign_model(self, chain, rhs, scope, indent, node):
        """``model.MC.lightSource.xFocus = v``, with the settings that need more than a name."""
        from miss_hit_core import m_ast

        target, special = self.model_path(chain, write=True)
        m = py_name(chain[0])
        if special == "media_func":
            if not isinstance(rhs, m_ast.Function_Pointer):
                raise Unconvertible("mediaPropertiesFunc that is not a handle to a function of "
                                    "this file")
            fname = rhs.n_name.t_ident.value
            if fname not in self.functions:
                raise Unconvertible(f"the media function {fname} is not in this file")
            self.media_funcs[m] = fname
            line = self.src.span(node)[0]
            later = any(ln > line and v == m for ln, v in self.param_lines)
            if later and _uses_last_input(self.functions[fname]):
                # MCmatlab calls it at run time with mediaPropParams, set further down
                return [f"{indent}# {m}.G.media is set below, where G.mediaPropParams is  # "
                        f"({fname} reads its parameters)"]
            return [f"{indent}{m}.G.media = {self.media_call(fname, '[]', m)}"]
        if special == "media_params":
            fname = self.media_funcs.get(m)
            if fname is None:
                raise Unconvertible("mediaPropParams before mediaPropertiesFunc")
            params = self.ex(rhs, scope).code
            return [f"{indent}{m}.G.media = {self.media_call(fname, params, m)}  "
                    "# (MCmatlab calls the media function with mediaPropParams)"]
        if special == "silent":
            e = self.ex(rhs, scope)
            value = {"True": "False", "False": "True"}.get(e.code, f"not {wrap(e, 5)}")
            owner = target.rsplit(".", 1)[0]
            if chain[1] == "G":
                raise Unconvertible("model.G prints nothing here: no silentMode")
            return [f"{indent}{owner}.progress = {value}  # (MCmatlab's silentMode)"]
        if special == "all_cpus":
            raise Unconvertible("numba runs on every core already (MC.n_threads = None)")
        if isinstance(rhs, m_ast.Matrix_Expression):
            e = self._ex_Matrix_Expression(rhs, scope, as_setting=True)
        else:
            e = self.ex(rhs, scope)
        if special == "hs_T":
            # MCmatlab's HS.T is the start temperature, also what the Monte Carlo's T-dependent
            # media see before a heat run
            return [f"{indent}{target} = {m}.MC.T = {e.code}"]
        if special == "matched":
            # MCmatlab's cuboid faces neither reflect nor refract (a packet outside sees the
            # nearest voxel's medium); this port's default is Fresnel against air (n_outside 1)
            owner = target.rsplit(".", 1)[0]
            return [f"{indent}{owner}.n_outside = None  # MCmatlab's faces: no Fresnel at the cuboid",
                    f"{indent}{target} = {e.code}"]
        if special == "medium_index":
            e = _minus_one(e)  # MCmatlab's media are numbered from 1
            return [f"{indent}{target} = {e.code}  # (0-based: MCmatlab's index minus 1)"]
        if special == "mc_P":
            line = self.src.span(node)[0]
            heat = any(ln > line and k == "hs" and v == m for ln, k, v in self.events)
            runs = any(ln > line and k == "mc" and v == m for ln, k, v in self.events)
            if heat and runs:
                return [f"{indent}{m}.MC.P = {m}.HS.P = {e.code}"]
            if heat:
                return [f"{indent}{m}.HS.P = {e.code}  # (MCmatlab's MC.P: the heat run's power)"]
        return [f"{indent}{target} = {e.code}"]

    def _st_Compound_Assignment_Statement(self, node, scope, indent):
        from miss_hit_core import m_ast

        names = []
        for lhs in node.l_lhs:
            if not isinstance(lhs, m_ast.Identifier):
                raise Unconvertible("a multiple assignment into indexed values")
            names.append(lhs.t_ident.value)
        e = self.ex(node.n_rhs, scope)
        kind = {"grids": "voxels", "shape": "int"}.get(e.kind)
        for n in names:
            if n != "~":
                scope.kinds[n] = kind
        targets = ", ".join("_" if n == "~" else py_name(n) for n in names)
        return [f"{indent}{targets} = {e.code}"]

    def _st_Naked_Expression_Statement(self, node, scope, indent):
        from miss_hit_core import m_ast

        expr = node.n_expr
        name = None
        if isinstance(expr, m_ast.Identifier):
            name = expr.t_ident.value
        elif isinstance(expr, m_ast.Reference | m_ast.Function_Call):
            n = expr.n_ident if isinstance(expr, m_ast.Reference) else expr.n_name
            name = n.t_ident.value if isinstance(n, m_ast.Identifier) else None
        args = list(getattr(expr, "l_args", []))
        if name == "tic" and not scope.has("tic"):
            self.imports.add("time")
            return [f"{indent}tic_ = time.perf_counter()"]
        if name == "toc" and not scope.has("toc"):
            self.imports.add("time")
            return [f'{indent}print(f"Elapsed time is {{time.perf_counter() - tic_:.6f}} '
                    'seconds.")']
        if name in ("fprintf", "disp", "error", "warning") and not scope.has(name):
            return self.output(name, args, scope, indent)
        if name == "clc" and not scope.has("clc"):
            raise Unconvertible("clc clears MATLAB's command window")
        return [f"{indent}{self.ex(expr, scope).code}"]

    def output(self, name, args, scope, indent):
        from miss_hit_core import m_ast

        if name == "disp":
            return [f"{indent}print({self.ex(args[0], scope).code})"]
        if name == "fprintf" and args and not isinstance(args[0], m_ast.Char_Array_Literal |
                                                             m_ast.String_Literal):
            if int_literal(args[0]) in (1, 2):
                args = args[1:]  # fprintf(1, ...) writes to the screen
            else:
                raise Unconvertible("fprintf to a file: use open() and write()")
        if name == "warning" and len(args) == 2 and isinstance(args[0], m_ast.Char_Array_Literal) \
                and args[0].t_string.value.lower() in ("on", "off"):
            raise Unconvertible("MATLAB's warning switches: Python's warnings.filterwarnings")
        newline = False
        if name == "fprintf" and isinstance(args[0], m_ast.Char_Array_Literal) and \
                args[0].t_string.value.endswith("\\n") and args[0].t_string.value.count("\\n") == 1:
            newline = True  # print's own newline stands for the format's last \n
        e = self.formatted(args, scope, strip_newline=newline)
        if name == "error":
            return [f"{indent}raise RuntimeError({e.code})"]
        if name == "warning":
            self.imports.add("warnings")
            return [f"{indent}warnings.warn({e.code}, stacklevel=1)"]
        return [f"{indent}print({e.code})" if newline else f'{indent}print({e.code}, end="")']

    # -- the file ------------------------------------------------------------------------
    def prescan(self, tree) -> None:
        """Roles of the functions, and where each model runs its Monte Carlo and heat."""
        from miss_hit_core import m_ast

        translator = self

        def register(fns):
            for fn in fns:
                self.functions[fn.n_sig.n_name.t_ident.value] = fn
                register(getattr(fn, "l_nested", []))

        register(tree.l_functions)

        class Scan(m_ast.AST_Visitor):
            def visit(self, n, parent, relation):
                if isinstance(n, m_ast.Simple_Assignment_Statement) and isinstance(
                        n.n_lhs, m_ast.Selection) and isinstance(n.n_rhs, m_ast.Function_Pointer):
                    try:
                        field = selection_chain(n.n_lhs)[-1]
                    except Unconvertible:
                        return
                    fname = getattr(n.n_rhs.n_name, "t_ident", None)
                    if fname is not None and field == "geomFunc":
                        translator.roles[fname.value] = "geometry"
                    elif fname is not None and field == "mediaPropertiesFunc":
                        translator.roles[fname.value] = "media"
                if isinstance(n, m_ast.Simple_Assignment_Statement) and isinstance(
                        n.n_lhs, m_ast.Selection):
                    try:
                        chain = selection_chain(n.n_lhs)
                    except Unconvertible:
                        return
                    if chain[-1] == "mediaPropParams":
                        translator.param_lines.append((n.loc().line, py_name(chain[0])))
                    if chain[-1] == "FRdepIterations":
                        translator.sets_fr_iterations.add(py_name(chain[0]))
                if isinstance(n, m_ast.Reference) and isinstance(n.n_ident, m_ast.Identifier):
                    name = n.n_ident.t_ident.value
                    kind = {"runMonteCarlo": "mc", "simulateHeatDistribution": "hs"}.get(name)
                    if kind and n.l_args and isinstance(n.l_args[0], m_ast.Identifier):
                        translator.events.append((n.loc().line, kind,
                                                  py_name(n.l_args[0].t_ident.value)))

        tree.visit(None, Scan(), "root")
        for name, fn in self.functions.items():
            if name not in self.roles and self.is_media_function(fn):
                self.roles[name] = "media"
            if self.roles.get(name) == "media" and self.fr_in_text(fn):
                self.fr_text_media.add(name)

    def translate(self, tree) -> tuple[list[str], list[str]]:
        """(function definitions, script body) as lines of Python."""
        from miss_hit_core import m_ast

        self.prescan(tree)
        body: list[str] = []
        last_script_line = 0
        self.preamble = []
        if isinstance(tree, m_ast.Script_File):
            script = Scope(role="script")
            stmts = tree.n_statements.l_statements
            if stmts:  # the comments above the first statement's paragraph describe the script
                start = self.src.span(stmts[0])[0]
                blank = max((n for n in range(1, start) if not self.src.lines[n - 1].strip()),
                            default=0)
                self.preamble = self.comments_before(0, blank + 1, "")
            body += self.block(tree.n_statements, script, "", 0)
            stmts = tree.n_statements.l_statements
            last_script_line = self.src.span(stmts[-1])[1] if stmts else 0
            body[:] = self.fill_settings(body)
        defs: list[str] = []
        prev = last_script_line
        for fn in tree.l_functions:
            first, last = self.src.span(fn)
            head = self.comments_before(prev, first, "")
            defs += ["", ""] + head + self.function(fn, "")
            prev = last
        return defs, body

    def fill_settings(self, body: list[str]) -> list[str]:
        """Replace the markers left after ``Model()`` by the settings the script needs there."""
        out = []
        for line in body:
            stripped = line.strip()
            if stripped.startswith("#@settings "):
                m = stripped.split()[1]
                indent = line[: len(line) - len(line.lstrip())]
                if m in self.needs_ni:
                    out.append(f"{indent}{m}.MC.calc_normalized_irradiance = True  # the script "
                               "reads NI_* (MCmatlab computes them always)")
                if self.media_funcs.get(m) in self.fr_text_media and \
                        m not in self.sets_fr_iterations:
                    out.append(f"{indent}{m}.MC.fr_dep_iterations = 20  # MCmatlab 3 iterated "
                               "media whose text holds FR 20 times (its FRdepIterations)")
                continue
            out.append(line)
        return out

    def function(self, fn, indent: str) -> list[str]:
        """A MATLAB function as a Python ``def`` (nested functions first in its body)."""
        name = fn.n_sig.n_name.t_ident.value
        role = self.roles.get(name, "function")
        if role == "media":
            return self.media_function(fn, indent)
        scope = Scope(role=role, parent=getattr(self, "_outer_scope", None))
        params = [p.t_ident.value for p in fn.n_sig.l_inputs]
        for k, p in enumerate(params):
            scope.kinds[p] = "voxels" if role == "geometry" and k < 3 else None
        outs = [o.t_ident.value for o in fn.n_sig.l_outputs]
        first, last = self.src.span(fn)
        head = f"{indent}def {py_name(name)}({', '.join(py_name(p) for p in params)}):"
        head += self.trailing(first, first)
        lines = [head]
        inner = indent + INDENT
        saved_outputs, self._outputs = getattr(self, "_outputs", []), [py_name(o) for o in outs]
        try:
            if role == "geometry":
                lines += self.geometry_body(fn, scope, inner, outs)
            else:
                for nested in getattr(fn, "l_nested", []):
                    lines += self.function(nested, inner) + [""]
                lines += self.block(fn.n_body, scope, inner, first, last)
                if outs:
                    lines.append(f"{inner}return {', '.join(py_name(o) for o in outs)}")
        finally:
            self._outputs = saved_outputs
        if len(lines) == 1:
            lines.append(f"{inner}pass")
        self.function_kinds[name] = scope.kinds.get(outs[0]) if outs else None
        return lines

    def geometry_body(self, fn, scope, indent, outs) -> list[str]:
        """A geometry function's body: media numbered from 0 (MCmatlab's from 1)."""
        first, last = self.src.span(fn)
        out = outs[0] if outs else None
        shift = out is not None and self.literal_media(fn.n_body, out)
        self._shift_media = out if shift else None
        try:
            lines = self.block(fn.n_body, scope, indent, first, last)
        finally:
            self._shift_media = None
        if out is None:
            return lines
        if shift:
            lines.append(f"{indent}return {py_name(out)}  # media numbered from 0 (MCmatlab: "
                         "from 1)")
        else:
            lines.append(f"{indent}return {py_name(out)} - 1  # MCmatlab numbers media from 1, "
                         "mcmatlab_py from 0")
        return lines


def _comment(text: str, indent: str) -> str:
    """A MATLAB comment's text as a Python comment; ``%%`` cells stay ``# %%`` cells."""
    if text.startswith("%"):
        return f"{indent}# %{text}".rstrip()
    return f"{indent}# {text.lstrip()}".rstrip() if text.strip() else f"{indent}#"


def _uses_last_input(fn) -> bool:
    """Whether ``fn``'s body reads its last input (a media function's ``parameters``)."""
    from miss_hit_core import m_ast

    inputs = fn.n_sig.l_inputs
    if not inputs:
        return False
    name = inputs[-1].t_ident.value
    found = []

    class V(m_ast.AST_Visitor):
        def visit(self, n, parent, relation):
            if isinstance(n, m_ast.Identifier) and n.t_ident.value == name and n is not inputs[-1]:
                found.append(n)

    fn.n_body.visit(None, V(), "root")
    return bool(found)


def _compound(node) -> bool:
    from miss_hit_core import m_ast

    return isinstance(node, m_ast.Compound_Statement)
