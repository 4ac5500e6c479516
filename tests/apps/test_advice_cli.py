"""`tensormass run`: setup advice printed before the run and kept in the summary JSON (exit code
unchanged); formulation refusals and singular static runs exit 2 naming the key or the element."""
from __future__ import annotations

import json

from tensormass.apps.cli import main

SCENE = """
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [2, 1, 1]
element = "{element}"
[[material]]
law = "hooke"
quadrature = "{quadrature}"
E = 1.0e6
nu = {nu}
{more}
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[[loads.force]]
box = [[1.0, -1, -1], [1.0, 1, 1]]
value = [0.0, 0.0, -0.1]
"""


def run(capsys, tmp_path, element="tetra", quadrature="gauss1", nu=0.49, more=""):
    path = tmp_path / "s.toml"
    path.write_text(SCENE.format(element=element, quadrature=quadrature, nu=nu, more=more))
    code = main(["run", str(path), "--json", str(tmp_path / "summary.json")])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_advice_is_printed_before_the_run_and_kept_in_the_summary(capsys, tmp_path):
    code, out, _ = run(capsys, tmp_path)
    line = ('advice: material[0]: nu = 0.49 on tetra with the displacement formulation locks (too stiff); '
            'use formulation = "nodal_pressure"')
    assert code == 0 and line in out.splitlines()[:3]              # among the setup lines, before the summary
    assert out.index(line) < out.index("status")
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["advice"] == [line.removeprefix("advice: ")]
    assert data["status"] == "ok" and data["exit_code"] == 0 and data["warnings"] == []


def test_no_advice_is_an_empty_list(capsys, tmp_path):
    code, out, _ = run(capsys, tmp_path, nu=0.3)
    assert code == 0 and "advice:" not in out
    assert json.loads((tmp_path / "summary.json").read_text())["advice"] == []


def test_a_formulation_the_element_lacks_exits_2_with_the_key(capsys, tmp_path):
    code, out, err = run(capsys, tmp_path, more='formulation = "mean_dilatation"')
    assert code == 2 and "material[0].formulation: tetra: mean_dilatation does not apply" in err
    assert "Traceback" not in err and not (tmp_path / "summary.json").exists()


def test_a_singular_static_hexahedral_run_exits_2_before_any_file(capsys, tmp_path):
    code, out, err = run(capsys, tmp_path, element="hexahedron", nu=0.3)
    assert code == 2 and "static solve refused: the stiffness at rest is singular, hexahedron" in err
    assert "advice: material[0]: hexahedron with quadrature 'gauss1' has 12 spurious" in out
    assert "Traceback" not in err and not (tmp_path / "summary.json").exists()
