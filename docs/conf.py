"""Sphinx configuration of the rhmpc documentation.

Build (warnings are errors, as in CI)::

    .venv/bin/python -m sphinx -W -b html docs docs/_build/html

Choices:

* **numpydoc** renders the API docstrings (the code is written in numpydoc style). Its
  validation is off and class members are not listed by numpydoc (autodoc lists them), so that
  reasonable docstrings build without warnings; ``numpydoc_xref_param_type`` stays off because
  the docstrings name types in prose ("ndarray, shape (n, 3)").
* **MathJax offline**: ``sphinx-mathjax-offline`` ships MathJax 3 in its wheel and points
  ``mathjax_path`` at the copy it puts in ``_static``; equations render without a network.
* **Results** are included from ``docs/results/*.md``, which ``benchmarks/run_all.py`` writes
  next to the JSON files that hold every number (see ``docs/validation/index.md``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")

from rhmpc import __version__  # noqa: E402

project = "rhmpc"
author = "rhmpc developers"
copyright = f"2026, {author}"
release = version = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.intersphinx",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",
    "numpydoc",
    "sphinxarg.ext",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "results/README.md", "gallery/*.ipynb", "gallery/*.py",
                    "gallery/*.zip", "gallery/*.json", "gallery/*.md5"]
root_doc = "index"

# MyST: $…$ and $$…$$ math, definition lists, heading anchors for cross-page links.
myst_enable_extensions = ["dollarmath", "amsmath", "deflist", "colon_fence", "attrs_inline"]
myst_heading_anchors = 3

# API: autosummary writes one stub page per module into api/_autosummary (not tracked).
autosummary_generate = True
autosummary_imported_members = False
# ``ignore-module-all``: a package's page lists what the package defines, not what its
# ``__all__`` re-exports from its modules (documented on their own pages; listing both would
# describe ``robots.linearize`` twice, as a function and as a module).
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False,
                           "ignore-module-all": True}
autodoc_typehints = "none"
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_validation_checks: set[str] = set()
numpydoc_xref_param_type = False
numpydoc_attributes_as_param_list = True

intersphinx_mapping: dict[str, tuple[str, None]] = {}

sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "gallery",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "matplotlib_animations": False,
    "show_memory": False,
    "parallel": False,
    "reset_modules": ("matplotlib",),
    "within_subsection_order": "FileNameSortKey",
}

html_theme = "pydata_sphinx_theme"
html_title = f"rhmpc {release}"
html_static_path = ["_static"]
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "header_links_before_dropdown": 8,
    "secondary_sidebar_items": [],  # the article gets the width (wide tables, long commands)
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
}
html_sidebars = {"**": ["sidebar-nav-bs"], "index": [], "changelog": []}
html_show_sourcelink = False
html_css_files = ["custom.css"]
