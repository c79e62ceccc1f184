"""Sphinx configuration of the sblsim documentation site (``sphinx-build -W docs OUT``).

Offline by construction: Sphinx's built-in alabaster theme with its own CSS and no web fonts, no MathJax
(the pages have no formulas to typeset), no intersphinx; every page is Markdown (MyST) or generated from the
code (the API reference from the docstrings, the CLI reference from the argument parser).
"""

project = "sblsim"
author = "the sblsim authors"
copyright = "the sblsim authors, MIT licence"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "numpydoc",
    "sphinxarg.ext",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "examples", "figures"]
myst_heading_anchors = 3
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
autodoc_member_order = "bysource"
html_theme = "alabaster"
html_theme_options = {"font_family": "sans-serif", "head_font_family": "sans-serif", "show_relbars": True}
html_static_path: list[str] = []
html_copy_source = False
nitpicky = False
suppress_warnings = ["myst.header"]
