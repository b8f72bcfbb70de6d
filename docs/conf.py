"""Sphinx configuration of the softarm-gym documentation (``make docs``; strict build in the tests)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).parent / "_ext"))

import softarm_gym  # noqa: E402

project = "softarm-gym"
author = "The softarm-gym authors"
release = version = softarm_gym.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "softarm_docstrings",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "**/README.md"]
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 4
autodoc_mock_imports = ["elastica"]

autodoc_member_order = "bysource"
autodoc_inherit_docstrings = False  # Gymnasium's and SB3's own docstrings are theirs to render
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True  # "Attributes:" as fields: NamedTuple fields are documented once
# An ivar field links its name, and NamedTuples of several modules share field names
# (converged, snapped, ...): Sphinx then finds more than one target and picks one. Only that
# ambiguity is silenced; missing pages, anchors and files still fail the build.
suppress_warnings = ["ref.python"]

html_theme = "furo"
html_title = f"softarm-gym {release}"
html_static_path = []
