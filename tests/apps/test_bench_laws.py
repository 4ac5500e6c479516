"""`tensormass bench laws`: the report's structure and what it compares (no timing assertions)."""
import json

import pytest

from tensormass.apps import bench_laws as bl


@pytest.mark.heavy          # the benchmark's quick run (a gmsh organ, three kernels): CI's heavy step
def test_quick_case_reports_every_variant(tmp_path):
    out = tmp_path / "laws.json"
    report = bl.run_laws_bench(quick=True, json_path=out, progress=lambda *_: None)
    (name, row), = report["cases"].items()
    for variant in bl.VARIANTS:
        assert row[variant]["ms_per_step"] > 0 and row[variant]["newton"] >= 1
    assert row["viscous"]["history_ms_per_step"] > 0 and row["elastic"]["history_ms_per_step"] == 0
    assert row["ratio_viscous"] == row["viscous"]["ms_per_step"] / row["elastic"]["ms_per_step"]
    assert json.loads(out.read_text())["cases"][name]["ratio_hgo"] == row["ratio_hgo"]


def test_the_variants_change_the_material_only():
    case = bl.QUICK_CASES[0]
    scenes = {v: bl._scene(case, v) for v in bl.VARIANTS}
    (elastic,), (viscous,), (hgo,) = (scenes[v].materials for v in ("elastic", "viscous", "hgo"))
    assert elastic.viscous is None and viscous.viscous == ((0.1, 1.0), (1.0, 0.5))
    assert hgo.law == "hgo" and hgo.fibres == ((1.0, 0.0, 0.0),)
    assert elastic.E == viscous.E and scenes["elastic"].solver.kind == "implicit_euler"
