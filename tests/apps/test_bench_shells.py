"""`tensormass bench shells --quick`: the closed shell runs in every row and the JSON is sane."""
from __future__ import annotations

import json

import pytest

from tensormass.apps.bench_shells import run_shells_bench, scene_text
from tensormass.runtime.scene.scene import Scene


@pytest.mark.heavy          # the benchmark's quick run, 10 to 35 s cold: CI's heavy step
def test_quick_bench_writes_rows_ratios_and_colours(tmp_path):
    lines = []
    path = tmp_path / "shells.json"
    run_shells_bench(quick=True, json_path=path, progress=lines.append)
    report = json.loads(path.read_text())
    rows = report["rows"]
    assert set(rows) == {"linear, 1 thread", "co-rotational, 1 thread", "co-rotational, 2 threads"}
    assert rows["linear, 1 thread"]["ratio_to_linear"] == 1.0
    assert all(r["ms_per_step"] > 0 and r["triangles"] == 320 for r in rows.values())
    # the ball sags: the same answer however many threads
    assert rows["co-rotational, 1 thread"]["top_uz"] == rows["co-rotational, 2 threads"]["top_uz"] < 0
    assert 4 <= report["colours"]["dsatur"] <= report["colours"]["greedy"]
    assert any("thesis" in line for line in lines)


def test_the_scene_is_the_thesis_ball():
    s = Scene.from_string(scene_text(3, 1, 1))
    m = s.materials[0]
    assert (m.law, m.E, m.nu, m.params["thickness"], m.density) == ("cst_dkt", 3000.0, 0.49, 0.1, 100.0)
    assert s.solver.kind == "implicit_euler"
