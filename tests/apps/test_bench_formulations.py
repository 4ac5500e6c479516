"""`tensormass bench formulations`: the report's structure and what it compares (no timing assertions)."""
import json

import pytest

from tensormass.apps import bench_formulations as bf


@pytest.mark.heavy          # the benchmark's quick run, 10 to 35 s cold: CI's heavy step
def test_quick_hexahedral_case_reports_both_formulations(tmp_path):
    case = [c for c in bf.QUICK_CASES if c[0].body == "cantilever"]
    out = tmp_path / "f.json"
    report = bf.run_formulations_bench(quick=True, json_path=out, cases=case, progress=lambda *_: None)
    (name, row), = report["cases"].items()
    assert row["formulation"] == "mean_dilatation"
    for key in ("displacement", "mean_dilatation"):
        assert row[key]["newton"] >= 1 and row[key]["ms_per_iteration"] > 0
    # same mesh and pattern (mean dilatation couples nothing outside a cell), a slightly softer answer
    assert row["displacement"]["matrix_entries"] == row["mean_dilatation"]["matrix_entries"]
    base, other = row["displacement"]["probe"][-1], row["mean_dilatation"]["probe"][-1]
    assert abs(other) > abs(base) and abs(other - base) < 0.1 * abs(base)
    assert row["ratio_per_iteration"] == row["mean_dilatation"]["ms_per_iteration"] / row["displacement"]["ms_per_iteration"]
    assert json.loads(out.read_text())["cases"][name]["formulation"] == "mean_dilatation"


def test_formulation_is_written_into_the_scene():
    case, formulation = bf.QUICK_CASES[-1]
    scene = bf._scene(case, formulation)
    assert [m.formulation for m in scene.materials] == ["mean_dilatation"]
