"""The 3D nearly incompressible block (apps/reports/block.py): tetrahedra lock, nodal pressure does not."""
from __future__ import annotations

import pytest

from tensormass.apps.reports.accuracy import BENCHMARK_NAMES
from tensormass.apps.reports.block import block


@pytest.mark.heavy          # the report's quick run, 10 to 45 s cold: CI's heavy step
def test_tetrahedra_lock_and_nodal_pressure_does_not():
    assert "block" in BENCHMARK_NAMES
    res = block(True, lambda *_: None, {"levels": {"tetra": [4], "tetra10": [2]}, "reference": 4})
    refs = res["references"]
    err = {(r["case"], r["element"], r["formulation"]): (r["value"] - refs[r["case"]]) / refs[r["case"]]
           for r in res["rows"]}
    assert all(r["value"] > 0 for r in res["rows"])                    # the top moves with the traction
    assert err[("nu=0.4999", "tetra", "displacement")] < -0.3             # locked
    assert err[("nu=0.4999", "tetra", "nodal_pressure")] > err[("nu=0.4999", "tetra", "displacement")] + 0.15
    # compressible: the two tetra formulations are close to each other
    assert abs(err[("nu=0.3", "tetra", "nodal_pressure")] - err[("nu=0.3", "tetra", "displacement")]) < 0.1
    assert set(res["reference_checks"]["nu=0.4999"]) == {1, 2, 4}
    assert any("| 0.4999 | tetra | nodal_pressure |" in line for line in res["notes"])
