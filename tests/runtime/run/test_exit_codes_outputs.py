"""Exit code 2 means bad input found before the first step: every output kind of a run that reached
its end (frames, summary, history, picture, plot) either is written or is refused before step 1, and
an optional file (picture, plot) that fails after the run is a warning with exit code 0."""
from __future__ import annotations

import json

import pytest

from tensormass.apps.cli import main

from run_scenes import bar, plate, write_scene

SCENES = {"bar": bar(), "shell": plate()}


def _scene(tmp_path, kind, text=None):
    return write_scene(tmp_path, SCENES[kind] if text is None else text, kind)


def _run(tmp_path, kind, *extra, text=None):
    out = tmp_path / "out"
    rc = main(["run", str(_scene(tmp_path, kind, text)), "--out", str(out), "--quiet", *extra])
    return rc, out


@pytest.mark.parametrize("kind", ["bar", "shell"])
def test_frames_summary_and_history_of_a_finished_run_exit_0(tmp_path, kind):
    rc, out = _run(tmp_path, kind)
    assert rc == 0
    names = sorted(p.name for p in out.iterdir())
    assert "frame.pvd" in names and "frame_000000.vtu" in names
    assert "summary.json" in names and "summary.csv" in names
    data = json.loads((out / "summary.json").read_text())
    assert data["exit_code"] == 0 and data["status"] == "ok"
    assert (out / "summary.csv").read_text().splitlines()[0].startswith("step")


@pytest.mark.parametrize("kind", ["bar", "shell"])
@pytest.mark.parametrize("field", ["", "displacement"])
def test_a_picture_is_drawn_or_refused_before_the_first_step(tmp_path, kind, field, capsys):
    rc, out = _run(tmp_path, kind, "--picture", *([field] if field else []))
    err = capsys.readouterr().err
    if rc == 2:                          # refused: before anything was written, naming why
        assert not out.exists()
        assert "refused before the first step" in err
    else:
        assert rc == 0, err
        data = json.loads((out / "summary.json").read_text())
        assert data["output"]["picture"] and (out / f"{field or 'von_mises'}.png").is_file()
    if kind == "bar":                    # a solid's picture always works
        assert rc == 0


@pytest.mark.parametrize("kind", ["bar", "shell"])
def test_plot_of_a_finished_run_exit_0(tmp_path, kind):
    rc, out = _run(tmp_path, kind, "--plot")
    assert rc == 0
    assert (out / "summary.png").is_file()
    assert json.loads((out / "summary.json").read_text())["output"]["plot"] == str(out / "summary.png")


def _fail(*args, **kwargs):
    raise OSError(28, "No space left on device")


@pytest.mark.parametrize("kind", ["bar", "shell"])
def test_a_plot_that_fails_after_the_run_is_a_warning_with_exit_0(tmp_path, kind, monkeypatch, capsys):
    from tensormass.runtime.run import run_files
    monkeypatch.setattr(run_files, "plot_history", _fail)
    rc, out = _run(tmp_path, kind, "--plot")
    assert rc == 0
    data = json.loads((out / "summary.json").read_text())
    assert data["status"] == "warnings" and data["exit_code"] == 0
    assert "No space left on device" in data["output"]["plot_error"]
    assert [w["kind"] for w in data["warnings"]] == ["output"]
    assert "summary.png not written: " in data["warnings"][0]["message"]


def test_a_picture_that_fails_after_the_run_is_a_warning_with_exit_0(tmp_path, monkeypatch, capsys):
    from tensormass.runtime.run import picture
    monkeypatch.setattr(picture, "picture_of_simulation", _fail)
    rc, out = _run(tmp_path, "bar", "--picture", "displacement")
    assert rc == 0
    data = json.loads((out / "summary.json").read_text())
    assert data["status"] == "warnings" and data["output"]["picture"] is None
    assert "displacement.png not written: " in data["output"]["picture_error"]
    assert "No space left on device" in data["warnings"][0]["message"]


def test_the_python_api_refuses_an_undrawable_picture_before_writing(tmp_path):
    import tensormass as tm
    from tensormass.runtime.base.errors import TensormassError
    scene = tm.Scene.from_toml(_scene(tmp_path, "bar"))
    scene.output.picture = "von_mises"
    from tensormass.runtime.run import picture
    calls = []

    def refuse(*args, **kwargs):
        calls.append(args)
        raise TensormassError("picture: cannot draw this")
    original = picture.check_picture
    picture.check_picture = refuse
    try:
        with pytest.raises(TensormassError, match="refused before the first step: picture: cannot draw this"):
            tm.Simulation(scene, output=tmp_path / "api").run()
    finally:
        picture.check_picture = original
    assert calls and not (tmp_path / "api").exists()


def test_a_bare_picture_of_a_corotational_shell_draws_the_displacement(tmp_path, capsys):
    """The default field (von Mises) needs stress records a co-rotational shell kernel does not give:
    a bare --picture draws the displacement instead, checked before the first step, exit 0."""
    rc, out = _run(tmp_path, "shell", "--picture", text=plate(corotational=True))
    assert rc == 0, capsys.readouterr().err
    data = json.loads((out / "summary.json").read_text())
    assert data["status"] == "ok"
    assert data["output"]["picture"] == str(out / "displacement.png") and (out / "displacement.png").is_file()
    assert not (out / "von_mises.png").exists()
    assert data["output"]["picture_note"] == ("the displacement is drawn: von_mises needs the stress records of every "
                                              "kernel, and the kernel for shell/cst_dkt/exact gives none")


def test_a_named_field_the_kernels_cannot_give_is_still_refused(tmp_path, capsys):
    rc, out = _run(tmp_path, "shell", "--picture", "cauchy_stress", text=plate(corotational=True))
    assert rc == 2 and not out.exists()
    assert "refused before the first step" in capsys.readouterr().err


def test_von_mises_named_on_a_corotational_shell_is_refused_not_replaced(tmp_path, capsys):
    """Only the default field falls back to the displacement: a named von_mises is the user's
    choice, refused before the first step with the kernel that lacks the stress records."""
    rc, out = _run(tmp_path, "shell", "--picture", "von_mises", text=plate(corotational=True))
    err = capsys.readouterr().err
    assert rc == 2 and not out.exists()
    assert "picture of 'von_mises'" in err and "refused before the first step" in err
    assert "the kernel for shell/cst_dkt/exact" in err and "draw the displacement (--picture displacement)" in err
    assert "output.fields" not in err and "fields = []" not in err      # advice for the picture, not the frames


def test_the_scene_keeps_whether_the_picture_field_was_named():
    from tensormass.runtime.scene.parser import set_picture
    from tensormass.runtime.scene.types import Output
    for value, field, named in ((True, "von_mises", False), ("von_mises", "von_mises", True), (False, None, False)):
        out = Output()
        set_picture(out, value, "output.picture")
        assert (out.picture, out.picture_named) == (field, named)


def test_a_clip_that_keeps_no_cell_names_the_clip_not_the_field(tmp_path, capsys):
    """A clip refusal says what the clip does wrong and how to mend it; no other picture field helps."""
    rc, out = _run(tmp_path, "bar", "--picture", text=bar(output="clip = [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]"))
    err = capsys.readouterr().err
    assert rc == 2 and not out.exists()
    assert "removes every cell (the rest centre of each lies on the side the normal points to" in err
    assert "move the clip's point into the body, or turn its normal round" in err
    assert "--picture displacement" not in err
