"""`report accuracy --benchmark hybmss`: the thesis' chapter-7 comparisons (apps/reports/hybmss.py).

One small quick run (4^3 cube, three models, compression and shear at 5 %) shared by the checks.
"""
import csv
import math

import pytest

from tensormass.apps.reports.accuracy import COLUMNS, MODEL_COLUMNS, run_accuracy
from tensormass.apps.reports.hybmss import analytic, hybmss, hybmss_scene

SWEEP = {"cases": ["compression", "shear"], "strains": [0.05], "nus": [0.0, 0.499],
         "models": ["MSS-Baudet", "HybMSS", "FEM hooke"]}


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("hybmss")
    rows = run_accuracy(out, benchmarks=["hybmss"], quick=True, progress=None, _sweep={"hybmss": SWEEP})
    with open(out / "results.csv", newline="") as fh:
        reader = csv.DictReader(fh)
        table = list(reader)
    return rows, reader.fieldnames, table, (out / "report.md").read_text()


def _value(rows, model, case):
    hits = [r["value"] for r in rows if r["model"] == model and r["case"] == case]
    assert len(hits) == 1, (model, case, hits)
    return hits[0]


def test_analytic_references_are_the_thesis_numbers():
    assert analytic("shear", 0.05) == pytest.approx(3571.4, abs=0.1)
    assert analytic("shear", 0.20) == pytest.approx(14285.7, abs=0.1)
    assert analytic("torsion", 1.0) == pytest.approx(1227.2, abs=0.1)
    assert analytic("torsion", 45.0) == pytest.approx(55223, abs=1.0)
    assert analytic("compression", 0.05, 0.25) == pytest.approx(2.5)
    assert analytic("bending", 100.0) == pytest.approx(1.5 * 100 * 10 * 2.4 ** 4 / (1e7 * 0.4 ** 2))


@pytest.mark.heavy          # the report's quick run takes 60 s cold: CI's heavy step
def test_quick_report_rows_and_files(report):
    rows, header, table, md = report
    assert header == COLUMNS + MODEL_COLUMNS and len(table) == len(rows) == 9
    assert all(r["benchmark"] == "hybmss" and r["model"] for r in table)
    hyb = next(r for r in table if r["model"] == "HybMSS" and r["case"].startswith("shear"))
    assert float(hyb["thesis_value"]) == 3396.0 and float(hyb["reference_value"]) == pytest.approx(3571.43, abs=0.01)
    assert "Table 7.3" in md and "Table 7.5" in md and "(3396)" in md and "(5.61)" in md


@pytest.mark.heavy          # the report's quick run takes 60 s cold: CI's heavy step
def test_quick_numbers_are_sane(report):
    rows = report[0]
    # HybMSS shear force within 10 % of Timoshenko's 3571 N at 5 %
    shear = _value(rows, "HybMSS", "shear 5%")
    assert abs(shear - 3571.4) / 3571.4 < 0.10
    # HybMSS follows nu: ~eps at nu = 0, nearly incompressible at 0.499
    assert abs(_value(rows, "HybMSS", "compression 5% nu=0 clamped") - 5.0) < 0.5
    assert _value(rows, "HybMSS", "compression 5% nu=0.499 clamped") < 0.5
    # MSS-Baudet cannot: its volume change moves far less with nu than linear theory asks (5 % -> 0.01 %)
    mss0 = _value(rows, "MSS-Baudet", "compression 5% nu=0 clamped")
    mss1 = _value(rows, "MSS-Baudet", "compression 5% nu=0.499 clamped")
    assert mss1 > 2.0 and abs(mss0 - mss1) < 0.3 * (5.0 - 0.01)
    for r in rows:
        assert math.isfinite(r["value"]) and r["time_total"] > 0


def test_bad_case_and_model_are_refused():
    with pytest.raises(ValueError, match="unknown case 'bend'"):
        hybmss(True, None, {"cases": ["bend"]})
    with pytest.raises(ValueError, match="unknown model 'FEM'"):
        hybmss_scene("FEM", "shear", [1, 1, 1], 0.05)
