"""Sphinx configuration of the dg16m documentation site (MyST Markdown, the furo theme).

Build: ``make docs`` (``sphinx-build -W --keep-going -b html docs docs/_build/html``).
Pages under ``environments/``, ``api/`` and ``cli.md`` are generated at build time from the
code by ``_ext/dg16m_docs.py``; pictures of trials by ``scripts/docs_pictures.py``.
"""

from __future__ import annotations

import os
import sys
import warnings
from importlib.metadata import version as _version
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MUJOCO_GL", "egl")  # dg16m_env's default; set before MuJoCo imports

# sphinx-autodoc-typehints (3.6 here) calls ``SphinxParser.set_application`` on every docstring
# it parses, which Sphinx 9 deprecates: ~1,090 identical ``RemovedInSphinx10Warning`` lines (two
# each) per build, none about this project. Hidden here, this one message only; the fix is a
# sphinx-autodoc-typehints release that no longer calls it.
warnings.filterwarnings(
    "ignore",
    message=r".*_RstSnippetParser\.set_application' is deprecated",
    module=r"sphinx_autodoc_typehints(\..*)?",
)

project = "dg16m"
author = "the dg16m authors"
copyright = "the dg16m authors, MIT licence"
release = _version("dg16m")
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx_autodoc_typehints",
    "dg16m_docs",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "**/.*", "README.md"]
templates_path: list[str] = []

# -- MyST --------------------------------------------------------------------------------------
myst_enable_extensions = ["colon_fence", "deflist", "attrs_inline"]
myst_heading_anchors = 3  # `page.md#a-heading` links (the included Markdown files use them)

# -- autodoc -----------------------------------------------------------------------------------
# Each name is documented where it is defined (``__all__`` lists re-exports too).
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_class_signature = "separated"
autodoc_inherit_docstrings = False  # Gymnasium's base-class docstrings are not ours
# Only what is not installed (the optional MuJoCo Warp extra); everything else is imported.
autodoc_mock_imports = ["warp", "mujoco_warp"]
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
typehints_use_signature = False
typehints_use_signature_return = False
always_document_param_types = False
typehints_document_rtype = True
typehints_fully_qualified = False

# -- cross-references --------------------------------------------------------------------------
# Every reference must resolve (warnings are errors), except names of other projects: this site
# is built offline (no intersphinx), so those are expected to stay plain text.
nitpicky = True
_EXTERNAL = (
    r"(builtins|typing|typing_extensions|collections|collections\.abc|abc|enum|dataclasses|os|"
    r"pathlib|io|argparse|subprocess|multiprocessing|concurrent|threading|asyncio|json|re|"
    r"sqlite3|logging|types|contextlib|functools|numbers|datetime|hashlib|http|socket|signal|"
    r"tempfile|queue|random|weakref|np|numpy|numpy\.typing|npt|scipy|h5py|trimesh|torch|nn|"
    r"gym|gymnasium|mujoco|dm_control|stable_baselines3|sb3|ray|starlette|uvicorn|httpx|"
    r"matplotlib|clarabel|cvxpy|numba|fcl|coacd|PIL|tqdm|warp|mujoco_warp|manifold3d|"
    r"selenium|pytest|shapely|rtree|Image|mjcf|mjx|importlib|hmac|html|secrets|h11|H11Protocol)"
)
# Starlette's own annotations name classes it imports only for type checkers.
suppress_warnings = ["sphinx_autodoc_typehints.forward_reference"]
nitpick_ignore_regex = [
    (r"py:.*", _EXTERNAL + r"(\..*)?"),
    (
        r"py:.*",
        r"(int|float|str|bytes|bool|object|list|dict|tuple|set|frozenset|type|None|"
        r"Ellipsis|complex|slice|range|memoryview|bytearray|callable|iterable|sequence|mapping|"
        r"optional|array|ndarray|array_like|array-like|path-like|file-like|Path|Any|Callable|"
        r"Iterator|Iterable|Sequence|Mapping|Generator|TypeVar|Literal|Self|NDArray|PathLike|"
        r"Exception|ValueError|TypeError|KeyError|OSError|RuntimeError|KeyboardInterrupt|"
        r"FileNotFoundError|FileExistsError|NotADirectoryError|MemoryError|TimeoutError)",
    ),
]

# -- HTML --------------------------------------------------------------------------------------
html_theme = "furo"
html_title = f"dg16m {release}"
html_static_path = ["_static"]
html_css_files = ["dg16m.css"]
html_last_updated_fmt = None
html_show_sourcelink = False
html_copy_source = False
html_theme_options = {
    "source_repository": "",
    "navigation_with_keys": True,
    "sidebar_hide_name": False,
}
pygments_style = "sphinx"
pygments_dark_style = "monokai"
