"""Sphinx configuration. Build: ``python -m sphinx -W -b html docs docs/_build/html``."""

import dolfinx_nnqem  # noqa: F401  (the PyPI wheel needs it before dolfinx is imported by autodoc)

project = "dolfinx_nnqem"
author = "dolfinx_nnqem developers"
release = dolfinx_nnqem.__version__
extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon", "sphinx.ext.mathjax"]
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build"]
autodoc_member_order = "bysource"
autodoc_typehints = "none"
napoleon_numpy_docstring = True
napoleon_google_docstring = False
napoleon_use_ivar = True  # "Attributes" sections as fields: NamedTuple fields are documented once
html_theme = "alabaster"
suppress_warnings = ["myst.header"]


def _escape_bars(app, what, name, obj, options, lines):
    # docstrings write norms as |x|, which reStructuredText would read as substitutions
    lines[:] = [line.replace("|", r"\|") for line in lines]


def setup(app):
    app.connect("autodoc-process-docstring", _escape_bars)
