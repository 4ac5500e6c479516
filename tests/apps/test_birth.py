"""The reduced birth scene in a quick form: the committed mesh holds the head's shell zones beside the
pelvic floor's tetrahedra; a few steps of the first contraction bring the head into the floor's
opening through frictionless contact, and the opening widens around it."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tensormass.apps import birth, fetal_head
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.run.simulation import Simulation
from tensormass.runtime.scene.scene import Scene

SCENE = Path(__file__).resolve().parents[2] / "examples" / "birth" / "birth.toml"


def test_the_mesh_holds_the_head_beside_the_floor():
    sim = Simulation(Scene.from_toml(SCENE), output=False)
    model = sim.model
    assert [b.type for b in model.mesh.blocks] == ["tetra", "shell"]
    assert model.dofs_per_node == 6
    head_nodes, floor_nodes, lip = birth._bodies(model)
    assert not np.intersect1d(head_nodes, floor_nodes).size and lip.size > 10
    X = model.mesh.points
    assert abs(np.hypot(*X[lip, :2].T).min() - birth.FLOOR_INNER) < 1e-3
    d = fetal_head.diameters(X, fetal_head.landmarks(X))
    for name, (diameter, _) in fetal_head.TABLE_8_2.items():
        assert abs(1e3 * d[name] - diameter) < 1.0
    # the head's vertex is GAP above the floor at rest
    assert abs(X[floor_nodes, 2].max() - X[head_nodes, 2].min() + birth.GAP) < 1e-3
    assert {p.law for p in model.parts} == {"neohookean", "cst_dkt"}


def test_the_first_steps_push_the_head_into_the_opening():
    out = birth.run_birth(SCENE, steps=4)
    rows = out["rows"]
    assert out["status"] == "ok" and len(rows) == 5
    descent = [r["descent_mm"] for r in rows]
    assert descent[0] == 0.0 and all(b > a for a, b in zip(descent, descent[1:]))
    assert descent[-1] > birth.GAP * 1e3                    # past first touch: the floor holds it
    assert rows[-1]["stretch"] > 1.0                          # the opening widens around the head


def test_without_the_scene_file_the_report_says_so(tmp_path):
    with pytest.raises(TensormassError, match="birth scene .* is not there"):
        birth.run_birth(tmp_path / "none.toml", steps=1)


def test_a_run_that_fails_says_why_and_exits_1(tmp_path, capsys):
    text = SCENE.read_text().replace('file = "birth.msh"', f'file = "{SCENE.with_suffix(".msh").as_posix()}"')
    scene = tmp_path / "birth.toml"
    scene.write_text(text.replace("newton_max_iterations = 60", "newton_max_iterations = 1"))
    assert birth.main(["report", "--scene", str(scene), "--steps", "2"]) == 1
    assert "birth: step 1 failed" in capsys.readouterr().out
