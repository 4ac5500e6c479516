"""`tensormass bench cutting --quick`: a cut is applied and timed, the baseline rebuild too, the JSON is sane."""
from __future__ import annotations

import json

import pytest

from tensormass.apps.bench_cutting import CUT_STEP, STEPS, run_cutting_bench


@pytest.mark.heavy          # the benchmark's quick run, 10 to 35 s cold: CI's heavy step
def test_quick_bench_times_the_cut_against_a_full_rebuild(tmp_path):
    lines = []
    path = tmp_path / "cutting.json"
    run_cutting_bench(quick=True, json_path=path, progress=lines.append)
    report = json.loads(path.read_text())
    (row,) = report["rows"].values()
    assert row["status"] == "ok" and row["faces"] > 0 and row["nodes_added"] > 0
    cut = row["cut_ms"]
    assert set(cut) == {"topology", "model", "solver", "total"} and all(v > 0 for v in cut.values())
    assert abs(cut["total"] - (cut["topology"] + cut["model"] + cut["solver"])) < 1e-6
    assert row["full_rebuild_ms"] > 0 and row["ratio_to_full_rebuild"] > 0
    assert row["step_ms_before"] > 0 and row["step_ms_after"] > 0 and 1 < CUT_STEP < STEPS
    assert report["target_ms"] == 50.0 and any("full rebuild" in line for line in lines)


def test_scale_run_builds_ten_incisions_or_says_it_needs_gmsh(tmp_path):
    """--scale: ten [[cut]] events, one every other step, through the organ; without gmsh a clear error."""
    from tensormass.apps import bench_cutting
    from tensormass.runtime.base.errors import TensormassError
    try:
        import gmsh  # noqa: F401
    except ImportError:
        with pytest.raises(TensormassError, match="needs gmsh"):
            bench_cutting.run_cutting_scale(progress=lambda line: None)
        return
    bench_cutting.SCALE_SIZE, size = 0.012, bench_cutting.SCALE_SIZE          # a coarse organ: the scene only
    try:
        text = bench_cutting._organ_scale(tmp_path)
    finally:
        bench_cutting.SCALE_SIZE = size
    from tensormass.runtime.scene.scene import Scene
    scene = Scene.from_string(text)
    steps = [e.step for e in scene.topology]
    assert len(steps) == bench_cutting.SCALE_CUTS == 10 and steps == list(range(3, 23, 2))
    assert scene.solver.steps == 23 and scene.solver.kind == "implicit_euler"
