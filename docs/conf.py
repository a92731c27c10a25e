"""Sphinx configuration of sb3_classic's documentation: MyST Markdown pages, the furo theme, autodoc from the
package's Sphinx ``:param:`` docstrings. Built with warnings as errors (``tests/test_docs.py``):
``sphinx-build -W --keep-going -b html docs docs/_build/html``."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# The checkout's package and its benchmarks/ (an editable install has the package already)
sys.path.insert(0, str(ROOT))

import sb3_classic  # noqa: E402

project = "sb3_classic"
author = "sb3_classic developers"
copyright = "sb3_classic developers"
version = release = sb3_classic.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.extlinks",
    "sphinx.ext.mathjax",
    # MathJax from the docs extra's own copy, not a CDN: the maths renders offline
    "sphinx-mathjax-offline",
]

source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]

# MyST: $…$ maths, tables, anchors for the headings of every page (links such as guide/design.md#anchor)
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

# Links to the repository's files that are not pages of this site (results, YAMLs, scripts):
# {repo}`benchmarks/results/learning.md`. tests/test_docs.py checks that every such path exists.
REPOSITORY = "https://github.com/sb3-classic/sb3_classic"
extlinks = {"repo": (f"{REPOSITORY}/blob/main/%s", "%s")}

# autodoc: the classes' and functions' docstrings as written (Sphinx :param: fields); the constructor's arguments are
# in the class docstring, as in SB3 and sb3-contrib
autoclass_content = "class"
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_description_target = "documented"
autodoc_inherit_docstrings = True
# The annotations name SB3's and PyTorch's types, which this site does not document (no intersphinx: the build is
# offline); they are shown as written, without a link
nitpicky = False

# The sdist leaves the benchmarks' figures out (they stay in the repository): there the pages build without them
if not (ROOT / "benchmarks" / "results" / "Acrobot-v1-steps.png").exists():
    suppress_warnings = ["image.not_readable"]

html_theme = "furo"
html_title = f"sb3_classic {release}"
html_static_path: list[str] = []
