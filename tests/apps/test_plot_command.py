"""`tensormass plot SUMMARY.json [-o PNG] [--what ...]`: exit codes, outputs, refusals."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from tensormass.apps.cli import main

DATA = Path(__file__).resolve().parent / "data"


def _summary(tmp_path, name="summary_dynamic_s5.json"):
    target = tmp_path / "run.json"
    shutil.copy(DATA / name, target)
    return target


def _is_png(path):
    return path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_default_output_is_beside_the_summary(tmp_path, capsys):
    source = _summary(tmp_path)
    assert main(["plot", str(source)]) == 0
    assert _is_png(tmp_path / "run.png")
    assert "wrote" in capsys.readouterr().out
    assert sorted(os.listdir(tmp_path)) == ["run.json", "run.png"]


def test_output_and_groups(tmp_path, capsys):
    source = _summary(tmp_path, "summary_static_s5.json")
    out = tmp_path / "curves.png"
    assert main(["plot", str(source), "-o", str(out), "--what", "solver", "--quiet"]) == 0
    assert _is_png(out) and capsys.readouterr().out == ""


@pytest.mark.parametrize("case", ["missing", "folder", "not ours", "no history", "group absent",
                                  "unknown group", "bad output", "output folder missing", "output is summary"])
def test_refusals_exit_2_and_write_nothing(tmp_path, capsys, case):
    source = _summary(tmp_path)
    args = ["plot", str(source)]
    expect = {
        "missing": "no such file", "folder": "is a folder", "not ours": "not a tensormass run summary",
        "no history": "no per-step history", "group absent": "nothing to plot",
        "unknown group": "unknown plot group", "bad output": "must end in .png",
        "output folder missing": "does not exist", "output is summary": "must end in .png",
    }[case]
    if case == "missing":
        args[1] = str(tmp_path / "nope.json")
    elif case == "folder":
        (tmp_path / "dir.json").mkdir()
        args[1] = str(tmp_path / "dir.json")
    elif case == "not ours":
        source.write_text(json.dumps({"per_step": {"step": [1]}}))
    elif case == "no history":
        data = json.loads(source.read_text())
        data["per_step"] = None
        source.write_text(json.dumps(data))
    elif case == "group absent":
        args += ["--what", "reactions"]
    elif case == "unknown group":
        args += ["--what", "stress"]
    elif case == "bad output":
        args += ["-o", str(tmp_path / "x.pdf")]
    elif case == "output folder missing":
        args += ["-o", str(tmp_path / "no" / "x.png")]
    elif case == "output is summary":
        args += ["-o", str(source)]
    before = sorted(os.listdir(tmp_path))
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("tensormass: error: ") and expect in err and err.count("\n") == 1, err
    assert sorted(os.listdir(tmp_path)) == before
