"""`tensormass report accuracy SCENE` on a scene whose mesh is a file (apps/reports/file_levels.py)."""
from __future__ import annotations

import csv
import math
from pathlib import Path

import meshio
import pytest

from tensormass.apps.reports.accuracy import COLUMNS, run_accuracy
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.mesh.io import to_meshio

DATA = Path(__file__).resolve().parent / "data"
ROOT = Path(__file__).resolve().parents[3]

ROD = """
name = "rod"
[mesh]
file = "{mesh}"
[[material]]
region = "{region}"
law = "hooke"
quadrature = "gauss2"
E = 1.0e8
nu = 0.3
density = 1000.0
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0.0, 0.0, -9.81]
[[probe]]
name = "tip"
point = [1.0, 0.0, 0.0]
"""


def _table(path):
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        return reader.fieldnames, list(reader)


def test_a_tetra_file_is_refined_and_raised_to_tetra10(tmp_path):
    """The gmsh rod (222 tetra, a file relative to the scene): tetra and raised tetra10 on 2 levels of
    uniform refinement; the finest tetra10 run is the reference and both elements converge to it."""
    scene = tmp_path / "rod.toml"
    scene.write_text(ROD.format(mesh=DATA / "rod_tetra.msh", region="tetra"))   # region follows the element
    lines = []
    rows = run_accuracy(tmp_path / "out", scene_path=scene, quick=True, progress=lines.append)
    header, table = _table(tmp_path / "out" / "results.csv")
    assert header == COLUMNS
    assert [(r["element"], r["cells"]) for r in table] == [("tetra", "222"), ("tetra", "1776"),
                                                          ("tetra10", "222"), ("tetra10", "1776")]
    err = [r["error_reference"] for r in rows]
    assert err[3] == 0.0 and err[1] < err[0] and err[2] < err[1]     # raised tetra10 beats refined tetra
    assert all(math.isnan(r["error_analytic"]) for r in rows)        # no beam formula for a file mesh
    report = (tmp_path / "out" / "report.md").read_text()
    assert "uniform (red) refinement" in report and "raised from tetra" in report
    assert (tmp_path / "out" / "convergence.png").read_bytes().startswith(b"\x89PNG")
    assert any("222 tetra cells" in line for line in lines)


def test_a_curved_tetra10_file_keeps_its_geometry(tmp_path):
    """gmsh's second-order rod (curved midside nodes): refined through each cell's quadratic map, the
    tip deflection approaches beam theory for the true circular section (its faceted corners do not)."""
    scene = tmp_path / "rod10.toml"
    scene.write_text(ROD.format(mesh=DATA / "rod_tetra10.msh", region="all"))
    rows = run_accuracy(tmp_path / "out", scene_path=scene, quick=True, progress=None,
                        elements=["tetra10", "tetra"])
    assert [(r["element"], r["cells"]) for r in rows] == [("tetra10", "222"), ("tetra10", "1776"),
                                                         ("tetra", "222"), ("tetra", "1776")]
    r, rho, g, E, nu, L = 0.1, 1000.0, 9.81, 1.0e8, 0.3, 1.0
    A, I = math.pi * r ** 2, math.pi * r ** 4 / 4
    timoshenko = rho * g * A * L ** 4 / (8 * E * I) + rho * g * L ** 2 / (2 * 0.9 * E / (2 * (1 + nu)))
    assert rows[1]["value"] == pytest.approx(timoshenko, rel=0.03)
    assert rows[1]["error_reference"] == 0.0 and 0 < rows[0]["error_reference"] < 0.02


def test_the_file_sweep_matches_the_generated_sweep_on_the_same_mesh(tmp_path):
    """An existing example (examples/cantilever_tetra.toml) with its generated mesh written to a file:
    the first level of both sweeps is the same mesh, so the same tip displacement."""
    text = (ROOT / "examples" / "cantilever_tetra.toml").read_text()
    text = text.replace("cells = [24, 4, 4]", "cells = [6, 1, 1]")
    generated = tmp_path / "generated.toml"
    generated.write_text(text)
    meshio.write(tmp_path / "bar.vtu", to_meshio(generate_bar((1.2, 0.2, 0.2), (6, 1, 1), "tetra")))
    start, end = text.index('generate = "bar"'), text.index('element = "tetra"') + len('element = "tetra"')
    from_file = tmp_path / "from_file.toml"
    from_file.write_text(text[:start] + 'file = "bar.vtu"' + text[end:])
    a = run_accuracy(tmp_path / "a", scene_path=generated, progress=None, levels=1)
    b = run_accuracy(tmp_path / "b", scene_path=from_file, progress=None, levels=2, elements=["tetra"])
    assert a[0]["value"] == pytest.approx(b[0]["value"], rel=1e-12) and a[0]["dofs"] == b[0]["dofs"]
    assert b[1]["cells"] == str(8 * 6 * 6) and b[1]["value"] > b[0]["value"]   # refined: less stiff
    assert not (tmp_path / "out").exists()                   # [output] dir of the example: not written


def test_other_file_meshes_are_swept_as_read_with_a_clear_message(tmp_path):
    meshio.write(tmp_path / "hex.vtu", to_meshio(generate_bar((1.0, 0.2, 0.2), (4, 1, 1), "hexahedron")))
    scene = tmp_path / "hex.toml"
    scene.write_text(ROD.format(mesh="hex.vtu", region="all").replace("[1.0, 0.0, 0.0]", "[1.0, 0.1, 0.1]"))
    with pytest.raises(TensormassError, match=r"--levels 2: the mesh file .*hex\.vtu has 4 hexahedron cells, and "
                                              r"uniform refinement of a mesh file is supported for triangle and tetra"):
        run_accuracy(tmp_path / "o", scene_path=scene, progress=None, levels=2)
    with pytest.raises(TensormassError, match=r"so --elements can only be hexahedron"):
        run_accuracy(tmp_path / "o", scene_path=scene, progress=None, elements=["tetra"])
    assert not (tmp_path / "o").exists()
    rows = run_accuracy(tmp_path / "o", scene_path=scene, progress=None, laws=["hooke", "stvk"])
    assert [(r["element"], r["law"], r["cells"]) for r in rows] == [("hexahedron", "hooke", "4"),
                                                                    ("hexahedron", "stvk", "4")]
    assert "swept as read" in (tmp_path / "o" / "report.md").read_text()
    tet = tmp_path / "tet.toml"
    tet.write_text(ROD.format(mesh=DATA / "rod_tetra.msh", region="all"))
    with pytest.raises(TensormassError, match=r"--elements hexahedron: .* can be swept as tetra or tetra10"):
        run_accuracy(tmp_path / "o2", scene_path=tet, progress=None, elements=["hexahedron"])
