"""Sphinx configuration for the warptissue documentation (MyST Markdown pages)."""

from __future__ import annotations

import importlib
import pkgutil
import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent

# `python -m sphinx` run from the checkout puts the checkout first on sys.path, where the
# device code is the top-level folder kernels/, not the installed warptissue.kernels: document
# the installed package (an editable install maps both itself).
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != ROOT]
sys.path.insert(0, str(DOCS / "_ext"))

from sphinx.pycode import ModuleAnalyzer  # noqa: E402

from warptissue import __version__  # noqa: E402

project = "warptissue"
author = "the warptissue developers"
copyright = "the warptissue developers"  # noqa: A001
release = __version__
version = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "warptissue_cli",
]

source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]

myst_enable_extensions = ["colon_fence", "deflist", "dollarmath"]
myst_heading_anchors = 3

napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
napoleon_use_ivar = True
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}

html_theme = "alabaster"
html_title = f"warptissue {__version__}"
html_static_path: list[str] = []

# Ambiguous short names in the Attributes sections of dataclasses (``node_count`` on both
# ``TetMesh`` and ``MeshQuality``) are not worth a failed build.
suppress_warnings = ["ref.python"]

_ABSOLUTE_VALUE = re.compile(r"(?<!\\)\|")


def _escape_bars(app, what, name, obj, options, lines: list[str]) -> None:  # noqa: ARG001
    """Read ``|x|`` in docstrings as an absolute value, not a reST substitution.

    The Google docstrings write norms and magnitudes as ``|x|``; reST would take them for
    substitution references. Lines of grid tables (``+---``, ``| cell``) are kept.
    """
    for i, line in enumerate(lines):
        if not line.lstrip().startswith(("+-", "+=", "| ")):
            lines[i] = _ABSOLUTE_VALUE.sub(r"\\|", line)


PUBLIC_FACES = ("warptissue.study", "warptissue.materials")
"""Packages whose ``__init__`` re-exports the names of private modules (``_schema.py``, ...)."""


def _document_reexported_data(app) -> None:  # noqa: ARG001
    """Give autodoc the docstrings of the constants that a public face re-exports.

    autodoc documents a module's constant only where the module's own source holds its
    docstring (the string literal below it); a package's ``__init__`` imports its constants
    from private modules, which hold them. Their docstrings are added to the attribute docs
    of the package's source analyzer (cached, so autodoc reads them from there).
    """
    for package in PUBLIC_FACES:
        face = importlib.import_module(package)
        analyzer = ModuleAnalyzer.for_module(package)
        analyzer.analyze()
        for info in pkgutil.iter_modules(face.__path__, f"{package}."):
            module = importlib.import_module(info.name)
            for (scope, name), lines in (
                ModuleAnalyzer.for_module(info.name).find_attr_docs().items()
            ):
                if scope or name not in face.__all__:
                    continue
                if getattr(face, name) is getattr(module, name, None):
                    analyzer.attr_docs.setdefault((scope, name), list(lines))


def setup(app) -> None:
    """Connect the docstring hooks."""
    app.connect("builder-inited", _document_reexported_data)
    app.connect("autodoc-process-docstring", _escape_bars)
