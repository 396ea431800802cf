"""MATLAB calls, indexing and property reads to Python: ``A(i)``, ``f(x)``, ``model.MC.NFR``.

The part of the expression translator that knows functions: MATLAB's builtins that
MCmatlab's models use (to numpy), MCmatlab's own (``runMonteCarlo``, ``plot(model, 'MC')``,
``combineModels``, ``calc_mua``, ``findInsideVoxels``, MCmatlab 3's ``plotMCmatlab``...)
and the plotting commands of a sweep's figure (to matplotlib).
"""

from __future__ import annotations

from .expr import ADD, ATOM, CMP, MUL, PRIMARY, E, ExprTranslator, Scope, py_name, py_string, wrap
from .names import (
    SPECIAL,
    Unconvertible,
    child_class,
    label,
    python_name,
    root_class,
)

__all__ = ["CallTranslator"]

#: name-value pairs of MATLAB's plot -> matplotlib's keywords
_PLOT_KEYWORDS = {"linewidth": "linewidth", "color": "color", "linestyle": "linestyle",
                  "marker": "marker", "markersize": "markersize", "displayname": "label"}
#: figure commands: MATLAB -> pyplot call
_PYPLOT = {"xlabel": "xlabel", "ylabel": "ylabel", "zlabel": None, "title": "title",
           "clf": "clf", "colorbar": "colorbar", "legend": "legend", "xlim": "xlim",
           "ylim": "ylim", "semilogy": "semilogy", "semilogx": "semilogx", "loglog": "loglog"}
#: MCmatlab's plot targets, MCmatlab 3's plot functions
_MCMATLAB3_PLOTS = {"plotMCmatlabGeom": "G", "plotMCmatlabHeat": "HS"}


class CallTranslator(ExprTranslator):
    """Calls, indexing, property paths."""

    #: model variables whose NI_* maps are read (MCmatlab computes them always; here only
    #: with MC.calc_normalized_irradiance)
    needs_ni: set

    # -- A(i), f(x), model.MC.x(i) -----------------------------------------------------------
    def _ex_Reference(self, node, scope):
        from miss_hit_core import m_ast

        name_node = node.n_ident
        if isinstance(name_node, m_ast.Identifier):
            name = name_node.t_ident.value
            if scope.has(name):
                return self.subscript(self.ex(name_node, scope), node.l_args, scope)
            return self.call(name, node.l_args, scope, node)
        if isinstance(name_node, m_ast.Selection):
            chain = selection_chain(name_node)
            if chain[0] == "MCmatlab":
                return self.call("MCmatlab." + ".".join(chain[1:]), node.l_args, scope, node)
            return self.subscript(self.ex(name_node, scope), node.l_args, scope)
        return self.subscript(self.ex(name_node, scope), node.l_args, scope)

    def subscript(self, base: E, args, scope) -> E:
        """``base(args)`` on an array: 0-based, column-major for one subscript into 3-D."""
        from miss_hit_core import m_ast

        if len(args) == 1 and isinstance(args[0], m_ast.Reshape):
            self.imports.add("np")
            return E(f"np.ravel({base.code}, order=\"F\")", PRIMARY, "vector")
        subs = [self.index(a, scope, base, k, len(args)) for k, a in enumerate(args)]
        if len(args) == 1 and base.kind in ("voxels", "array", "matrix") and \
                not self._is_bool(args[0], scope):
            # MATLAB's linear index runs down the columns: x fastest, as in base.T's rows
            return E(f"{wrap(base, PRIMARY)}.T.flat[{subs[0]}]", PRIMARY, None)
        kind = base.kind if any(":" in s for s in subs) or any(
            self._is_bool(a, scope) for a in args) else None
        return E(f"{wrap(base, PRIMARY)}[{', '.join(subs)}]", PRIMARY, kind)

    def _is_bool(self, node, scope) -> bool:
        from miss_hit_core import m_ast

        if isinstance(node, m_ast.Reshape | m_ast.Range_Expression):
            return False
        try:
            return self.ex(node, scope).kind == "bool"
        except Unconvertible:
            return False

    # -- a.b.c -----------------------------------------------------------------------------
    def _ex_Selection(self, node, scope):
        chain = selection_chain(node)
        if chain[0] == "MCmatlab":
            if chain[1:] == ["model"]:
                self.imports.add("Model")
                return E("Model()", PRIMARY, "model")
            return self.call("MCmatlab." + ".".join(chain[1:]), [], scope, node)
        if scope.kind(chain[0]) == "model":
            return self.model_path(chain, write=False)
        return E(".".join(py_name(c) for c in chain), PRIMARY, None)

    def model_path(self, chain: list[str], write: bool):
        """``model.MC.lightSource.xFocus`` -> ``model.MC.light_source.x_focus``.

        Returns an :class:`E` for a read; for a write, ``(code, special)`` with the name of
        the :data:`SPECIAL` rule that applies, if any.
        """
        root = py_name(chain[0])
        if len(chain) == 1:
            return (root, None) if write else E(root, ATOM, "model")
        cls = root_class(chain[1])
        parts = [root, chain[1]]
        special = None
        for name in chain[2:]:
            rule = SPECIAL.get((label(cls), name))
            if rule is not None and name == chain[-1]:
                special = rule
                if rule == "hs_T":
                    parts.append("T_initial" if write else "T_voxels")
                    break
                if rule == "hs_Omega" and not write:
                    parts.append("Omega_voxels")
                    break
                if rule == "m_raw" and not write:
                    return E(f"({'.'.join(parts)}.medium_map() + 1)", ATOM, "voxels")
                if rule == "FR":
                    parts.append("FR")
                    break
                if rule == "mc_P":
                    parts.append("P")
                    break
                if rule in ("media_func", "media_params", "silent", "all_cpus"):
                    if not write:
                        raise Unconvertible(f"reading MCmatlab's {label(cls)}.{name}")
                    return ".".join([*parts, name]), rule
            py = python_name(cls, name)
            parts.append(py)
            if py.startswith("NI_") and not write:
                self.needs_ni.add(root)
            nxt = child_class(cls, py)
            if nxt is None and name != chain[-1]:
                # a field of a plain value (an array's attribute): leave the rest as it is
                parts.extend(chain[chain.index(name) + 1:])
                break
            cls = nxt if nxt is not None else cls
        code = ".".join(parts)
        return (code, special) if write else E(code, PRIMARY, None)

    # -- command form: grid on, hold on, close all -------------------------------------------
    def _ex_Function_Call(self, node, scope):
        name = node.n_name.t_ident.value
        return self.call(name, node.l_args, scope, node)

    # -- calls -----------------------------------------------------------------------------
    def args(self, nodes, scope) -> list[E]:
        return [self.ex(a, scope) for a in nodes]

    def call(self, name: str, nodes, scope: Scope, node) -> E:  # noqa: C901 (a dispatch table)
        """``name(nodes...)``: a function of this file, a builtin, or MCmatlab's."""
        if name in self.functions:
            args = self.args(nodes, scope)
            return E(f"{py_name(name)}({', '.join(a.code for a in args)})", PRIMARY,
                     self.function_kinds.get(name))
        np_ = self._np
        if name in ("zeros", "ones", "NaN", "nan", "Inf", "inf", "rand", "randn", "true",
                    "false"):
            return self.filled(name, nodes, scope)
        if name == "size":
            a = self.args(nodes, scope)
            if len(a) == 1:
                return E(f"{wrap(a[0], PRIMARY)}.shape", PRIMARY, "shape")
            return E(f"{wrap(a[0], PRIMARY)}.shape[{_minus1(a[1])}]", PRIMARY, "int")
        if name in ("numel", "length"):
            (a,) = self.args(nodes, scope)
            return E(f"{np_('size')}({a.code})" if name == "numel" else f"len({a.code})",
                     PRIMARY, "int")
        if name == "isempty":
            (a,) = self.args(nodes, scope)
            return E(f"{np_('size')}({a.code}) == 0", CMP, "bool")
        if name in ("linspace", "logspace"):
            a = self.args(nodes, scope)
            n = a[2].code if len(a) > 2 else ("100" if name == "linspace" else "50")
            return E(f"{np_(name)}({a[0].code}, {a[1].code}, {n})", PRIMARY, "vector")
        if name in ("ndgrid", "meshgrid"):
            a = self.args(nodes, scope)
            extra = ', indexing="ij"' if name == "ndgrid" else ""
            return E(f"{np_('meshgrid')}({', '.join(x.code for x in a)}{extra})", PRIMARY,
                     "grids")
        if name == "eye":
            a = self.args(nodes, scope)
            return E(f"{np_('eye')}({', '.join(x.code for x in a)})", PRIMARY, "matrix")
        if name in ("max", "min"):
            a = self.args(nodes, scope)
            if len(a) == 2:
                return E(f"{np_(name + 'imum')}({a[0].code}, {a[1].code})", PRIMARY, _kind2(a))
            if len(a) == 1:
                return E(f"{np_(name)}({self._whole(nodes[0], a[0], scope)})", PRIMARY, "scalar")
            return E(f"{np_(name)}({a[0].code}, axis={_minus1(a[2])})", PRIMARY, None)
        if name in _REDUCE or name == "std":
            a = self.args(nodes, scope)
            extra = ", ddof=1" if name == "std" else ""
            if len(a) == 1:
                whole = self._whole(nodes[0], a[0], scope)
                axis = ", axis=0" if a[0].kind == "voxels" and whole == a[0].code else ""
                return E(f"{np_(_REDUCE.get(name, name))}({whole}{axis}{extra})", PRIMARY,
                         "scalar")
            if name == "std":
                raise Unconvertible("std with a weight or dimension")
            return E(f"{np_(_REDUCE[name])}({a[0].code}, axis={_minus1(a[1])})", PRIMARY, None)
        from .expr import _ELEMENTWISE

        if name in _ELEMENTWISE:
            a = self.args(nodes, scope)
            return E(f"{np_(_ELEMENTWISE[name])}({', '.join(x.code for x in a)})", PRIMARY,
                     _kind2(a))
        if name in ("calc_mua", "calc_mus"):
            self.imports.add(name)
            a = self.args(nodes, scope)
            return E(f"{name}({', '.join(x.code for x in a)})", PRIMARY, None)
        if name == "findInsideVoxels":
            self.imports.add("find_inside_voxels")
            a = self.args(nodes, scope)
            return E(f"find_inside_voxels({', '.join(x.code for x in a)})", PRIMARY, "bool")
        if name == "interp1":
            a = self.args(nodes, scope)
            if len(a) == 3 or (len(a) == 4 and a[3].code.strip('"').lower() == "linear"):
                return E(f"{np_('interp')}({a[2].code}, {a[0].code}, {a[1].code}, left=np.nan, "
                         "right=np.nan)", PRIMARY, None)
            if len(a) == 5 and a[3].code.strip('"').lower() == "linear":
                return E(f"{np_('interp')}({a[2].code}, {a[0].code}, {a[1].code}, "
                         f"left={a[4].code}, right={a[4].code})", PRIMARY, None)
            raise Unconvertible("interp1 other than linear")
        if name == "readtable":
            self.imports.add("readtable")
            a = self.args(nodes, scope)
            if len(a) != 1:
                raise Unconvertible("readtable with options")
            return E(f"readtable({a[0].code})", PRIMARY, None)
        if name in ("num2str", "int2str"):
            a = self.args(nodes, scope)
            if len(a) == 2:
                return E(f"{wrap(a[1], MUL + 1)} % {wrap(a[0], MUL + 1)}", MUL, "str")
            return E(f"str({a[0].code})", PRIMARY, "str")
        if name == "sprintf":
            return self.formatted(nodes, scope)
        if name == "toc":
            self.imports.add("time")
            return E("time.perf_counter() - tic_", ADD, "scalar")
        if name in ("runMonteCarlo", "simulateHeatDistribution", "plot", "reset",
                    "combineModels", "plotMCmatlab", "MCmatlab.plotAzFz",
                    "MCmatlab.plotRadialReflectanceTransmittance", "MCmatlab.closeMCmatlabFigures",
                    "closeMCmatlabFigures", *_MCMATLAB3_PLOTS):
            return self.mcmatlab_call(name, nodes, scope)
        if name in _PYPLOT and _PYPLOT[name] is not None:
            self.imports.add("plt")
            a = self.args(nodes, scope)
            return E(f"plt.{_PYPLOT[name]}({', '.join(x.code for x in a)})", PRIMARY, None)
        if name == "figure":
            if nodes:
                raise Unconvertible("MCmatlab's figure numbers: model.plot returns "
                                    "{name: Figure} instead (figure(n) only brings one forward)")
            self.imports.add("plt")
            return E("plt.figure()", PRIMARY, None)
        if name == "drawnow":
            self.imports.add("plt")
            return E("plt.pause(0.001)", PRIMARY, None)
        if name == "grid":
            self.imports.add("plt")
            what = self.args(nodes, scope)[0].code.strip('"') if nodes else "on"
            if what == "minor":
                return E("plt.minorticks_on()", PRIMARY, None)
            return E(f"plt.grid({what != 'off'})", PRIMARY, None)
        if name == "close":
            self.imports.add("plt")
            a = self.args(nodes, scope)
            return E(f"plt.close({', '.join(x.code for x in a)})", PRIMARY, None)
        if name == "pause" and nodes:
            self.imports.add("time")
            (a,) = self.args(nodes, scope)
            return E(f"time.sleep({a.code})", PRIMARY, None)
        raise Unconvertible(_UNKNOWN.get(name, f"{name}(...): neither a function of this file "
                                               "nor one the converter knows"))

    def _np(self, name: str) -> str:
        self.imports.add("np")
        return f"np.{name}"

    def _whole(self, node, e: E, scope) -> str:
        """``x(:)`` inside a reduction is the whole array."""
        from miss_hit_core import m_ast

        if (isinstance(node, m_ast.Reference) and len(node.l_args) == 1
                and isinstance(node.l_args[0], m_ast.Reshape)):
            return self.ex(node.n_ident, scope).code
        return e.code

    def filled(self, name: str, nodes, scope) -> E:
        """``zeros(size(X))``, ``ones(1, n)``, ``NaN(a, b, c)``, ``rand(...)``."""
        from miss_hit_core import m_ast

        a = self.args(nodes, scope)
        kind = "array"
        if not a:
            shape = None
        elif len(a) == 1 and a[0].kind == "shape":
            shape = a[0].code
            base = nodes[0].l_args[0] if isinstance(nodes[0], m_ast.Reference) else None
            if base is not None and self.ex(base, scope).kind == "voxels":
                kind = "voxels"
        elif len(a) == 1:
            shape = f"({a[0].code}, {a[0].code})"
        elif len(a) == 2 and (a[0].code == "1" or a[1].code == "1"):
            shape = a[1].code if a[0].code == "1" else a[0].code  # a vector: 1-D here
            kind = "vector"
        else:
            shape = "(" + ", ".join(x.code for x in a) + ")"
        np_ = self._np
        if shape is None:
            scalar = {"zeros": "0.0", "ones": "1.0", "NaN": "np.nan", "nan": "np.nan",
                      "Inf": "np.inf", "inf": "np.inf", "true": "True", "false": "False"}
            if name in scalar:
                return E(scalar[name], ATOM, "scalar")
            self.imports.add("rng")
            return E(f"rng.{'random' if name == 'rand' else 'standard_normal'}()", PRIMARY,
                     "scalar")
        if name in ("zeros", "ones"):
            return E(f"{np_(name)}({shape})", PRIMARY, kind)
        if name in ("rand", "randn"):
            self.imports.add("rng")
            return E(f"rng.{'random' if name == 'rand' else 'standard_normal'}({shape})",
                     PRIMARY, kind)
        fill = {"NaN": "np.nan", "nan": "np.nan", "Inf": "np.inf", "inf": "np.inf",
                "true": "True", "false": "False"}[name]
        return E(f"{np_('full')}({shape}, {fill})", PRIMARY, "bool" if fill in (
            "True", "False") else kind)

    def formatted(self, nodes, scope, escapes: bool = True, strip_newline: bool = False) -> E:
        """``sprintf(fmt, args...)`` -> ``fmt % (args,)`` (``strip_newline``: without the
        format's final ``\\n``)."""
        from miss_hit_core import m_ast

        fmt_node, rest = nodes[0], nodes[1:]
        if isinstance(fmt_node, m_ast.Char_Array_Literal | m_ast.String_Literal):
            text = fmt_node.t_string.value.replace("''", "'")
            if strip_newline:
                text = text[:-2]
            fmt = py_string(text, escapes=escapes)
        else:
            fmt = self.ex(fmt_node, scope)
        args = self.args(rest, scope)
        if not args:
            return E(fmt.code.replace("%%", "%"), fmt.prec, "str")
        if len(args) == 1:
            return E(f"{wrap(fmt, MUL + 1)} % {wrap(args[0], MUL + 1)}", MUL, "str")
        return E(f"{wrap(fmt, MUL + 1)} % ({', '.join(a.code for a in args)})", MUL, "str")

    def mcmatlab_call(self, name: str, nodes, scope) -> E:
        a = self.args(nodes, scope)
        if name in ("MCmatlab.closeMCmatlabFigures", "closeMCmatlabFigures"):
            self.imports.add("plt")
            return E('plt.close("all")', PRIMARY, None)
        if name == "MCmatlab.plotAzFz":
            self.imports.add("plot_az_fz")
            return E(f"plot_az_fz({a[0].code})", PRIMARY, None)
        if name == "MCmatlab.plotRadialReflectanceTransmittance":
            self.imports.add("plot_radial_reflectance_transmittance")
            self.needs_ni.add(a[0].code)
            return E(f"plot_radial_reflectance_transmittance({a[0].code})", PRIMARY, None)
        if name == "combineModels":
            self.imports.add("combine_models")
            what = a[1].code if len(a) > 1 else '"MC"'
            return E(f"combine_models({a[0].code}, simulation={what})", PRIMARY, "model")
        if not a or a[0].kind != "model":
            if name == "plot":
                return self.line_plot(nodes, a)
            raise Unconvertible(f"{name}(...) whose first argument is not a MCmatlab model")
        m = wrap(a[0], PRIMARY)
        if name == "runMonteCarlo":
            kind = "" if len(a) == 1 else a[1].code
            return E(f"{m}.run_monte_carlo({kind})", PRIMARY, "model")
        if name == "simulateHeatDistribution":
            return E(f"{m}.simulate_heat_distribution()", PRIMARY, "model")
        if name == "reset":
            return E(f"{m}.reset({a[1].code if len(a) > 1 else ''})", PRIMARY, "model")
        if name == "plotMCmatlab":
            what = '"FMC"' if len(a) > 1 and "fluor" in a[1].code else '"MC"'
            return E(f"{m}.plot({what})", PRIMARY, "figures")
        if name in _MCMATLAB3_PLOTS:
            return E(f'{m}.plot("{_MCMATLAB3_PLOTS[name]}")', PRIMARY, "figures")
        # plot(model, 'MC')
        what = a[1].code if len(a) > 1 else ""
        return E(f"{m}.plot({what})", PRIMARY, "figures")

    def line_plot(self, nodes, a: list[E]) -> E:
        """MATLAB's ``plot(x, y, 'LineWidth', 2)`` -> ``plt.plot(x, y, linewidth=2)``."""
        self.imports.add("plt")
        positional, keywords = [], []
        k = 0
        while k < len(a):
            e = a[k]
            key = e.code.strip('"').lower() if e.kind == "str" else None
            if key in _PLOT_KEYWORDS and k + 1 < len(a):
                keywords.append(f"{_PLOT_KEYWORDS[key]}={a[k + 1].code}")
                k += 2
                continue
            if key is not None and not positional:
                raise Unconvertible(f"plot's option {e.code}")
            positional.append(e.code)
            k += 1
        return E(f"plt.plot({', '.join(positional + keywords)})", PRIMARY, None)


_REDUCE = {"sum": "sum", "mean": "mean", "prod": "prod", "any": "any", "all": "all",
           "median": "median", "cumsum": "cumsum", "std": "std"}
_UNKNOWN = {
    "set": "set(...) styles a MATLAB figure: style the matplotlib figure instead",
    "hold": "matplotlib keeps the earlier lines of a figure: no 'hold' is needed",
    "pause": "pause waits for a key in MATLAB: the converted script does not stop (run it with "
             "python -i, or add input())",
    "axis": "axis(...): use plt.axis(...)",
    "MCmatlab.NdimSliderPlot": "use mcmatlab_py.plotting.slice_viewer.slice_viewer(data, G)",
}


def _minus1(e: E) -> str:
    return str(int(e.code) - 1) if e.kind == "int" and e.code.lstrip("-").isdigit() else \
        f"{wrap(e, ADD)} - 1"


def _kind2(a: list[E]):
    kinds = {x.kind for x in a}
    if "voxels" in kinds:
        return "voxels"
    if kinds <= {"int", "scalar"}:
        return "scalar"
    return None


def selection_chain(node) -> list[str]:
    """``a.b.c`` -> ``["a", "b", "c"]`` (Unconvertible for ``a(1).b`` and dynamic fields)."""
    from miss_hit_core import m_ast

    parts = []
    while isinstance(node, m_ast.Selection):
        parts.append(node.n_field.t_ident.value)
        node = node.n_prefix
    if not isinstance(node, m_ast.Identifier):
        raise Unconvertible("a field of an indexed value (a(1).b)")
    parts.append(node.t_ident.value)
    return parts[::-1]
