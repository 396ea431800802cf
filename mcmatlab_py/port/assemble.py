"""The converted script put together: docstring, imports, functions, the script's body."""

from __future__ import annotations

__all__ = ["assemble"]

#: what the translator asked for -> the import line that gives it
_IMPORTS = {
    "copy": "import copy",
    "time": "import time",
    "warnings": "import warnings",
    "np": "import numpy as np",
    "plt": "import matplotlib.pyplot as plt",
}
_FROM = {  # name -> module
    "Model": "mcmatlab_py", "Medium": "mcmatlab_py", "calc_mua": "mcmatlab_py",
    "calc_mus": "mcmatlab_py", "find_inside_voxels": "mcmatlab_py",
    "combine_models": "mcmatlab_py.combine",
    "plot_az_fz": "mcmatlab_py.plotting.outputs",
    "plot_radial_reflectance_transmittance": "mcmatlab_py.plotting.outputs",
    "quick": "mcmatlab_py.port.runtime", "readtable": "mcmatlab_py.port.runtime",
}


def assemble(name: str, tr, defs: list[str], body: list[str]) -> str:
    imports = set(tr.imports)
    shows = any("plt." in line or ".plot(" in line for line in defs + body)
    if shows:
        imports.add("plt")
    if "rng" in imports:
        imports.add("np")
    doc = [f'"""{name} converted to Python (mcmatlab_py) by `tissue-enkf port`.', ""]
    doc += ["Media are numbered from 0 here (MCmatlab's medium j is media[j - 1]); MCmatlab's",
            "settings carry their snake_case names (docs/mcmatlab_names.md)."]
    if tr.unconverted:
        doc += ["", "Not converted (kept as comments marked 'MATLAB (line N, not converted'):"]
        for line, text, why in sorted(tr.unconverted):
            first = " ".join(text.split())
            if len(first) > 60:
                first = first[:57] + "..."
            doc.append(f"  line {line}: {first} -- {why}")
    doc.append('"""')
    lines = [d.replace("\\", "\\\\") for d in doc]
    std = sorted(_IMPORTS[k] for k in ("copy", "time", "warnings") if k in imports)
    third = [_IMPORTS[k] for k in ("plt", "np") if k in imports]
    modules: dict[str, list[str]] = {}
    for n in sorted(imports):
        if n in _FROM:
            modules.setdefault(_FROM[n], []).append(n)
    own = [f"from {m} import {', '.join(sorted(ns, key=lambda n: (n[:1].islower(), n)))}"
           for m, ns in sorted(modules.items())]
    lines.append("")
    for group in (std, third, own):
        if group:
            lines += group + [""]
    if "rng" in imports:
        lines += ["rng = np.random.default_rng()  # MATLAB's rand", ""]
    while lines and lines[-1] == "":
        lines.pop()
    if tr.preamble:
        lines += ["", ""] + tr.preamble
    lines += defs
    lines += ["", ""] + body
    if shows:
        lines += ["", "plt.show()  # MCmatlab leaves its figures open"]
    text = "\n".join(line.rstrip() for line in lines).rstrip() + "\n"
    while "\n\n\n\n" in text:
        text = text.replace("\n\n\n\n", "\n\n\n")
    return text
