"""The path rule (runtime/base/paths.py): paths in a scene are relative to the scene file's folder,
paths on the command line to the working directory."""
from __future__ import annotations

import json
from pathlib import Path

import meshio

from tensormass.apps.cli import main
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.mesh.io import to_meshio
from tensormass.runtime.base.paths import scene_path
from tensormass.runtime.scene.scene import Scene

SCENE = """
[mesh]
{mesh}
[[material]]
law = "hooke"
quadrature = "gauss2"
E = 1.0e8
nu = 0.3
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0.0, 0.0, -9.81]
[output]
dir = "{out}"
"""
BAR = 'generate = "bar"\nsize = [1.0, 0.2, 0.2]\ncells = [2, 1, 1]'


def write_scene(folder: Path, out="frames", mesh=BAR) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "scene.toml"
    path.write_text(SCENE.format(mesh=mesh, out=out))
    return path


def test_scene_path_rule(tmp_path):
    assert scene_path("a/b", tmp_path) == str(tmp_path / "a" / "b")
    assert scene_path(str(tmp_path / "abs"), Path("elsewhere")) == str(tmp_path / "abs")
    assert scene_path("~/x", tmp_path) == str(Path.home() / "x")
    assert scene_path("a", None) == "a"                   # no scene file: as written


def test_output_dir_and_mesh_file_are_relative_to_the_scene_file(tmp_path, monkeypatch):
    folder = tmp_path / "scenes"
    folder.mkdir()
    meshio.write(folder / "bar.vtu", to_meshio(generate_bar((1.0, 0.2, 0.2), (2, 1, 1))))
    path = write_scene(folder, out="out/run", mesh='file = "bar.vtu"')
    monkeypatch.chdir(tmp_path)                               # the working directory is not the scene's
    scene = Scene.from_toml("scenes/scene.toml")
    assert Path(scene.mesh.file) == Path("scenes") / "bar.vtu"
    assert Path(scene.output.dir) == Path("scenes") / "out" / "run"
    absolute = write_scene(tmp_path / "abs", out=str(tmp_path / "elsewhere"))
    assert Scene.from_toml(absolute).output.dir == str(tmp_path / "elsewhere")
    # a scene without a file keeps its paths as written (the working directory's)
    assert Scene.from_string(SCENE.format(mesh=BAR, out="frames")).output.dir == "frames"
    assert path.is_file()


def test_run_writes_where_the_scene_says_and_the_summary_says_so(tmp_path, monkeypatch, capsys):
    write_scene(tmp_path / "scenes", out="frames")
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(["run", "../scenes/scene.toml", "--json", "summary.json"]) == 0
    printed = capsys.readouterr().out
    assert (tmp_path / "scenes" / "frames" / "frame.pvd").is_file()
    assert not (work / "frames").exists()
    data = json.loads((work / "summary.json").read_text())   # --json: the working directory's
    assert Path(data["output"]["dir"]).resolve() == (tmp_path / "scenes" / "frames").resolve()
    assert data["output"]["dir_from"] == "[output] dir, relative to the scene file"
    assert "relative to the scene file" in printed
    # --out on the command line: relative to the working directory
    assert main(["run", "../scenes/scene.toml", "--out", "mine", "--quiet", "--json", "s2.json"]) == 0
    assert (work / "mine" / "frame.pvd").is_file()
    data = json.loads((work / "s2.json").read_text())
    assert data["output"]["dir_from"] == "given on the command line, relative to the working directory"
