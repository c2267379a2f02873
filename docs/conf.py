"""Sphinx configuration of the posecrb documentation (``make docs``).

The build is offline (no intersphinx, no remote images or fonts) and runs with warnings as errors
(``sphinx -W``), here and in the test suite (tests/docs/test_site.py).
"""
from __future__ import annotations

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "_ext"))
sys.path.insert(0, os.path.dirname(HERE))   # the checkout's posecrb, also without an install

import posecrb  # noqa: E402

project = "posecrb"
author = "The posecrb maintainers"
copyright = "2026, The posecrb maintainers"
version = release = posecrb.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "numpydoc",
    "sphinx_click",
    "posecrb_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
templates_path: list[str] = []
html_static_path = ["_static"]
html_css_files = ["posecrb.css"]   # the layout: one sidebar, a content column wide enough for code

# No "smart" typography: it turns the ``--`` of option names in prose and in the CLI reference
# (``--data-dir``) into en-dashes, which break when copied. Dashes and quotes stay as written.
smartquotes = False

# MyST: heading anchors for in-page links such as [noise model](#noise-model) and
# [a section](getting-started.md#reading-a-status).
myst_heading_anchors = 4
myst_enable_extensions = ["deflist"]

# autodoc + numpydoc (API reference generated from posecrb.__all__ by posecrb_docs)
autodoc_typehints = "signature"     # the typed signatures (choices as their Literal); numpydoc's Parameters say more
autodoc_typehints_format = "short"
autodoc_member_order = "bysource"
autodoc_preserve_defaults = True    # signatures show ``lb_status=OK`` as written, not the object's repr
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False

html_theme = "pydata_sphinx_theme"
html_title = f"posecrb {release}"
# One sidebar, on the left: the section's pages, then this page's contents. The right-hand
# sidebar is dropped so that the content column holds code blocks, tables and figures at 1400 px
# without horizontal scrolling.
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": [],
    "show_prev_next": True,
    "github_url": "https://github.com/posecrb/posecrb",   # where the code is, on every page
}
html_sidebars = {"**": ["sidebar-nav-bs", "page-toc"]}   # thinned per page by posecrb_docs
