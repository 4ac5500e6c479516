"""The grab's spring (runtime.physics.grab) and stepping a Simulation by hand (start, advance, grab,
drag, release): the spring's force is minus its energy's gradient and its Hessian the force's
derivative, a run stepped by hand gives run()'s bits, and a grab pulls the body toward its target."""
import numpy as np
import pytest

from tensormass.runtime.base.errors import RunStopped, TensormassError
from tensormass.runtime.physics.grab import Grab, GrabError
from tensormass.runtime.run.simulation import Simulation

from helpers import LIVE_POLE as POLE, live_scene as scene


@pytest.fixture(scope="module")
def started():
    sim = Simulation(scene(), output=False)
    sim.start()
    sim.advance(3)
    return sim


def test_the_spring_force_is_minus_the_gradient_of_its_energy(started):
    sim = started
    rng = np.random.default_rng(1)
    grab = Grab.at(sim.ctx.asm, sim.ctx.u, POLE, POLE + [0.004, -0.002, 0.01], stiffness=37.0)
    assert np.isclose(grab.weights.sum(), 1.0) and grab.nodes.size == 10      # a tetra10's shape functions
    u = sim.ctx.u + 1e-3 * rng.standard_normal(sim.model.n_dofs)
    f, h = grab.forces(u), 1e-7
    for dof in grab._dofs.ravel()[::4]:
        e = np.zeros_like(u)
        e[dof] = h
        assert np.isclose(-(grab.energy(u + e) - grab.energy(u - e)) / (2 * h), f[dof], rtol=1e-6, atol=1e-12)
    d = 1e-4 * rng.standard_normal(u.size)
    assert np.allclose(grab.forces(u + d) - f, -(grab.hessian() @ d), atol=1e-12)
    assert np.allclose(f.reshape(-1, 3).sum(axis=0), grab.force(u))           # the pull on the body, summed
    assert np.linalg.eigvalsh(grab.hessian().toarray()[np.ix_(grab._dofs.ravel(), grab._dofs.ravel())]).min() > -1e-9


def test_a_point_off_the_body_and_a_bad_stiffness_are_refused(started):
    sim = started
    with pytest.raises(GrabError, match="grab"):
        Grab.at(sim.ctx.asm, sim.ctx.u, [1.0, 1.0, 1.0])
    with pytest.raises(GrabError, match="stiffness"):
        Grab.at(sim.ctx.asm, sim.ctx.u, POLE, stiffness=-1.0)
    with pytest.raises(GrabError, match="target"):
        Grab.at(sim.ctx.asm, sim.ctx.u, POLE, target=[0.0, np.nan, 0.0])


def test_stepping_by_hand_gives_the_bits_of_run():
    ran = Simulation(scene(steps=6), output=False)
    ran.run()
    by_hand = Simulation(scene(steps=6), output=False)
    by_hand.start()
    row = by_hand.advance(4)
    assert row["step"] == 4
    by_hand.advance(2)
    assert np.array_equal(ran.displacement, by_hand.displacement)
    assert by_hand.finish().steps_done == 6
    by_hand.advance(3)                        # open-ended: past solver.steps the loads hold
    assert by_hand.step == 9 and np.isclose(by_hand.time, 0.09)
    with pytest.raises(TensormassError, match="started by hand"):
        by_hand.run()


def test_a_grab_pulls_the_body_and_release_lets_go():
    sim = Simulation(scene(), output=False)
    sim.start()
    sim.advance(10)
    z0 = sim.probes()["pole"][2]
    at = POLE + np.array(sim.probes()["pole"])
    grab = sim.grab(at)
    assert np.allclose(grab.force(sim.ctx.u), 0.0)        # no pull until the target moves
    for i in range(1, 11):
        sim.drag(at + [0.0, 0.0, 0.001 * i])
        sim.advance(3)
    pulled = sim.probes()["pole"][2]
    assert pulled > z0 + 0.004                            # up toward the target, 10 mm above the pole
    assert grab.force(sim.ctx.u)[2] > 0 and grab.work > 0
    # the balance's external work: gravity's and the spring's, nothing else in this scene
    assert np.isclose(sim._history.last["external_work"], sim.model.motion.work(sim.ctx.u, sim.time) + grab.work,
                      rtol=1e-12, atol=0.0)
    sim.release()
    assert sim.ctx.grab is None
    sim.advance(40)
    assert sim.probes()["pole"][2] < pulled               # falls back once let go
    with pytest.raises(TensormassError, match="nothing is grabbed"):
        sim.drag(POLE)


def test_a_static_run_takes_no_grab():
    sim = Simulation(scene(kind="static", steps=2), output=False)
    sim.start()
    with pytest.raises(TensormassError, match="takes no grab"):
        sim.grab(POLE)


def test_a_failed_step_stops_stepping_with_the_reason():
    sim = Simulation(scene(), output=False)
    sim.start()
    sim.advance(2)
    sim.grab(POLE + np.array(sim.probes()["pole"]), target=POLE + [0.0, 0.0, 0.2], stiffness=5e4)   # a 20 cm jerk
    with pytest.raises(RunStopped) as stopped:
        sim.advance(5)
    assert stopped.value.summary.status == "failed" and "det F" in str(stopped.value)
    with pytest.raises(TensormassError, match="stopped at step"):
        sim.advance(1)
