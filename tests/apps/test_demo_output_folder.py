"""`tensormass demo` says how its output folder was chosen: its default when no --out was given."""
from __future__ import annotations

import argparse

import pytest

from tensormass.apps import commands


@pytest.mark.parametrize("out, said", [
    (None, "the demo's default ./tensormass-demo, relative to the working directory (--out chooses another)"),
    ("elsewhere", "given on the command line (--out), relative to the working directory"),
])
def test_the_demo_names_where_its_folder_came_from(monkeypatch, capsys, out, said):
    seen = {}

    def fake_run_scene(scene, out=None, **kwargs):
        seen.update(kwargs, out=out)
        return {"exit_code": 0, "probes": {}, "output": {"pvd": None}}
    monkeypatch.setattr(commands, "run_scene", fake_run_scene)
    args = argparse.Namespace(out=out, json=None, overwrite=False, max_memory=None, quiet=True)
    assert commands.cmd_demo(args) == 0
    assert seen["dir_from"] == said
    assert str(seen["out"]) == (out or commands.DEMO_OUT)
    assert "given on the command line" not in said or out is not None


def test_the_summary_line_quotes_it(capsys):
    said = "the demo's default ./tensormass-demo, relative to the working directory (--out chooses another)"
    commands.print_summary({"output": {"dir": "tensormass-demo", "pvd": "tensormass-demo/frame.pvd", "frames": 2,
                                       "every": 1, "dir_from": said}})
    assert f"(2 frame(s), every 1 step(s); {said})" in capsys.readouterr().out
