"""The Python API writes what the scene's [output] asks, the same files as `tensormass run` (#14)."""
from __future__ import annotations

import json

import numpy as np
import pytest

import tensormass as tm
from tensormass.apps.cli import main
from tensormass.runtime.model.model import Model
from tensormass.runtime.run.output import SUMMARY_FORMAT

from run_scenes import IMPLICIT, bar, write_scene

SCENE = bar(cells=4, solver=IMPLICIT, output='dir = "frames"')


@pytest.fixture
def scene_path(tmp_path):
    return write_scene(tmp_path, SCENE, "bar")


def _files(folder):
    return sorted(p.name for p in folder.iterdir())


def test_python_run_writes_the_same_files_as_the_command_line(scene_path, tmp_path, capsys):
    assert main(["run", str(scene_path), "--out", str(tmp_path / "cli"), "--quiet"]) == 0
    summary = tm.Simulation(tm.Scene.from_toml(scene_path), output=tmp_path / "api").run()
    cli, api = tmp_path / "cli", tmp_path / "api"
    assert _files(cli) == _files(api) == (["frame.pvd"] + [f"frame_{k:06d}.vtu" for k in range(4)]
                                          + ["summary.csv", "summary.json"])
    for name in _files(cli):
        if not name.startswith("summary"):      # timings differ; everything computed is bit-identical
            assert (cli / name).read_bytes() == (api / name).read_bytes(), name
    a, b = (json.loads((d / "summary.json").read_text()) for d in (cli, api))
    assert a["format"] == b["format"] == SUMMARY_FORMAT and set(a) == set(b)
    assert a["probes"] == b["probes"] == json.loads(json.dumps(summary.to_dict()["probes"]))
    assert b["output"]["dir"] == str(api) and b["output"]["frames"] == 4
    tip = b["probe_points"]["tip"]                       # the summary says how the probe reads the body
    assert tip["point"] == [1.0, 0.1, 0.1] and tip["cell"] == 3 and "interpolated" in tip["how"]


def test_scene_output_section_is_written_relative_to_the_scene_file(scene_path, tmp_path, monkeypatch):
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    sim = tm.Simulation(tm.Scene.from_toml(scene_path))
    sim.run()
    folder = scene_path.parent / "frames"
    assert "summary.json" in _files(folder) and "frame.pvd" in _files(folder)
    assert sim.data["output"]["summary"] == str(folder / "summary.json")
    assert list(elsewhere.iterdir()) == []


def test_output_false_writes_nothing(scene_path, tmp_path):
    tm.Simulation(tm.Scene.from_toml(scene_path), output=False).run()
    assert _files(tmp_path) == ["bar.toml"]


def test_bad_output_arguments_are_refused(scene_path, tmp_path):
    scene = tm.Scene.from_toml(scene_path)
    with pytest.raises(tm.TensormassError, match="a Model has no scene"):
        tm.Simulation(Model.from_scene(scene), output=tmp_path / "x")
    scene.output.dir = None
    with pytest.raises(tm.TensormassError, match="no \\[output\\] dir"):
        tm.Simulation(scene, output=True)
    with pytest.raises(tm.TensormassError, match="takes a folder"):
        tm.Simulation(scene, output=3)


def test_a_summary_json_that_is_not_ours_needs_overwrite(scene_path, tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "summary.json").write_text("{}")
    with pytest.raises(tm.TensormassError, match="not a tensormass summary.*overwrite"):
        tm.Simulation(tm.Scene.from_toml(scene_path))
    assert (folder / "summary.json").read_text() == "{}"
    tm.Simulation(tm.Scene.from_toml(scene_path), overwrite=True).run()
    assert json.loads((folder / "summary.json").read_text())["format"] == SUMMARY_FORMAT


def test_on_step_sees_the_live_state_between_steps(scene_path):
    seen = []

    def on_step(sim):
        seen.append((sim.step, sim.time, sim.displacement.copy(), sim.velocity.copy()))

    sim = tm.Simulation(tm.Scene.from_toml(scene_path), output=False, on_step=on_step)
    sim.run()
    assert [s[0] for s in seen] == [1, 2, 3]
    assert np.allclose([s[1] for s in seen], [0.01, 0.02, 0.03])
    assert not np.array_equal(seen[0][2], seen[1][2])          # the state moves between calls
    assert np.array_equal(seen[-1][2], sim.displacement)
    assert np.abs(seen[-1][3]).max() > 0


def test_an_exception_in_on_step_comes_back_as_it_was(scene_path, tmp_path):
    def on_step(sim):
        if sim.step == 2:      # a ValueError: what the runtime would otherwise report as a failed step
            raise ValueError("viewer closed")

    with pytest.raises(ValueError, match="viewer closed") as info:
        tm.Simulation(tm.Scene.from_toml(scene_path), on_step=on_step).run()
    assert not isinstance(info.value, tm.RunStopped)


def test_public_names_and_version(capsys):
    names = dir(tm)
    for name in ("Scene", "Simulation", "load_kernel", "Kernel", "RunStopped", "TensormassError", "__version__"):
        assert name in names
        getattr(tm, name)
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"tensormass {tm.__version__}"


def test_picture_plot_and_history_csv_on_request(scene_path, tmp_path):
    scene_path.write_text(SCENE + "picture = true\nplot = true\nfields = [\"von_mises\", \"reaction\"]\n")
    sim = tm.Simulation(tm.Scene.from_toml(scene_path))
    summary = sim.run()
    folder = tmp_path / "frames"
    assert {"von_mises.png", "summary.png", "summary.csv", "summary.json"} <= set(_files(folder))
    for png in ("von_mises.png", "summary.png"):
        assert (folder / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = (folder / "summary.csv").read_text().splitlines()
    assert rows[0].startswith("step,time [s],") and "reaction.fixed[0].Fz [N]" in rows[0]
    assert len(rows) == 1 + len(summary.per_step["step"]) == 4
    assert sim.data["output"]["picture"] == str(folder / "von_mises.png")
    assert sim.data["output"]["plot"] == str(folder / "summary.png")
    final = summary.reactions["fixed[0]"]                 # the summary's final reactions: the last row's
    assert final["force"] == summary.per_step["reactions"]["fixed[0]"]["force"][-1]
    assert final["moment"] == summary.per_step["reactions"]["fixed[0]"]["moment"][-1] and len(final["point"]) == 3


def test_picture_needs_an_output_folder_and_a_known_field(scene_path):
    scene_path.write_text(SCENE.replace('dir = "frames"', 'picture = "von_mises"'))
    with pytest.raises(tm.TensormassError, match="output.picture: pictures go to the output folder"):
        tm.Simulation(tm.Scene.from_toml(scene_path), json=scene_path.parent / "s.json")
    scene_path.write_text(SCENE + 'picture = "vonmises"\n')
    with pytest.raises(tm.TensormassError, match="output.picture: expected true, false or a field name"):
        tm.Scene.from_toml(scene_path)


def test_a_history_csv_that_is_not_ours_needs_overwrite(scene_path, tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "summary.csv").write_text("my data\n")
    with pytest.raises(tm.TensormassError, match="summary.csv: exists and was not written by an earlier tensormass"):
        tm.Simulation(tm.Scene.from_toml(scene_path))
    assert (folder / "summary.csv").read_text() == "my data\n"
    (tmp_path / "results.csv").write_text("my results\n")        # --json results.json: its history beside it
    with pytest.raises(tm.TensormassError, match="results.csv: exists and was not written"):
        tm.Simulation(tm.Scene.from_toml(scene_path), json=tmp_path / "results.json")
    assert (tmp_path / "results.csv").read_text() == "my results\n"
    tm.Simulation(tm.Scene.from_toml(scene_path), overwrite=True).run()
    tm.Simulation(tm.Scene.from_toml(scene_path)).run()      # ours now: replaced without asking
    assert (folder / "summary.csv").read_text().startswith("step,")


def test_cli_picture_of_the_displacement(scene_path, tmp_path, capsys):
    assert main(["run", str(scene_path), "--picture", "displacement", "--quiet"]) == 0
    assert (tmp_path / "frames" / "displacement.png").read_bytes()[:4] == b"\x89PNG"
    assert not (tmp_path / "frames" / "summary.png").exists()
