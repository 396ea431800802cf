"""Sphinx configuration of the tissue-enkf documentation site.

Build: ``sphinx-build -W -b html docs docs/_build/html`` (warnings are errors).
Nothing here runs a Monte Carlo or a heat simulation: the gallery shows the figures
stored in ``docs/gallery/`` with each script's source, and the API pages import the
packages only.
"""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS / "_ext"))

project = "tissue-enkf"
author = "the tissue-enkf authors"
copyright = "the tissue-enkf authors, MIT license"  # noqa: A001 (Sphinx's name)

try:
    from importlib.metadata import version as _version

    release = _version("tissue-enkf")
except Exception:  # a checkout that is not installed
    release = "unknown"
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "tissue_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_templates", "_ext", "Thumbs.db", ".DS_Store"]
templates_path = ["_templates"]

# --- markdown -----------------------------------------------------------------------
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3  # links to sections as page.md#a-heading

# --- API reference ------------------------------------------------------------------
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "none"  # numpydoc shows the types from the docstrings
autodoc_mock_imports = ["pyvista", "dask", "distributed", "numba.cuda"]
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set[str] = set()

# --- HTML ---------------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = f"tissue-enkf {release}"
html_static_path = ["_static"]
html_css_files = ["custom.css"]
html_theme_options = {
    "navigation_depth": 2,
    "show_toc_level": 2,
    "header_links_before_dropdown": 7,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
}
html_show_sourcelink = False
