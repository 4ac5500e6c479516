"""Every code snippet of the documentation (docs/**/*.md and README.md) is checked.

- ```toml: a whole scene is parsed and validated by the scene parser (Scene.from_string, its mesh
  built or read, paths relative to the checkout's root). A snippet whose first line is
  "# fragment" is part of a scene: it is parsed as TOML, and each of its keys must be a scene key
  (runtime.scene.keys), so a misspelt key in the documentation fails here too.
- ```python: run, in the checkout's root, one snippet after the other in fresh namespaces. A
  snippet whose first line is "# skip: <reason>" (gmsh, long runs) is only compiled.

Snippets must stay cheap: scenes that would run long are only parsed.
"""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from tensormass import laws
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.scene.keys import KEYS, TABLES

ROOT = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^(?P<indent>[ \t]*)```(?P<lang>[A-Za-z0-9_+-]*)[^\n]*\n(?P<body>.*?)^(?P=indent)```[ \t]*$",
                   re.M | re.S)


def _snippets(lang):
    files = sorted(ROOT.glob("docs/**/*.md")) + [ROOT / "README.md"]
    found = []
    for path in files:
        if "_build" in path.parts:
            continue
        text = path.read_text(encoding="utf-8")
        for match in FENCE.finditer(text):
            if match.group("lang") != lang:
                continue
            indent = match.group("indent")
            body = "\n".join(line[len(indent):] for line in match.group("body").splitlines())
            line = text.count("\n", 0, match.start()) + 1
            found.append(pytest.param(body, id=f"{path.relative_to(ROOT)}:{line}"))
    return found


TOML = _snippets("toml")
PYTHON = _snippets("python")


def test_the_docs_have_snippets():
    assert len(TOML) >= 15 and len(PYTHON) >= 4


_TABLE_NAMES = {t.name for t in TABLES}


def _check_keys(data, table=""):
    """Every key of a fragment is a scene key of its table (tables and arrays of tables recursed)."""
    known = {k.name for k in KEYS if k.table == table}
    for key, value in data.items():
        path = f"{table}.{key}" if table else key
        if table == "material" and key not in known:
            law = laws.get(data.get("law", "stvk"))
            options = {o for o, _, _ in getattr(law, "options", ())}
            assert key in set(law.parameters) | options, f"[[material]] {key}: not a key of law {law.name!r}"
            continue
        assert key in known, f"{path}: not a scene key (runtime.scene.keys)"
        items = value if isinstance(value, list) else [value]
        for item in items:
            if isinstance(item, dict) and path in _TABLE_NAMES:
                _check_keys(item, path)


@pytest.mark.parametrize("text", TOML)
def test_toml_snippet(text):
    if text.lstrip().startswith("# fragment"):
        _check_keys(tomllib.loads(text))
        return
    Scene.from_string(text, base_dir=ROOT, source="snippet")


@pytest.mark.parametrize("code", PYTHON)
def test_python_snippet(code, monkeypatch):
    first = code.lstrip().splitlines()[0] if code.strip() else ""
    compiled = compile(code, "<snippet>", "exec")
    if first.startswith("# skip:"):
        reason = first.removeprefix("# skip:").strip()
        assert reason, "a skipped snippet says why"
        pytest.skip(reason)
    monkeypatch.chdir(ROOT)
    exec(compiled, {"__name__": "__snippet__"})
