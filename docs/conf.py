"""Sphinx configuration of the rhmpc documentation.

Build from the checkout (warnings are errors, as in CI); the ``docs`` extra, installed once,
provides Sphinx and its extensions, and the packages are imported from this checkout, so the
build needs no reinstall of rhmpc after an edit::

    .venv/bin/python -m sphinx -W -b html docs docs/_build/html

Choices:

* **The checkout, not the installed package**: the repository's root goes first on
  ``sys.path`` and the version is read from ``pyproject.toml``, so the API pages, the CLI
  reference and the gallery show the code being edited, whatever copy of rhmpc is installed
  (``rhmpc.robots``, ``rhmpc.predictors`` and ``rhmpc.sim``, whose folders are at the root,
  included: ``rhmpc`` imported from a checkout finds them in that checkout).
* **numpydoc** renders the API docstrings (the code is written in numpydoc style). Its
  validation is off and class members are not listed by numpydoc (autodoc lists them), so that
  reasonable docstrings build without warnings; ``numpydoc_xref_param_type`` stays off because
  the docstrings name types in prose ("ndarray, shape (n, 3)").
* **Dataclass fields** (``_ext/dataclass_fields.py``): every field of a dataclass gets its own
  entry on its class's page, inherited fields included, with its type, default, unit and
  meaning from the ``Attributes`` sections of the class and its bases.
* **API pages and links** (``_ext/api_links.py``): the pages of modules that were moved or
  deleted are removed before autosummary writes the current ones; a module named like the
  function its package re-exports (``rhmpc.robots.linearize``) gets its own page; a reference
  through a re-export (``rhmpc.sim.loop.LoopResult``) links to the page of the object where it
  is defined.
* **Typography**: quotes and ellipses are made typographic, dashes are not (prose types its
  dashes as the Unicode characters, and ``--`` is always a command-line option); the CLI
  reference, generated from the parser, keeps every character as typed, for copy and paste.
* **MathJax offline**: ``sphinx-mathjax-offline`` ships MathJax 3 in its wheel and points
  ``mathjax_path`` at the copy it puts in ``_static``; equations render without a network.
  Docstrings write equations as ``.. math::`` blocks and ``:math:`` roles (LaTeX).
* **Results** are included from ``docs/results/*.md``, which ``benchmarks/run_all.py`` writes
  next to the JSON files that hold every number (see ``docs/validation/index.md``).
"""

from __future__ import annotations

import os
import sys
import tomllib
from pathlib import Path

from sphinxarg.ext import ArgParseDirective

ROOT = Path(__file__).resolve().parents[1]
# The packages from this checkout, before any installed copy; the local extensions next.
sys.path[:0] = [str(ROOT), str(Path(__file__).parent / "_ext")]
os.environ.setdefault("MPLBACKEND", "Agg")

project = "rhmpc"
author = "rhmpc developers"
copyright = f"2026, {author}"
# The checkout's version (an installed copy's metadata may be older, or absent).
release = version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]

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
    "dataclass_fields",  # docs/_ext: every dataclass field on its class's page
    "api_links",  # docs/_ext: a page for every module that exists, links through re-exports
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "results/README.md", "gallery/*.ipynb", "gallery/*.py",
                    "gallery/*.zip", "gallery/*.json", "gallery/*.md5"]
root_doc = "index"

# Quotes and ellipses typographic, dashes as typed: ``--duration`` must not become an en dash.
smartquotes_action = "qe"

# MyST: $…$ and $$…$$ math, definition lists, heading anchors for cross-page links.
myst_enable_extensions = ["dollarmath", "amsmath", "deflist", "colon_fence", "attrs_inline"]
myst_heading_anchors = 3

# API: autosummary writes one stub page per module into api/_autosummary (not tracked).
autosummary_generate = True
autosummary_imported_members = False
# ``ignore-module-all``: a package's page lists what the package defines, not what its
# ``__all__`` re-exports from its modules (documented on their own pages; listing both would
# describe ``rhmpc.robots.linearize`` twice, as a function and as a module).
# Undocumented members are listed (the autosummary tables link to them) and so are the bases;
# autodoc's flag options are on whenever present, whatever their value, hence True.
autodoc_default_options = {"members": True, "undoc-members": True, "show-inheritance": True,
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


class VerbatimArgParse(ArgParseDirective):
    """The CLI reference as typed: no smart quotes in anything generated from the parser.

    Every option and every help string may be copied into a shell (``--set
    sensor_settings.playback="offline"``), so the quotes stay ASCII there too.
    """

    def run(self):
        generated = super().run()
        for node in generated:
            node["support_smartquotes"] = False  # read by Sphinx for the node and its children
        return generated


def setup(app):
    app.add_directive("argparse", VerbatimArgParse, override=True)
