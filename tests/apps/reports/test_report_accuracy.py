"""`tensormass report accuracy`: a tiny sweep, the user-scene path and the CLI route."""
from __future__ import annotations

import argparse
import csv
import math

import pytest

from tensormass.apps.reports.accuracy import COLUMNS, add_accuracy_command, pareto_front, run_accuracy

PNG = b"\x89PNG\r\n\x1a\n"

TINY = {"elements": ["hexahedron", "tetra", "tetra10"], "laws": ["hooke"], "quadratures": {"tetra": ["gauss1"]},
        "levels": [[6, 1, 1], [12, 2, 2]], "levels_quadratic": [[6, 1, 1]], "reference": [12, 2, 2]}

SCENE = """
name = "tiny"
[mesh]
generate = "bar"
size = [1.2, 0.2, 0.2]
cells = [4, 1, 1]
element = "hexahedron"
[[material]]
law = "hooke"
quadrature = "gauss2"
E = 1.0e8
nu = 0.3
density = 800.0
[[fixed]]
box = [[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]
[loads]
gravity = [0.0, 0.0, -9.81]
[[probe]]
name = "tip"
point = [1.2, 0.1, 0.1]
[output]
dir = "should_not_be_written"
"""


def _read(path):
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        return reader.fieldnames, list(reader)


def _check_outputs(out):
    for name in ("error_vs_time.png", "convergence.png"):
        data = (out / name).read_bytes()
        assert len(data) > 1000 and data.startswith(PNG), name
    assert not list(out.glob("*.tmp"))
    report = (out / "report.md").read_text()
    assert "Pareto front" in report
    return report


@pytest.fixture(scope="module")
def builtin(tmp_path_factory):
    out = tmp_path_factory.mktemp("accuracy")
    lines = []
    rows = run_accuracy(out, quick=True, progress=lines.append, _sweep=TINY)
    return out, rows, lines


@pytest.mark.heavy          # the report's quick run, 10 to 45 s cold: CI's heavy step
def test_builtin_results_csv(builtin):
    out, rows, lines = builtin
    header, table = _read(out / "results.csv")
    assert header == COLUMNS
    assert len(table) == len(rows) == 5        # 2 hexahedron + 2 tetra + 1 tetra10
    for r in table:
        assert r["benchmark"] == "cantilever"
        assert r["formulation"] == "displacement"
        for key in COLUMNS[COLUMNS.index("dofs"):]:
            value = float(r[key])
            assert math.isfinite(value) and value > 0, (key, r)
    assert {r["element"] for r in table} == {"hexahedron", "tetra", "tetra10"}
    assert any("reference" in line for line in lines)


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_builtin_errors_decrease_for_hexahedron(builtin):
    _, rows, _ = builtin
    hexa = [r for r in rows if r["element"] == "hexahedron"]
    assert [r["cells"] for r in hexa] == ["6x1x1", "12x2x2"]
    assert hexa[1]["error_reference"] < hexa[0]["error_reference"]
    assert hexa[1]["error_analytic"] < hexa[0]["error_analytic"]
    assert hexa[1]["dofs"] > hexa[0]["dofs"]


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_builtin_plots_and_report(builtin):
    out, rows, _ = builtin
    report = _check_outputs(out)
    assert "tetra10 / hooke / gauss2 on 12x2x2" in report        # the numerical reference is named
    assert "Timoshenko" in report


def test_pareto_front():
    rows = [{"time_total": t, "error_reference": e} for t, e in [(1, 0.5), (2, 0.6), (3, 0.1), (0.5, 0.9), (4, 0.1)]]
    assert pareto_front(rows) == [3, 0, 2]


@pytest.mark.heavy          # a convergence sweep of a user scene, 15 s cold: CI's heavy step
def test_user_scene(tmp_path):
    scene = tmp_path / "tiny.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    rows = run_accuracy(out, scene_path=scene, quick=True, progress=lambda *_: None)
    header, table = _read(out / "results.csv")
    assert header == COLUMNS
    assert [r["cells"] for r in table] == ["4x1x1", "8x2x2"]
    assert rows[-1]["error_reference"] == 0.0                  # the finest run is the reference
    assert 0 < rows[0]["error_reference"] < 1
    assert all(math.isfinite(r["error_analytic"]) for r in rows)  # a bar under gravity probed at x = L
    _check_outputs(out)
    assert not (tmp_path / "should_not_be_written").exists()


def test_user_scene_needs_generated_mesh(tmp_path):
    from tensormass.runtime.base.errors import TensormassError
    scene = tmp_path / "noprobe.toml"
    scene.write_text(SCENE.split("[[probe]]")[0])
    with pytest.raises(TensormassError, match="probe"):
        run_accuracy(tmp_path / "out", scene_path=scene, quick=True, progress=None)
    assert not (tmp_path / "out").exists()


def test_cli_route(tmp_path, monkeypatch):
    parser = argparse.ArgumentParser(prog="tensormass")
    sub = parser.add_subparsers(dest="command", required=True)
    add_accuracy_command(sub)
    args = parser.parse_args(["accuracy", "--quick", "--out", str(tmp_path / "o")])
    assert args.scene is None and args.quick and args.out == str(tmp_path / "o")
    args = parser.parse_args(["accuracy", "beam.toml", "--out", "d"])
    assert args.scene == "beam.toml" and not args.quick and args.benchmark is None
    args2 = parser.parse_args(["accuracy", "--benchmark", "beam2d", "volume", "--out", "d"])
    assert args2.benchmark == ["beam2d", "volume"]
    with pytest.raises(SystemExit):
        parser.parse_args(["accuracy", "--benchmark", "nope", "--out", "d"])
    with pytest.raises(SystemExit):
        parser.parse_args(["accuracy"])                        # --out is required
    calls = []
    import tensormass.apps.reports.accuracy as acc
    monkeypatch.setattr(acc, "run_accuracy", lambda out, scene_path=None, quick=False: calls.append((out, scene_path, quick)))
    assert args.run(args) == 0
    assert calls == [("d", "beam.toml", False)]


def test_report_cli_route(tmp_path):
    """Through `report accuracy` (apps/reports/__init__.py), with a real tiny scene."""
    from tensormass.apps.reports import add_report_command
    scene = tmp_path / "tiny.toml"
    scene.write_text(SCENE)
    parser = argparse.ArgumentParser(prog="tensormass")
    sub = parser.add_subparsers(dest="command", required=True)
    add_report_command(sub)
    args = parser.parse_args(["report", "accuracy", str(scene), "--quick", "--out", str(tmp_path / "r")])
    assert args.run(args) == 0
    assert (tmp_path / "r" / "results.csv").exists()


# -- the other built-in benchmarks, shrunk -----------------------------------------------------------
SHRUNK = {
    "beam2d": {"elements": ["triangle", "triangle6"], "levels": [[6, 1], [12, 2]], "claim": False,
               "reference": [24, 4]},
    "volume": {"laws": ["hooke"], "nus": [0.0, 0.499], "strains": [0.05], "cells": [2, 2, 2],
               "formulations": ["displacement"]},
    "mixed": {"elements": ["mixed", "tetra10"], "levels": [[16, 2, 2]], "reference": [16, 2, 2]},
    "large_deflection": {"laws": ["hooke", "neohookean"], "levels": [[6, 1, 1]], "reference": [12, 2, 2],
                         "steps": 3, "load_scales": [0.1, 1.0], "load_cells": [6, 1, 1]},
}


@pytest.fixture(scope="module")
def others(tmp_path_factory):
    out = tmp_path_factory.mktemp("benchmarks")
    rows = run_accuracy(out, quick=True, progress=lambda *_: None, _sweep=SHRUNK,
                        benchmarks=["beam2d", "volume", "mixed", "large_deflection"])
    return out, rows


@pytest.mark.heavy          # the report's quick run, 10 to 45 s cold: CI's heavy step
def test_benchmarks_rows_and_column(others):
    out, rows = others
    header, table = _read(out / "results.csv")
    assert header == COLUMNS and header[0] == "benchmark"
    assert [r["benchmark"] for r in table] == [r["benchmark"] for r in rows]
    counts = {b: sum(r["benchmark"] == b for r in table) for b in SHRUNK}
    assert counts == {"beam2d": 4, "volume": 2, "mixed": 2, "large_deflection": 2}
    report = _check_outputs(out)
    for b in SHRUNK:
        assert f"## Benchmark `{b}`" in report
    assert "thesis' FEM" in report and "Hooke's error" in report


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_volume_change(others):
    _, rows = others
    vol = {r["case"]: r["value"] for r in rows if r["benchmark"] == "volume"}
    assert abs(vol["nu=0 compression=5%"] - 5.0) < 0.5
    assert 0 <= vol["nu=0.499 compression=5%"] < 1.0


def test_mean_dilatation_keeps_the_volume_of_a_compressed_cube():
    """nu = 0.499, 20 % compression, neo-Hookean hexahedra: the issue's target (volume loss <= 0.2 %)
    with mean dilatation; the displacement formulation loses several times more."""
    from tensormass.apps.reports.benchmarks import volume
    res = volume(True, lambda *_: None, {"laws": ["neohookean"], "nus": [0.499], "strains": [0.2],
                                          "cells": [2, 2, 2], "formulations": ["displacement", "mean_dilatation"]})
    loss = {r["formulation"]: r["value"] for r in res["rows"]}
    assert 0 <= loss["mean_dilatation"] <= 0.2
    assert loss["displacement"] > 3 * loss["mean_dilatation"]
    assert any("| neohookean | mean_dilatation | 20% | 0.499 |" in line for line in res["notes"])


def test_deformed_volume_of_a_sheared_hexahedron():
    import numpy as np
    from tensormass.runtime.mesh.bars import generate_bar
    from tensormass.apps.reports.benchmarks import deformed_volume
    mesh = generate_bar((2.0, 1.0, 1.0), (2, 1, 1), "hexahedron")
    u = np.zeros_like(mesh.points)
    assert deformed_volume(mesh, u) == pytest.approx(2.0)
    u[:, 0] = 0.3 * mesh.points[:, 2]                      # simple shear keeps the volume
    u[:, 2] = -0.1 * mesh.points[:, 2]                     # 10 % compression
    assert deformed_volume(mesh, u) == pytest.approx(1.8)


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_beam2d_quadratic_beats_linear(others):
    _, rows = others
    beam = {(r["element"], r["cells"]): r for r in rows if r["benchmark"] == "beam2d"}
    t6, t3 = beam[("triangle6", "6x1")], beam[("triangle", "12x2")]    # 72 dofs each
    assert t6["dofs"] == t3["dofs"]
    assert t6["error_reference"] < t3["error_reference"]


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_mixed_and_large_deflection(others):
    _, rows = others
    mixed = {r["element"]: r for r in rows if r["benchmark"] == "mixed"}
    assert mixed["tetra10"]["error_reference"] == 0.0           # it is the reference here
    assert 0 < mixed["mixed"]["error_reference"] < 0.5
    large = {r["law"]: r for r in rows if r["benchmark"] == "large_deflection"}
    assert large["hooke"]["value"] > large["neohookean"]["value"] > 0.15   # metres: a large deflection


# -- shear and torsion of the 5 m cube, shrunk ---------------------------------------------------------
CUBE_SHRUNK = {"elements": ["hexahedron", "tetra10"], "levels": [[2, 2, 2], [4, 4, 4], [8, 8, 8]],
               "levels_quadratic": [[1, 1, 1], [2, 2, 2]]}


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    out = tmp_path_factory.mktemp("cube")
    rows = run_accuracy(out, quick=True, progress=lambda *_: None, benchmarks=["shear", "torsion"],
                        _sweep={"shear": CUBE_SHRUNK, "torsion": CUBE_SHRUNK})
    return out, rows


@pytest.mark.parametrize("kind", ["shear", "torsion"])
def test_cube_against_thesis_formula_and_convergence(cube, kind):
    from tensormass.apps.reports.benchmarks import shear_analytic, torsion_analytic
    out, rows = cube
    analytic = shear_analytic() if kind == "shear" else torsion_analytic()
    mine = [r for r in rows if r["benchmark"] == kind]
    assert [(r["element"], r["cells"]) for r in mine] == [
        ("hexahedron", "2x2x2"), ("hexahedron", "4x4x4"), ("hexahedron", "8x8x8"),
        ("tetra10", "1x1x1"), ("tetra10", "2x2x2")]
    for r in mine:
        assert 0.5 < r["value"] / analytic < 2.0, r           # the thesis formula is an estimate: loose band
        assert r["error_analytic"] == pytest.approx(abs(r["value"] / analytic - 1.0))
    hexa = [r["value"] for r in mine if r["element"] == "hexahedron"]
    assert abs(hexa[2] - hexa[1]) < abs(hexa[1] - hexa[0])   # converging: the finest two agree better
    assert abs(hexa[2] - hexa[1]) < 0.1 * analytic            # the finest two agree to 10 %
    assert hexa[2] < hexa[0]                                  # refinement softens the response
    ref = [r for r in mine if r["error_reference"] == 0.0]
    assert [(r["element"], r["cells"]) for r in ref] == [("tetra10", "2x2x2")]   # the finest tetra10 run
    report = (out / "report.md").read_text()
    assert f"## Benchmark `{kind}`" in report and "/ thesis formula" in report


def test_cube_reactions_sign_and_linearity():
    """Reactions push back along the prescribed motion; the torque is ~linear in a small angle."""
    import numpy as np
    from tensormass.apps.reports.benchmarks import cube_run
    s, _, f = cube_run("shear", "hexahedron", [2, 2, 2], trace=False)
    _, _, t = cube_run("torsion", "hexahedron", [2, 2, 2], theta=0.02, trace=False)
    _, _, t1 = cube_run("torsion", "hexahedron", [2, 2, 2], theta=0.01, trace=False)
    assert f > 0 and t > 0
    assert t == pytest.approx(2 * t1, rel=1e-3)      # exact rotation: cos(theta) - 1 is O(theta^2)
    assert np.isfinite(s.time["total"])


# -- user-scene sweep over listed settings ---------------------------------------------------------------
@pytest.mark.heavy          # the report's quick run, 10 to 45 s cold: CI's heavy step
def test_user_scene_settings_sweep(tmp_path):
    scene = tmp_path / "tiny.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    rows = run_accuracy(out, scene_path=scene, quick=True, progress=lambda *_: None,
                        elements=["hexahedron", "tetra10"], laws=["hooke", "stvk"], quadratures=["gauss2", "exact"],
                        levels=2)
    header, table = _read(out / "results.csv")
    assert header == COLUMNS and len(table) == len(rows)
    combos = [(r["element"], r["law"], r["quadrature"], r["cells"]) for r in table]
    expected = [(e, l, q, c) for e in ("hexahedron", "tetra10") for l in ("hooke", "stvk")
                for q in ("gauss2", "exact") if not (e == "hexahedron" and q == "exact")
                for c in ("4x1x1", "8x2x2")]
    assert combos == expected                                  # one row per valid combination x level
    ref = [r for r in rows if r["error_reference"] == 0.0]
    assert {(r["element"], r["quadrature"], r["cells"]) for r in ref} >= {("tetra10", "exact", "8x2x2")}
    assert all(math.isfinite(r["error_reference"]) for r in rows)
    report = _check_outputs(out)
    assert "skipped hexahedron / hooke / exact" in report and "skipped hexahedron / stvk / exact" in report
    assert "finest run of tetra10 / hooke / exact" in report


def test_user_scene_settings_cli(tmp_path, monkeypatch):
    from tensormass.runtime.base.errors import TensormassError
    parser = argparse.ArgumentParser(prog="tensormass")
    sub = parser.add_subparsers(dest="command", required=True)
    add_accuracy_command(sub)
    args = parser.parse_args(["accuracy", "s.toml", "--elements", "hexahedron", "tetra10", "--laws", "hooke", "stvk",
                              "--quadratures", "gauss1", "gauss2", "--levels", "3", "--out", "d"])
    calls = []
    import tensormass.apps.reports.accuracy as acc
    monkeypatch.setattr(acc, "run_accuracy", lambda out, **kw: calls.append((out, kw)))
    assert args.run(args) == 0
    assert calls == [("d", {"scene_path": "s.toml", "quick": False, "elements": ["hexahedron", "tetra10"],
                            "laws": ["hooke", "stvk"], "quadratures": ["gauss1", "gauss2"], "levels": 3})]
    monkeypatch.undo()
    with pytest.raises(TensormassError, match="SCENE"):
        run_accuracy(tmp_path / "o", elements=["tetra"], progress=None)
    assert parser.parse_args(["accuracy", "--benchmark", "shear", "torsion", "--out", "d"]).benchmark == [
        "shear", "torsion"]


def test_adaptive_benchmarks(tmp_path):
    """adaptive_beam: adaptive hooke->stvk within 1 % of all-stvk where all-hooke is visibly off;
    refinement: R_S refinement from the coarsest mesh beats that mesh."""
    rows = run_accuracy(tmp_path / "out", quick=True, progress=lambda *_: None,
                        benchmarks=["adaptive_beam", "refinement"])
    static = {r["law"]: r for r in rows if r["benchmark"] == "adaptive_beam" and r["case"] == "static"}
    assert static["stvk"]["error_reference"] == 0
    assert static["hooke"]["error_reference"] > 0.02
    assert static["adaptive hooke->stvk"]["error_reference"] < 0.01
    refine = {r["case"]: r for r in rows if r["benchmark"] == "refinement"}
    adaptive = [r for case, r in refine.items() if case.startswith("R_S")]
    assert adaptive and all(r["error_reference"] < refine["uniform 12x2"]["error_reference"] for r in adaptive)
    assert "## Benchmark `adaptive_beam`" in (tmp_path / "out" / "report.md").read_text()
