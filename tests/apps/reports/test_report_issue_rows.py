"""The cylinder (prism and hexahedral layers against Lame) and the Newton-iteration rows near
incompressibility are benchmarks of `report accuracy`."""
import pytest

from tensormass.apps.reports.accuracy import BENCHMARK_NAMES, _benchmark_task


def test_cylinder_and_incompressible_are_accuracy_benchmarks():
    assert {"cylinder", "incompressible"} <= set(BENCHMARK_NAMES)


@pytest.mark.heavy          # the report's quick run, 10 to 45 s cold: CI's heavy step
def test_the_quick_cylinder_shows_prism_locking_and_its_cure():
    result, _ = _benchmark_task("cylinder", True, None)
    rows = {(r["element"], r["formulation"], r["case"], r["cells"]): r for r in result["rows"]}
    finest = max(r["cells"] for r in result["rows"] if r["element"] == "wedge")
    locked = [r for (e, f, c, n), r in rows.items() if e == "wedge" and f == "displacement" and "0.499" in c and n == finest]
    cured = [r for (e, f, c, n), r in rows.items() if e == "wedge" and f == "nodal_pressure" and "0.499" in c and n == finest]
    assert locked and cured
    assert abs(cured[0]["error_analytic"]) < 0.05 < abs(locked[0]["error_analytic"])
