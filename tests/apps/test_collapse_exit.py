"""A run that collapses elements (det F = 0 exactly) is an untrusted run (exit 3 with a summary), not
bad input: the frame at the collapse is written with its health mark, never refused after the fact."""
import json
import warnings

from tensormass.apps.cli import main

COLLAPSE = """
[mesh]
generate = "bar"
size = [1.0, 1.0, 1.0]
cells = [2, 2, 2]
element = "tetra"
[[material]]
law = "stvk"
E = 1e6
nu = 0.3
[[fixed]]
box = [[-1, -1, -1e-9], [2, 2, 1e-9]]
[[fixed]]                                  # the top face pressed onto the bottom one
box = [[-1, -1, 0.999999], [2, 2, 2]]
displacement = [0.0, 0.0, -1.0]
[solver]
kind = "static"
steps = 1
"""


def test_a_stvk_collapse_ends_with_exit_3_and_a_summary(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "collapse.toml").write_text(COLLAPSE)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)          # no numpy warning leaks to the user
        code = main(["run", "collapse.toml", "--out", "out", "--json", "summary.json"])
    err = capsys.readouterr().err
    assert code == 3, err
    assert "run invalid" in err and "error:" not in err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "invalid"
    pvd = (tmp_path / "out" / "frame.pvd").read_text()
    assert "health warning (step 1)" in pvd and "undefined there (det F = 0), written as 0" in pvd
