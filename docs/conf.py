"""Sphinx configuration of the insnav documentation site (scripts/docs.sh).

Why Sphinx (and not MkDocs + mkdocstrings): the docstrings are numpydoc, whose
reference renderer is a Sphinx extension; autodoc documents the compiled
``insnav._core``-backed API from the imported package; MyST-NB executes the
tutorials (Markdown notebooks) at build time through a Jupyter kernel; MyST
includes the existing Markdown documents (docs/*.md, docs/results/*.md) as
they are; and ``-W --keep-going -n`` turns every warning, including a
cross-reference that resolves to nothing, into a build failure.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE / "_ext"))
# the tutorials read the third-party data from ../shared/data beside the repo
# (or $INSNAV_SHARED_DATA); the executing kernel inherits the environment
os.environ.setdefault("INSNAV_SHARED_DATA", str(REPO.parent / "shared" / "data"))
# the kernels draw figures inline (a MPLBACKEND=Agg from the caller would draw none)
os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
os.environ.setdefault("INSNAV_PROGRESS", "0")

import insnav  # noqa: E402

project = "insnav"
author = "the insnav developers"
copyright = "the insnav developers (MIT licence)"
version = release = insnav.__version__

extensions = [
    "myst_nb",                 # MyST Markdown + executed notebooks (includes myst_parser)
    "sphinx.ext.autodoc",
    "numpydoc",                # numpydoc docstrings
    "sphinx.ext.mathjax",
    "insnav_docs",             # _ext/insnav_docs.py: CLI and config references, generated
]
source_suffix = {".md": "myst-nb", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "_ext", "Thumbs.db", ".DS_Store", "**.ipynb_checkpoints"]
root_doc = "index"

myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
myst_dmath_double_inline = True

# every tutorial runs at every build; an error in any cell fails the build
nb_execution_mode = "force"
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_execution_timeout = 300
nb_execution_in_temp = True      # files the tutorials write go to a temporary directory
nb_merge_streams = True

autodoc_typehints = "none"       # the numpydoc Parameters sections carry types and units
autodoc_member_order = "bysource"
# (only "members": a default given here replaces the option a directive gives)
autodoc_default_options = {"members": True}
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set = set()

nitpicky = False  # (types in docstrings are prose like "3 floats", not references)
suppress_warnings: list = []

html_theme = "furo"
html_title = f"insnav {release}"
html_static_path: list = []
html_show_sourcelink = False

# numpydoc reports a docstring it cannot parse (an unknown section, a bad
# underline) as a Python warning; with -W it fails the build like any other.
import warnings  # noqa: E402

warnings.filterwarnings("error", category=UserWarning, module=r"numpydoc\..*")
