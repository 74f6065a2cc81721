"""Sphinx configuration of the dpht manual (``make docs``; the test suite builds it with -W)."""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(ROOT))

project = "dpht"
author = "the dpht authors"
copyright = "the dpht authors; GPL-3.0-or-later"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "generated_pages",
    "sphinx_gallery.gen_gallery",
]

# The gallery's pages are reStructuredText that sphinx-gallery writes into gallery/ from the
# scripts in examples/ (run at every build, on the tiny data in examples/data/).
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "_generated", "examples"]
sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "gallery",
    "filename_pattern": r"/plot_",  # every example runs
    "run_stale_examples": True,  # at every build (a few seconds), not only when its script changed
    "abort_on_example_error": True,  # and a failing one fails the build
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
}
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
html_theme = "furo"
html_title = "dpht manual"
html_static_path: list[str] = []
# The API pages document functions, not the module-level constants they read.
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_typehints = "description"
autodoc_member_order = "bysource"
napoleon_google_docstring = True
napoleon_numpy_docstring = True
# Offline build: no intersphinx, no remote images.
suppress_warnings: list[str] = []
