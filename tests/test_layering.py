"""The package's import structure, read from the sources (ast): every import counts, those inside
functions too.

- the runtime's wings import only downhill (runtime.WINGS: base < mesh < ... < run), and nothing in
  the runtime imports the tools (apps) or the symbolic pipeline's builders;
- no import circle anywhere in the package (a circle is a strongly connected group of modules).
"""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# folder -> package (pyproject.toml's package-dir)
FOLDERS = {"api": "tensormass", "generator": "tensormass.generator", "laws": "tensormass.laws",
           "backends": "tensormass.backends", "generated": "tensormass.generated", "runtime": "tensormass.runtime",
           "apps": "tensormass.apps", "elements": "tensormass.elements"}
WINGS = ("base", "mesh", "kernels", "assembly", "solve", "physics", "contact", "scene", "model", "change", "run")


def _modules(root=ROOT) -> dict:
    out = {}
    for folder, package in FOLDERS.items():
        for path in (root / folder).rglob("*.py"):
            if "templates" in path.parts:
                continue
            parts = package.split(".") + list(path.relative_to(root / folder).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            out[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return out


def _import_source(path: Path) -> str:
    """The text whose imports count: the whole file; for a generated kernel (generated/, 100 MB of
    numba code in all) its head up to the first function, where its template puts every import."""
    text = path.read_text()
    if "generated" in path.parts and path.name != "__init__.py":
        cut = min((i for i in (text.find("\n@"), text.find("\ndef ")) if i >= 0), default=len(text))
        return text[:cut]
    return text


def import_graph(root=ROOT) -> dict:
    """module -> {imported project module: line of the first such import}."""
    modules = _modules(root)
    graph = {}
    for name, (path, is_package) in modules.items():
        deps = {}
        for node in ast.walk(ast.parse(_import_source(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".")[:None if is_package else -1]
                    base = base[:len(base) - node.level + 1]
                    prefix = ".".join(base + ([node.module] if node.module else []))
                else:
                    prefix = node.module or ""
                targets = [f"{prefix}.{a.name}" for a in node.names]
            for t in targets:
                while t not in modules and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in modules and t != name:
                    deps.setdefault(t, node.lineno)
        graph[name] = deps
    return graph


def _wing(module: str):
    parts = module.split(".")
    return parts[2] if len(parts) > 2 and parts[1] == "runtime" and parts[2] in WINGS else None


def upward_imports(graph) -> list:
    """(importer, imported, line) where a runtime module reaches a higher wing, the tools or the builders."""
    bad = []
    for module, deps in graph.items():
        if not module.startswith("tensormass.runtime"):
            continue
        mine = _wing(module)
        for dep, line in deps.items():
            theirs = _wing(dep)
            if dep.startswith("tensormass.apps") or (theirs is not None and mine is not None
                                                     and WINGS.index(theirs) > WINGS.index(mine)):
                bad.append((module, dep, line))
            if mine is None and theirs is not None and module != "tensormass.runtime":
                bad.append((module, dep, line))          # a runtime module outside every wing
    return sorted(bad)


def circles(graph) -> list:
    """Strongly connected groups of more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(sorted(group))

    import sys
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10_000))
    try:
        for v in sorted(graph):
            if v not in index:
                visit(v)
    finally:
        sys.setrecursionlimit(limit)
    return sorted(out)


def test_runtime_wings_import_only_downhill():
    from tensormass import runtime
    assert runtime.WINGS == WINGS
    assert upward_imports(import_graph()) == []


def test_no_import_circle_in_the_package():
    assert circles(import_graph()) == []


def test_every_runtime_module_lives_in_a_wing():
    loose = [p.name for p in (ROOT / "runtime").glob("*.py") if p.name != "__init__.py"]
    assert loose == []


@pytest.mark.parametrize("mutation", ["upward", "circle"])
def test_the_checks_see_a_mutation(tmp_path, mutation):
    """An upward import added to a copy of the sources, or a circle, is found."""
    import shutil
    for folder in FOLDERS:
        shutil.copytree(ROOT / folder, tmp_path / folder, ignore=shutil.ignore_patterns("__pycache__", "*.c", "*.nb?"))
    errors = tmp_path / "runtime" / "base" / "errors.py"
    if mutation == "upward":
        errors.write_text(errors.read_text() + "\n\ndef _late():\n    from ..run import simulation\n")
        assert ("tensormass.runtime.base.errors", "tensormass.runtime.run.simulation") in \
            [(a, b) for a, b, _ in upward_imports(import_graph(tmp_path))]
    else:
        paths = tmp_path / "runtime" / "base" / "paths.py"
        errors.write_text(errors.read_text() + "\nfrom . import paths\n")
        paths.write_text(paths.read_text() + "\nfrom . import errors\n")
        assert ["tensormass.runtime.base.errors", "tensormass.runtime.base.paths"] in circles(import_graph(tmp_path))
