"""Sphinx configuration of the dolfin_mpm documentation (``make docs``)."""

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS))

import literate  # noqa: E402  (the demos as pages, beside this file)

project = "dolfin_mpm"
author = "dolfin_mpm contributors"
copyright = "dolfin_mpm contributors"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "sphinx.ext.mathjax",
    "sphinxcontrib.mermaid",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "README.md", "Thumbs.db", ".DS_Store"]

# Markdown: headings get anchors (links such as `numerics.md#transfers-flip`), `$...$` maths,
# and fenced mermaid blocks are diagrams.
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
myst_fence_as_directive = ["mermaid"]

# API reference: Google-style docstrings, members in source order.
napoleon_google_docstring = True
napoleon_numpy_docstring = False
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_typehints = "description"

html_theme = "furo"
html_title = "dolfin_mpm"
html_static_path = []


def _demo_pages(app):
    literate.write_pages(DOCS.parent / "demos", DOCS / "demos")


def setup(app):
    """Write the demos' pages when the build starts."""
    app.connect("builder-inited", _demo_pages)
