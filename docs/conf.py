"""Sphinx configuration: the quadctl documentation, built from docs/ (``sphinx-build -W -n docs docs/_build/html``).

Pages are MyST Markdown, so every page reads on GitHub and in a clone as it does on the site, and
its fenced blocks run in the test suite (tests/docs/test_doc_pages.py). The reference pages are written
from the code at build time (docs/_ext/quadctl_reference.py: the typer app, the config's schema;
sphinx.ext.autodoc: the docstrings). The built site fetches nothing: the theme (furo) ships its CSS,
JS and icons, no web fonts, and no page uses math (MathJax would come from a CDN).
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
sys.path.insert(0, str(HERE.parent))  # the checkout's quadctl, ahead of an installed one

import quadctl  # noqa: E402

project = "quadctl"
author = "the quadctl developers"
copyright = "2026, the quadctl developers (MIT licence)"
release = version = quadctl.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "quadctl_reference",
]

source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_ext", "configs", "Thumbs.db", ".DS_Store"]

# GitHub's heading anchors (page.md#a-heading), so a link reads the same in a clone and on the site
myst_heading_anchors = 4
myst_enable_extensions = ["colon_fence"]

# numpydoc-style docstrings through napoleon: parameter types as text, not cross-references (they
# name shapes and units: "(M, M) array_like", "float, s")
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_param = False
napoleon_use_rtype = False
napoleon_preprocess_types = False
autodoc_typehints = "none"
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}

# furo: a theme from PyPI whose pages work offline (its CSS, JS and icons are local files; it loads
# no web fonts); the built-in alabaster would too, but has no dark mode and no sidebar search
html_theme = "furo"
html_title = f"quadctl {release}"
html_static_path: list[str] = []
html_last_updated_fmt = None
html_show_sourcelink = False
html_copy_source = False
html_show_sphinx = False  # the footer links to sphinx-doc.org and the theme's site: the site links nowhere outside
# no typographic quotes and dashes: "--set" in a help text stays two hyphens, as it is typed
smartquotes = False
