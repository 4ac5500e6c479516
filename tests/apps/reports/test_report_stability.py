"""`tensormass report stability`: the quick suite runs, every case meets its expectation, files are clean."""
from __future__ import annotations

import argparse
import csv
import re

import numpy as np
import pytest

from tensormass.apps.reports import stability, stability_runs
from tensormass.apps.reports.stability import COLUMNS, add_stability_command, min_det_F, run_stability


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("stability")
    rows = run_stability(out, quick=True, progress=None)
    return out, rows


def _csv(out):
    with open(out / "stability.csv", newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _find(rows, case, law):
    hits = [r for r in rows if r["case"].startswith(case) and r["law"] == law]
    assert hits, f"no case {case!r} for {law}"
    return hits


@pytest.mark.heavy          # the report's quick run, 10 to 45 s cold: CI's heavy step
def test_csv_columns_and_rows(quick):
    out, rows = quick
    table = _csv(out)
    with open(out / "stability.csv", encoding="utf-8") as fh:
        header = fh.readline().strip().split(",")
    assert tuple(header) == COLUMNS
    assert len(table) == len(rows) >= 20
    outcomes = {"stable", "recovered", "diverged (detected)", "invalid (detected)", "buckled (detected by the report)"}
    for r in table:
        assert r["outcome"] in outcomes or re.fullmatch(r"refused \(.+\)", r["outcome"]), r["outcome"]


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_no_nan_anywhere(quick):
    out, _ = quick
    for name in ("stability.csv", "report.md"):
        text = (out / name).read_text(encoding="utf-8")
        assert not re.search(r"\bnan\b", text, flags=re.IGNORECASE), name
        assert not re.search(r"\binf\b", text, flags=re.IGNORECASE), name
    for r in _csv(out):
        for c in ("dt", "max_energy", "max_abs_u", "min_det_F", "wall_time"):
            if r[c] != "":
                assert np.isfinite(float(r[c])), (r["case"], c, r[c])
    assert not list(out.glob("*.tmp")), "temporary files left behind"


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_every_case_ok(quick):
    out, rows = quick
    bad = [(r["case"], r["law"], r["outcome"], r["message"]) for r in rows if not r["ok"]]
    assert not bad
    assert all(r["ok"] == "True" for r in _csv(out))


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_expected_outcomes(quick):
    out, _ = quick
    table = _csv(out)
    two = [r for r in table if r["case"].startswith("explicit 2x")]
    assert len(two) == 1 and two[0]["outcome"] == "diverged (detected)"
    assert "unstable" in two[0]["message"]
    half = [r for r in table if r["case"].startswith("explicit 0.5x")]
    assert half[0]["outcome"] == "stable"
    nu5 = [r for r in table if r["case"] == "poisson nu=0.5"]
    assert len(nu5) == 1 and nu5[0]["outcome"].startswith("refused (") and "nu" in nu5[0]["outcome"]
    assert _find(table, "scramble and release", "stable_neohookean")[0]["outcome"] == "recovered"
    assert _find(table, "squash", "stable_neohookean")[0]["outcome"] == "recovered"
    neo = _find(table, "scramble and release", "neohookean")
    assert all(r["outcome"] == "diverged (detected)" or r["outcome"].startswith("refused (") for r in neo)
    inv = _find(table, "inverted rest element", "stvk")[0]
    assert inv["outcome"].startswith("refused (") and re.search(r"\b1\b", inv["message"])
    rot = {r["law"]: r for r in table if r["case"].startswith("rigid rotation")}
    assert set(rot) >= {"hooke", "stvk"} and all(r["outcome"] == "stable" for r in rot.values())
    for r in table:
        if r["case"].startswith(("stiffness", "large dt")) and r["case"] != "stiffness E=1e+03":
            assert r["outcome"] == "stable", r
    # the case: a bar too soft for its weight collapses with inverted StVK elements; the
    # report once called that "stable" with min det F < 0 in its own CSV
    for r in (r for r in table if r["case"] == "stiffness E=1e+03"):
        assert r["outcome"] != "stable" or float(r["min_det_F"]) > 0, r
        assert not (r["min_det_F"] and float(r["min_det_F"]) <= 0 and r["outcome"] in ("stable", "recovered")), r


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_report_md(quick):
    out, rows = quick
    text = (out / "report.md").read_text(encoding="utf-8")
    assert text.startswith("# Stability report")
    assert "| case | law |" in text
    assert text.count("\n- **") == len(rows)
    assert "NOT met" not in text


def test_min_det_F_matches_kernel():
    from tensormass.runtime.model.model import Model
    from tensormass.runtime.scene.scene import Scene
    model = Model.from_scene(Scene.from_dict(stability_runs.scene_dict("stvk", "backward_euler", 0.1, 1, fixed=None)))
    u = np.zeros(model.n_dofs)
    assert min_det_F(model, u) == pytest.approx(1.0)
    X = model.mesh.points
    u = (-1.5 * X).ravel()                      # x -> -x/2: det F = -1/8 everywhere
    assert min_det_F(model, u) == pytest.approx(-0.125)
    part = model.parts[0]
    assert part.kernel.inverted(part.D, model.element_displacements(part, u)).all()


def _parser():
    parser = argparse.ArgumentParser(prog="tensormass")
    sub = parser.add_subparsers(dest="command", required=True)
    add_stability_command(sub)
    return parser


def test_cli_route(tmp_path, monkeypatch):
    calls = []

    def fake(out_dir, quick=False, progress=print):
        calls.append((str(out_dir), quick))
        return [{"ok": True}, {"ok": ok_second}]

    monkeypatch.setattr(stability, "run_stability", fake)
    args = _parser().parse_args(["stability", "--quick", "--out", str(tmp_path)])
    ok_second = True
    assert args.run(args) == 0
    ok_second = False
    assert args.run(args) == 1
    assert calls == [(str(tmp_path), True)] * 2
    args = _parser().parse_args(["stability", "--out", "x"])
    assert args.quick is False
    with pytest.raises(SystemExit):
        _parser().parse_args(["stability", "--quick"])          # --out is required


@pytest.mark.heavy          # the report's quick run through the CLI, 45 s cold: CI's heavy step
def test_cli_quick_end_to_end(tmp_path):
    args = _parser().parse_args(["stability", "--quick", "--out", str(tmp_path / "out")])
    assert args.run(args) == 0
    assert (tmp_path / "out" / "stability.csv").exists() and (tmp_path / "out" / "report.md").exists()


def test_report_parser_route(tmp_path, monkeypatch):
    """The runtime's `report stability` sub-command reaches this module."""
    pytest.importorskip("tensormass.apps.reports.accuracy")     # owned by the accuracy report
    from tensormass.apps.reports import add_report_command
    monkeypatch.setattr(stability, "run_stability", lambda out, quick=False, progress=print: [{"ok": True}])
    parser = argparse.ArgumentParser(prog="tensormass")
    add_report_command(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["report", "stability", "--quick", "--out", str(tmp_path)])
    assert args.run(args) == 0


@pytest.mark.heavy          # the report's quick run (its module fixture), 15 to 50 s cold: CI's heavy step
def test_spring_lattices_buckle_without_face_diagonals(quick):
    """Thesis Fig. 7.3 / 7.6: squeezed 20 %, MSS-Baudet and HybMSS-FD lose their symmetry, HybMSS holds."""
    _, rows = quick
    got = {r["law"]: r["outcome"] for r in rows if r["case"].startswith("spring compression")}
    assert got == {"mss": "buckled (detected by the report)", "hybmss A=0": "buckled (detected by the report)",
                   "hybmss A=1": "stable"}
    assert {r["outcome"] for r in rows if r["case"].startswith("springs explicit 2x")} == {"diverged (detected)"}


def test_asymmetry_measure():
    from tensormass.apps.reports.springs_stability import asymmetry
    points = np.array([[x, y, 0.0] for x in (0.0, 0.5, 1.0) for y in (0.0, 1.0)])
    symmetric = np.column_stack([points[:, 0] - 0.5, np.zeros(6), -np.ones(6)])      # u_x odd, u_z even
    assert asymmetry(points, symmetric, 1.0) == 0.0
    bent = symmetric.copy()
    bent[:, 1] = points[:, 0]                                                          # u_y not even
    assert asymmetry(points, bent, 1.0) == pytest.approx(1.0, rel=1e-12)        # |x - (1 - x)| / max|u|
