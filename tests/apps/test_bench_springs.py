"""`tensormass bench springs --quick`: runs every model on the same meshes and writes sane JSON."""
from __future__ import annotations

import json

import pytest

from tensormass.apps.bench_springs import MODELS, run_springs_bench, scene_text
from tensormass.runtime.scene.scene import Scene


@pytest.mark.heavy          # the benchmark's quick run, 10 to 35 s cold: CI's heavy step
def test_quick_bench_writes_ratios_against_the_baselines(tmp_path):
    lines = []
    path = tmp_path / "springs.json"
    run_springs_bench(quick=True, json_path=path, progress=lines.append)
    report = json.loads(path.read_text())
    hexa = report["hexahedra"]["4^3 c"]
    assert set(hexa) == {"explicit", "implicit_euler"}
    for kind, rows in hexa.items():
        assert set(rows) == set(MODELS)
        assert {r["nodes"] for r in rows.values()} == {125}              # equal node count, every model
        assert rows["stvk_gauss2"]["ratio_to_stvk_gauss2"] == 1.0
        assert all(r["ms_per_step"] > 0 and r["tip_uz"] < 0 for r in rows.values())
    tetra = next(iter(report["tetrahedra"].values()))
    assert set(tetra["implicit_euler"]) == {"mss", "stvk_gauss1"}
    assert any("hybmss" in line for line in lines)


def test_the_scenes_use_cubes_and_the_named_law():
    s = Scene.from_string(scene_text("hybmss", "static", 3))
    assert (s.materials[0].law, s.materials[0].params) == ("hybmss", {"A": 1.0})
    assert s.mesh.size == (0.15, 0.15, 0.15) and s.mesh.cells == (3, 3, 3)
