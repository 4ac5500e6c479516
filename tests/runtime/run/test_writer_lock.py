"""Issue #29 item 6, outputs: one run per output folder (runtime.run.lock.FolderLock), and a frame
writer whose bookkeeping per frame does not grow with the frames written before.

The lock is exercised on a tiny bar through the Writer directly and through `tensormass run`
in this process; a live holder is this test's parent process (alive for the whole test), a dead
one a child that has exited and been reaped.
"""
from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from tensormass.apps.cli import main
from tensormass.runtime.run import lock as lock_module, output
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.run.lock import LOCK_NAME, FolderLock
from tensormass.runtime.run.output import Writer

SCENE = """
name = "bar"
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [2, 1, 1]
element = "hexahedron"
[[material]]
law = "hooke"
quadrature = "gauss2"
E = 1.0e8
nu = 0.3
density = 800.0
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "static"
steps = 2
[output]
every = 1
"""


def _mesh():
    return generate_bar((1.0, 0.2, 0.2), (2, 1, 1), "hexahedron")


def _frame(writer, step):
    return writer.write_frame(step, 0.1 * step, None, np.zeros((writer.mesh.n_points, 3)))


def _pvd_files(path: Path) -> list:
    return [d.get("file") for d in ET.parse(path).getroot().iter("DataSet")]


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()                                   # exited and reaped: the pid names no process
    return child.pid


# ============================================================================== the soak


class _CountingList(list):
    """A list that counts how often it is walked."""
    walks = 0

    def __iter__(self):
        type(self).walks += 1
        return super().__iter__()


def test_a_frame_does_not_walk_the_frames_written_before(tmp_path):
    # the cost per frame grew with the run (4.2 -> 9.7 ms over 6 000 frames): every frame scanned the
    # list of all earlier frames (three times). Its bookkeeping must not depend on how many came before.
    w = Writer(tmp_path, _mesh())
    _frame(w, 0)
    w.frames = _CountingList(w.frames)
    _CountingList.walks = 0
    for step in range(1, 30):
        _frame(w, step)
    assert _CountingList.walks == 0
    assert len(w.frames) == 30 and w.frames[-1][1] == "frame_000029.vtu"
    _frame(w, 3)                                   # a step written again: listed once, at its new place
    w.close()
    names = _pvd_files(tmp_path / "frame.pvd")
    assert len(names) == 30 and names.count("frame_000003.vtu") == 1 and names[-1] == "frame_000003.vtu"
    assert [n for _, n in w.frames] == names


# ============================================================================== the folder lock


def test_a_second_writer_into_a_locked_folder_is_refused(tmp_path):
    first, second = Writer(tmp_path, _mesh()), Writer(tmp_path, _mesh())
    second.prepare()                               # both passed their checks: the first frame decides
    _frame(first, 0)
    assert (tmp_path / LOCK_NAME).is_file()
    with pytest.raises(TensormassError, match=rf"{tmp_path}.*pid {os.getpid()}"):
        _frame(second, 0)
    with pytest.raises(TensormassError, match="another tensormass run"):
        Writer(tmp_path, _mesh()).prepare()
    _frame(first, 1)                               # the first run's files are untouched
    first.close()
    assert not (tmp_path / LOCK_NAME).exists()
    assert _pvd_files(tmp_path / "frame.pvd") == ["frame_000000.vtu", "frame_000001.vtu"]
    third = Writer(tmp_path, _mesh())              # free again: a rerun replaces them
    _frame(third, 0)
    third.close()
    assert _pvd_files(tmp_path / "frame.pvd") == ["frame_000000.vtu"]


def test_a_writer_dropped_without_close_releases_its_lock(tmp_path):
    _frame(Writer(tmp_path, _mesh()), 0)
    assert not (tmp_path / LOCK_NAME).exists()


def test_run_into_a_folder_another_live_run_holds_is_refused(tmp_path, capsys):
    scene = tmp_path / "bar.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    out.mkdir()
    lock = out / LOCK_NAME
    lock.write_text(FolderLock.record(os.getppid()))            # a live process holds it
    code = main(["run", str(scene), "--out", str(out), "--json", str(tmp_path / "s.json"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert f"output folder {out}" in err and f"pid {os.getppid()}" in err and len(err.splitlines()) == 1
    assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME] and not (tmp_path / "s.json").exists()
    assert lock.read_text() == FolderLock.record(os.getppid())  # the other run's lock is left alone


def test_a_stale_lock_of_a_dead_process_is_taken_over(tmp_path, capsys):
    scene = tmp_path / "bar.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_NAME).write_text(f"pid={_dead_pid()} host={lock_module._host()} start=1\n")
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == 0, capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["frame.pvd", "frame_000000.vtu", "frame_000001.vtu",
                                                      "frame_000002.vtu", "summary.csv", "summary.json"]


def test_a_reused_pid_with_another_start_is_stale(tmp_path):
    # the lock's pid now names another process (the holder died, the pid was reused): its start differs
    if lock_module._process_start(os.getppid()) is None:
        pytest.skip("no /proc: process starts unknown")
    start = lock_module._process_start(os.getppid())
    (tmp_path / LOCK_NAME).write_text(f"pid={os.getppid()} host={lock_module._host()} start={start + 1}\n")
    w = Writer(tmp_path, _mesh())
    _frame(w, 0)
    assert (tmp_path / LOCK_NAME).read_text() == FolderLock.record()
    w.close()
    assert not (tmp_path / LOCK_NAME).exists()


def test_the_lock_is_held_until_the_summary_is_written(tmp_path):
    from tensormass.runtime.run.run_files import RunFiles
    from tensormass.runtime.scene.scene import Scene
    from tensormass.runtime.run.simulation import Simulation
    scene = Scene.from_string(SCENE, name="bar")
    files = RunFiles(scene, out=tmp_path / "out")
    seen = []
    real = files._finish

    def finish(*args, **kw):
        seen.append((tmp_path / "out" / LOCK_NAME).is_file())
        return real(*args, **kw)
    files._finish = finish
    Simulation(scene, output=files).run()
    assert seen == [True] and (tmp_path / "out" / "summary.json").is_file()
    assert not (tmp_path / "out" / LOCK_NAME).exists()
