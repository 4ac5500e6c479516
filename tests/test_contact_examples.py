"""examples/contact/: every scene parses with its mesh (quick), the mesh files are what make_meshes.py
writes (quick), and every scene runs through `tensormass run` with status ok and actually touches:
contact pairs on some step, and a nonzero force on each obstacle that is meant to be hit (heavy: the
runs take seconds to a minute each)."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import meshio
import numpy as np
import pytest

from tensormass.apps.cli import main
from tensormass.runtime.mesh.io import read_mesh
from tensormass.runtime.scene.scene import Scene

CONTACT = Path(__file__).resolve().parents[1] / "examples" / "contact"
SCENES = sorted(CONTACT.glob("*.toml"))
# the obstacles each scene must push on (a force above zero on some step)
HIT = {"tool_indent": ["tool"], "squeeze_ball": ["top", "bottom"], "shell_ball_planes": ["top", "bottom"],
       "torus_stairs": ["paddle", "landing", "step1"], "two_bodies": [], "self_fold": []}


def test_the_expected_scenes_are_there():
    assert {p.stem for p in SCENES} == set(HIT)


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_contact_examples_parse(path):
    scene = Scene.from_toml(path)
    mesh = scene.load_mesh()
    assert scene.name == path.stem and mesh.n_cells > 0
    assert scene.contact is not None
    names = {o.name for o in scene.obstacles}
    assert set(HIT[path.stem]) <= names


def _make_meshes():
    spec = importlib.util.spec_from_file_location("make_meshes", CONTACT / "make_meshes.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_mesh_files_are_the_scripts():
    make = _make_meshes()
    points, tri = make.torus()
    torus = meshio.read(CONTACT / "torus.vtu")          # shell triangles: read as the shell reader does
    assert (len(points), len(tri)) == (600, 1200)
    np.testing.assert_allclose(torus.points, points, atol=1e-12)
    assert [(c.type, c.data.tolist()) for c in torus.cells] == [("triangle", tri.tolist())]
    blocks = read_mesh(CONTACT / "two_blocks.vtu")
    assert blocks.cell_types() == ["hexahedron"] and blocks.n_cells == 64
    assert (CONTACT / "torus.vtu").stat().st_size < 500_000


@pytest.mark.heavy
@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_contact_examples_run_and_touch(path, tmp_path):
    summary_file = tmp_path / "summary.json"
    code = main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet", "--json", str(summary_file)])
    summary = json.loads(summary_file.read_text())
    assert code == 0 and summary["status"] == "ok", summary.get("message")
    contact = summary["per_step"]["contact"]
    assert max(contact["pairs"]) > 0
    for name in HIT[path.stem]:
        force = np.array(summary["per_step"]["obstacles"][name]["force"], dtype=float)
        assert np.abs(force).max() > 0, name
