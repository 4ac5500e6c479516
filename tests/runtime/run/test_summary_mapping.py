"""The Python API: sim.probes() gives the summary's probe values, and a Summary reads like the
summary.json of its run (the same keys and values), with or without files."""
from __future__ import annotations

import json

import numpy as np
import pytest

import tensormass as tm
from tensormass.runtime.base.errors import RunStopped

from run_scenes import END, IMPLICIT, TIP, bar

SCENE = bar(solver=IMPLICIT, backend="c", probes=(TIP, END))


def _scene():
    return tm.Scene.from_string(SCENE)


def _json(value):
    return json.loads(json.dumps(value))


def test_probes_in_on_step_are_the_summary_values(tmp_path):
    seen = []
    sim = tm.Simulation(_scene(), output=False, on_step=lambda s: seen.append(s.probes()))
    assert sim.probes() == {"tip": [0.0, 0.0, 0.0], "end": [0.0, 0.0, 0.0]}      # before the first step
    summary = sim.run()
    assert len(seen) == 3 and seen[-1] == summary.probes == summary["probes"] == sim.probes()
    assert seen[0]["tip"][2] < 0 and seen[0] != seen[-1]
    assert summary.per_step["probes"]["tip"][-1] == pytest.approx(seen[-1]["tip"])


def test_a_summary_reads_like_its_summary_json(tmp_path):
    summary = tm.Simulation(_scene(), output=tmp_path / "out").run()
    written = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert list(summary.keys()) == list(written.keys())
    assert _json(dict(summary)) == written
    assert summary["output"]["summary"] == str(tmp_path / "out" / "summary.json")
    assert summary["scene"]["name"] == "bar" and summary["format"] == written["format"]
    assert "output" in summary and summary.get("no such key") is None
    with pytest.raises(KeyError, match="not a key of the run summary"):
        summary["no such key"]


def test_a_run_without_files_has_the_same_keys(tmp_path):
    written = tm.Simulation(_scene(), output=tmp_path / "out").run()
    summary = tm.Simulation(_scene(), output=False).run()
    assert list(summary.keys()) == list(written.keys())
    assert summary["output"] is None and summary["scene"] == written["scene"]
    assert np.allclose(summary["probes"]["tip"], written["probes"]["tip"])


def test_a_stopped_run_carries_the_mapping_too():
    # a soft bar under 1000 g: the health monitor stops it (runtime.physics.health)
    text = SCENE.replace("E = 1.0e6", "E = 1.0e3").replace("-9.81", "-9810.0").replace("steps = 3", "steps = 30")
    with pytest.raises(RunStopped) as err:
        tm.Simulation(tm.Scene.from_string(text), output=False).run()
    stop = err.value
    assert stop.summary["status"] == stop.status != "ok" and stop.summary["exit_code"] == 3
    assert stop.summary["output"] is None and stop.summary["message"] == str(stop)
