"""A cold start: the command line's help starts without sympy, numba or jinja2, the deferred
commands' stubs say what the full parsers say, and a run writes nothing into the package folder."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tensormass.apps import cli

HEAVY = ("numba", "sympy", "jinja2")


def _imported_by(args, env=None):
    """The top-level modules `python -X importtime -m tensormass ARGS` imports."""
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "tensormass", *args],
                          capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "usage: tensormass" in done.stdout
    return {line.split("|")[-1].strip().split(".")[0]
            for line in done.stderr.splitlines() if line.startswith("import time:")}


@pytest.mark.parametrize("args", [["--help"], ["run", "--help"], ["demo", "--help"]])
def test_help_imports_no_heavy_module(args):
    imported = _imported_by(args)
    assert "tensormass" in imported                 # the report did list the package's imports
    assert not imported & set(HEAVY), sorted(imported & set(HEAVY))


def _choices(parser):
    action = next(a for a in parser._actions if a.dest == "command")
    return {c.dest: c.help for c in action._choices_actions}, action.choices


def test_stubs_say_what_the_full_commands_say():
    full_help, full = _choices(cli.build_parser())
    stub_help, stubs = _choices(cli.build_parser(full=set()))
    assert stub_help == full_help
    assert list(stubs) == list(full)                 # the same commands, in the same order
    for name in cli.DEFERRED:
        assert stubs[name]._actions == []            # a stub: nothing parsed, nothing imported
        assert full[name]._actions                   # the real parser, with its options


def test_a_named_deferred_command_is_built_in_full():
    _, choices = _choices(cli.build_parser(full={cli.named_command(["generate", "--check"])}))
    assert any(a.dest == "check" for a in choices["generate"]._actions)
    assert cli.named_command(["--version"]) is None


PACKAGE = os.path.dirname(os.path.abspath(cli.__file__ + "/.."))       # the installed tensormass folder


def _numba_files(folder):
    """{path: mtime} of numba's cache files (*.nbi, *.nbc) under folder."""
    found = {}
    for root, _, names in os.walk(folder):
        for name in names:
            if name.endswith((".nbi", ".nbc")):
                path = os.path.join(root, name)
                found[path] = os.stat(path).st_mtime_ns
    return found


def test_numba_caches_into_the_user_cache_not_the_package(tmp_path):
    """A fresh process with an empty cache: a cached runtime helper lands in TENSORMASS_CACHE."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["TENSORMASS_CACHE"] = str(tmp_path)
    before = _numba_files(PACKAGE)
    code = ("import os, numpy as np, numba; from tensormass.runtime.mesh.topology import _count_sort; "
            "_count_sort(np.array([0, 1, 1]), 2); print(os.environ['NUMBA_CACHE_DIR'], numba.config.CACHE_DIR)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    from tensormass.runtime.base.cache import GENERATOR_VERSION
    folder = str(tmp_path / GENERATOR_VERSION / "numba")
    assert done.stdout.split() == [folder, folder]
    assert any("_count_sort" in path for path in _numba_files(folder))
    assert _numba_files(PACKAGE) == before


def test_a_users_numba_cache_dir_is_kept(tmp_path, monkeypatch):
    from tensormass.runtime.base import cache
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert cache.use_numba_cache() == str(tmp_path / "mine")
    assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "mine")


def test_this_process_caches_numba_outside_the_package():
    """The test session's own numba (imported after tensormass) writes into the user cache."""
    import numba
    assert numba.config.CACHE_DIR == os.environ["NUMBA_CACHE_DIR"]
    assert not os.path.abspath(numba.config.CACHE_DIR).startswith(PACKAGE + os.sep)


def test_a_scene_run_writes_no_numba_cache_into_the_package(tmp_path):
    from tensormass.apps.commands import demo_text, run_scene
    from tensormass.runtime.scene.scene import Scene
    text = demo_text().replace("cells = [16, 2, 2]", "cells = [4, 1, 1]")
    scene = Scene.from_string(text, name="small", source="test")
    before = _numba_files(PACKAGE)
    data = run_scene(scene, out=tmp_path / "out", quiet=True)
    assert data["exit_code"] == 0
    assert _numba_files(PACKAGE) == before


def test_every_package_folder_is_installed():
    """pyproject's package list names every folder with an __init__.py (a missing wing installs a
    tensormass that cannot start)."""
    import tomllib
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    if not (root / "pyproject.toml").exists():
        pytest.skip("not run from a checkout")
    tool = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]
    expected = {".".join((package, *init.parent.relative_to(root / folder).parts))
                for package, folder in tool["package-dir"].items()
                for init in (root / folder).rglob("__init__.py") if "__pycache__" not in init.parts}
    assert expected - set(tool["packages"]) == set()


def test_the_default_backend_is_c_with_a_compiler_else_numba(monkeypatch):
    from tensormass.apps.commands import backend_note
    from tensormass.backends.c.loader import default_backend
    from tensormass.runtime.scene.scene import Scene
    from tensormass.runtime.scene.types import Solver
    text = ("[mesh]\ngenerate = \"bar\"\n[[material]]\nlaw = \"stvk\"\nE = 1e6\nnu = 0.3\n"
            "[[fixed]]\nbox = [[-1, -1, -1], [0, 2, 2]]\n")
    assert default_backend() == "c"                       # this machine builds the C kernels (gcc)
    assert Solver().backend == "c" and Scene.from_string(text).solver.backend == "c"
    monkeypatch.setenv("CC", "no-such-compiler-here")
    assert default_backend() == "numba"
    assert Solver().backend == "numba" and Scene.from_string(text).solver.backend == "numba"
    assert "no C compiler was found" in backend_note("numba")
    scene = Scene.from_string(text + "[solver]\nbackend = \"c\"\n")
    assert scene.solver.backend == "c"                    # a scene's own choice stays


def test_warm_up_calls_only_the_outputs_the_run_calls(monkeypatch):
    """A Hooke part under an implicit solver: its constant K is assembled once, and its energy
    and forces come from K, so the warm-up compiles only its stiffness."""
    from tensormass.apps.commands import demo_text
    from tensormass.runtime.model.model import Model
    from tensormass.runtime.scene.scene import Scene
    text = demo_text().replace("cells = [16, 2, 2]", "cells = [4, 1, 1]")      # the default backend:
    # warm_up calls the outputs the same way for both, and the calls are intercepted below
    model = Model.from_scene(Scene.from_string(text, name="small", source="test"))
    called = []
    for part in model.parts:
        for name in ("energy", "forces", "stiffness", "forces_and_stiffness"):
            # monkeypatch: the kernels are cached and shared with every later test of this process
            monkeypatch.setattr(part.kernel, name, lambda D, u, _k=(part.law, name): called.append(_k))
    model.warm_up()
    assert {law for law, _ in called} == {"hooke", "stvk"}
    assert sorted({k for k in called if k[0] == "hooke"}) == [("hooke", "stiffness")]
    assert sorted({k for k in called if k[0] == "stvk"}) == [("stvk", name) for name in sorted(model.outputs)]


# Scenes whose kernels are all committed: an implicit Hooke bar (the constant-K path) and a
# stable neo-Hookean block under mean dilatation (the volumetric split).  Every run loads every
# built-in law file (shells and springs included): the registry imports them all.
_COMMITTED_RUNS = r'''
import sys, tomllib
from pathlib import Path
from tensormass import Scene, Simulation
root = Path(sys.argv[1])
changes = {
    "cantilever_tetra.toml": {"mesh": {"cells": [6, 2, 2]}},
    "soft_block_squeezed.toml": {"mesh": {"cells": [3, 3, 2], "element": "hexahedron"}, "solver": {"steps": 1},
                                 "material": {"formulation": "mean_dilatation", "quadrature": "gauss2"}},
}
for name, change in changes.items():
    data = tomllib.loads((root / name).read_text())
    for table, values in change.items():
        (data[table][0] if table == "material" else data[table]).update(values)
    data.pop("probe", None)
    data.pop("output", None)
    summary = Simulation(Scene.from_dict(data, base_dir=root)).run()
    assert summary["status"] == "ok", (name, summary["status"])
from tensormass import laws
assert {"cst_dkt", "hybmss", "mss"} <= set(laws.names())
print(sorted(m for m in ("sympy", "jinja2") if m in sys.modules))
'''


def test_a_run_of_committed_kernels_imports_neither_sympy_nor_jinja2(tmp_path):
    """Scene checks read the committed catalogue (generated/manifest.json), the law files import
    sympy only when an energy is built, and the kernels' metadata says which laws have a constant
    stiffness: a run of committed kernels never loads the symbolic pipeline."""
    root = Path(__file__).resolve().parents[2] / "examples"
    done = subprocess.run([sys.executable, "-c", _COMMITTED_RUNS, str(root)], capture_output=True,
                          text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"


def test_the_command_line_run_imports_neither_sympy_nor_jinja2(tmp_path):
    """`tensormass run` on an example (outputs written) under -X importtime."""
    scene = Path(__file__).resolve().parents[2] / "examples" / "cantilever_tetra.toml"
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "tensormass", "run", str(scene),
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    imported = {line.split("|")[-1].strip().split(".")[0]
                for line in done.stderr.splitlines() if line.startswith("import time:")}
    assert "numba" in imported                      # the report did list the run's imports
    assert not imported & {"sympy", "jinja2"}, sorted(imported & {"sympy", "jinja2"})
