"""docs/_ext/tensormass_docs.py: the generated reference pages describe the package, whatever the
process that builds them has loaded (no sphinx build here: the functions that make the Markdown)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from tensormass import laws

ROOT = Path(__file__).resolve().parents[1]
YEOH = ROOT / "examples" / "yeoh" / "yeoh.py"


@pytest.fixture(autouse=True)
def _forget_user_laws(forget_user_laws):
    """Every test here: its user laws leave with it (conftest.forget_user_laws)."""


def _extension():
    pytest.importorskip("docutils", reason="the docs extras are not installed (pip install '.[docs]')")
    path = ROOT / "docs" / "_ext" / "tensormass_docs.py"
    spec = importlib.util.spec_from_file_location("tensormass_docs_under_test", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_catalogue_and_scene_keys_list_only_built_in_laws(monkeypatch):
    """A $TENSORMASS_LAWS in the docs build's environment adds no user law to the published pages."""
    monkeypatch.setenv(laws.SEARCH_PATH, str(YEOH))
    assert "yeoh" in laws.names()                     # the process does know the user law
    ext = _extension()
    catalogue = "\n".join(ext.law_lines())
    assert "`neohookean`" in catalogue
    assert "yeoh" not in catalogue
    keys = "\n".join(ext.scene_key_lines())
    assert "`neohookean`" in keys
    assert "yeoh" not in keys
