"""Sphinx configuration: MyST Markdown pages, and the reference generated from the code
(docs/_ext/tensormass_docs.py). Build: sphinx-build -W --keep-going -b html docs docs/_build/html"""
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

project = "tensormass"
author = "the tensormass authors"
copyright = "the tensormass authors, MIT licence"
try:
    from importlib.metadata import version as _version
    release = _version("tensormass")
except Exception:          # an uninstalled checkout: the reference needs the package anyway
    release = ""

extensions = ["myst_parser", "tensormass_docs"]
source_suffix = {".md": "markdown"}
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
exclude_patterns = ["_build"]
html_theme = "alabaster"
html_static_path = []
html_title = "tensormass"
