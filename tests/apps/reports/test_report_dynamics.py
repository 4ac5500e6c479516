"""`tensormass report accuracy --benchmark dynamics`, quick form: the table, the CSV columns, the errors."""
import csv
import math

from tensormass.apps.reports.accuracy import COLUMNS, run_accuracy
from tensormass.apps.reports.dynamics import DYNAMICS_COLUMNS


def test_dynamics_report_quick(tmp_path):
    sweep = {"dynamics": {"settings": ["exact", "interactive", "20 CG-IC iterations (the thesis)"], "duration": 0.1}}
    rows = run_accuracy(tmp_path, benchmarks=["dynamics"], quick=True, progress=None, _sweep=sweep)
    by = {r["setting"]: r for r in rows}
    assert set(by) == set(sweep["dynamics"]["settings"])
    # the exact step at dt = 10 ms against the dt / 4 reference: implicit Euler's own time error, not zero
    assert 0.01 < by["exact"]["error_reference"] < 0.5
    assert math.isnan(by["exact"]["error_exact_step"])
    assert 0 < by["interactive"]["error_exact_step"] < 0.01
    assert by["interactive"]["stiffness_refreshes"] >= 2
    assert by["20 CG-IC iterations (the thesis)"]["error_exact_step"] < 1e-3
    for r in rows:
        assert r["step_ms_p95"] >= 0 and r["step_ms_mean"] > 0
    with open(tmp_path / "results.csv", newline="") as f:
        header = next(csv.reader(f))
    assert header[:len(COLUMNS)] == COLUMNS and header[-len(DYNAMICS_COLUMNS):] == DYNAMICS_COLUMNS
    report = (tmp_path / "report.md").read_text()
    assert "| interactive | 10 |" in report and "error vs exact step" in report
