"""A simulation stepped live (runtime.run.live, runtime.run.live_process): pause really stops the time,
play(speed=1) keeps to real time, a drag walks the grab's target a cell at a time, reset starts over,
and a live run in a child process answers like one in this process."""
import time

import numpy as np
import pytest

from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.run.live import Live
from tensormass.runtime.run.live_process import LiveProcess
from tensormass.runtime.scene.scene import Scene

from helpers import LIVE_POLE as POLE, LIVE_SCENE as LIVE, live_scene as scene


def test_pause_stops_the_time_and_reset_starts_over():
    with Live(scene()) as live:
        live.play()
        time.sleep(0.5)
        live.pause()
        paused = live.snapshot()
        assert paused.step > 0 and paused.status == "paused"
        time.sleep(0.3)
        assert live.snapshot() is paused                  # no step while paused
        live.play(speed=1.0)                              # real time: 10 ms steps
        time.sleep(1.0)
        live.pause()
        steps = live.snapshot().step - paused.step
        assert 30 <= steps <= 110
        assert live.reset().step == 0 and live.snapshot().time == 0.0


def test_a_drag_walks_the_target_a_cell_at_a_time_and_repeats_bit_for_bit():
    def pulled():
        with Live(scene()) as live:
            live.step(5)
            at = POLE + np.array(live.snapshot().probes["pole"])
            grab = live.grab(at)
            live.drag(at + [0.0, 0.0, 0.05])
            live.step(1)
            moved = np.linalg.norm(grab.target - at)
            assert np.isclose(moved, grab.cell_size)      # at most the grabbed cell's size per step
            live.step(19)
            snap = live.snapshot(curves=True)
            assert snap.grab is not None and snap.grab["force"][2] > 0
            assert snap.curves["grab force"][-1] > 0 and len(snap.curves["time"]) == 26
            return snap.displacement
    first = pulled()
    assert np.array_equal(first, pulled())


def test_snapshots_carry_the_fields_asked_for():
    with Live(scene()) as live:
        live.step(3)
        body = live.body()
        assert body["fields"][0] == "displacement" and "von_mises" in body["fields"]
        values, where = live.snapshot("von_mises").values
        assert where == "point" and values.shape == (body["mesh"].n_points,) and values.max() > 0
        values, where = live.snapshot("displacement").values
        assert np.allclose(values, np.linalg.norm(live.snapshot().displacement, axis=1))


def test_a_static_scene_cannot_be_stepped_live():
    with pytest.raises(TensormassError, match="cannot be stepped live"):
        Live(scene(kind="static"))


def test_a_live_process_answers_like_a_live_here():
    here = Live(scene())
    here.step(4)
    at = POLE + np.array(here.snapshot().probes["pole"])
    here.grab(at)
    here.drag(at + [0.0, 0.0, 0.01])
    here.step(6)
    with LiveProcess(scene()) as there:
        assert there.body()["fields"] == here.body()["fields"]
        there.step(4)
        there.grab(at)
        there.drag(at + [0.0, 0.0, 0.01])
        snap = there.step(6)
        assert snap.model is None and snap.step == 10
        assert np.array_equal(snap.displacement, here.snapshot().displacement)
        there.play()
        time.sleep(0.3)
        there.pause()
        stopped = there.snapshot().step
        time.sleep(0.2)
        assert there.snapshot().step == stopped > 10
        with pytest.raises(TensormassError, match="drag target"):
            there.drag([0.0, 0.0])
    here.close()


TOOL = LIVE.parent / "live_tool.toml"


def test_a_tool_moved_by_the_mouse_presses_the_body():
    with Live(Scene.from_toml(str(TOOL))) as live:
        live.step(60)                                           # settled under gravity
        rest = live.snapshot().probes["pole"][2]
        live.move_obstacle("tool", [0.0, 0.0, -0.003])          # 3 mm down: 2.5 mm into the pole
        live.step(1)
        reach = 0.001 * np.linalg.norm(np.ptp(live.sim.model.mesh.points, axis=0))
        tool = live.sim.model.contact.obstacles[0]
        assert np.isclose(-tool.shift[2], reach)                # a bounded walk per step
        live.step(80)
        snap = live.snapshot("displacement")
        assert np.isclose(tool.shift[2], -0.003)
        assert snap.probes["pole"][2] < rest - 0.0007           # pressed down
        assert snap.tools["tool"][2] > 0                        # the organ pushes the tool up
        assert np.isclose(snap.obstacles[0][:, 2].min(), 0.0305 - 0.003)
        with pytest.raises(TensormassError, match="no obstacle 'knife'"):
            live.move_obstacle("knife", [0.0, 0.0, 0.0])
        live.reset()
        assert live.sim.model.contact.obstacles[0].shift is None


def test_an_ipc_obstacle_is_not_moved_by_the_mouse():
    pytest.importorskip("ipctk")
    from tensormass.runtime.run.simulation import Simulation
    sim = Simulation(Scene.from_toml(str(LIVE.parents[1] / "contact" / "tool_indent.toml")), output=False)
    sim.start()
    with pytest.raises(TensormassError, match="move by their motion only"):
        sim.move_obstacle("tool", [0.0, 0.0, -0.001])
