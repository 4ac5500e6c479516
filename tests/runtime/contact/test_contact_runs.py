"""Runs with contact: IPC keeps every recorded state free of intersections (checked here with an
independent edge-through-triangle test), the per-step records and history columns, the plate's force
against the support's reaction, penalty contact with the explicit integrator, the contact_force field."""
from __future__ import annotations

import copy
import csv

import meshio
import numpy as np
import pytest

from tensormass.runtime.contact.surface import contact_surface
from tensormass.runtime.physics.integrators import stable_time_step
from tensormass.runtime.run.simulation import Simulation
from tensormass.runtime.scene.scene import Scene

from contact_scenes import bar, self_intersecting_pairs, surfaces_intersect

PRESS_STEPS = 2
PRESS = bar([{"name": "plate", "shape": "plane", "point": [0.05, 0.05, 0.102], "normal": [0, 0, -1],
              "translation": [0, 0, -0.02]}], solver={"kind": "static", "steps": PRESS_STEPS})
DROP_STEPS = 10
DROP = bar([{"name": "floor", "shape": "plane", "point": [0, 0, 0], "normal": [0, 0, 1]}],
           contact={"mu": 0.5}, solver={"kind": "backward_euler", "dt": 0.01, "steps": DROP_STEPS},
           cells=(2, 2, 1), loads={"gravity": [3.0, 0.0, -9.81]})
DROP["mesh"].update(size=[0.1, 0.1, 0.05], origin=[0.0, 0.0, 0.01])
del DROP["fixed"]


def _run(data, output=False, **kwargs):
    """Run the scene; per step (on_step): the displacement and the run fraction of the obstacles' pose."""
    states = []
    sim = Simulation(Scene.from_dict(copy.deepcopy(data)), output=output,
                     on_step=lambda s: states.append((s.displacement.copy(), s.step)), **kwargs)
    return sim, sim.run(), states


def _obstacle_at(obstacle, body, a):
    """The obstacle's triangles with its motion at amplitude value a (a plane: a square larger than the body)."""
    X = np.asarray(body, dtype=float)
    V, F = obstacle.triangles(2.0 * np.linalg.norm(X.max(axis=0) - X.min(axis=0)), 0.01, X.mean(axis=0))
    return obstacle.placed(V, a), F


def _check_free(sim, states, n_steps):
    """Every recorded state: the body's surface crosses no obstacle and itself nowhere; every vertex on
    the plane's side its normal points to."""
    model = sim.model
    surface = contact_surface(model)
    X = np.asarray(model.mesh.points, dtype=float)
    assert len(states) == n_steps
    for u, step in states:
        x = (X + u)[surface.nodes]
        assert self_intersecting_pairs(x, surface.triangles) == 0
        for o in model.scene.obstacles:
            a = step / n_steps                         # the default amplitude: the ramp over the run
            V, F = _obstacle_at(o, X, a)
            assert not surfaces_intersect(x, surface.triangles, V, F), f"step {step}: the body crosses {o.name}"
            n = np.asarray(o.normal, float) / np.linalg.norm(o.normal)
            assert np.min((x - o.placed(np.asarray([o.point], float), a)[0]) @ n) > 0


def test_the_intersection_check_sees_a_crossing():
    """The independent test itself: a surface pushed through the floor crosses it; lifted, it does not."""
    sim = Simulation(Scene.from_dict(copy.deepcopy(DROP)), output=False)
    surface = contact_surface(sim.model)
    x = np.asarray(sim.model.mesh.points, dtype=float)[surface.nodes]
    V, F = _obstacle_at(sim.model.scene.obstacles[0], x, 0.0)
    assert not surfaces_intersect(x, surface.triangles, V, F)
    assert surfaces_intersect(x - [0, 0, 0.03], surface.triangles, V, F)
    assert not surfaces_intersect(x + [0, 0, 0.03], surface.triangles, V, F)
    folded = x.copy()
    folded[np.argmax(folded[:, 2])] -= [0, 0, 0.2]      # a top vertex pulled through the bottom face
    assert self_intersecting_pairs(folded, surface.triangles) > 0


def test_ipc_static_press_is_free_of_intersections_and_balances_the_support():
    sim, summary, states = _run(PRESS)
    assert summary["status"] == "ok"
    _check_free(sim, states, PRESS_STEPS)
    contact, obstacles = summary.per_step["contact"], summary.per_step["obstacles"]
    assert all(len(v) == PRESS_STEPS for v in contact.values())
    assert min(contact["pairs"]) > 0 and all(0 < d < sim.model.contact.dhat for d in contact["min_distance"])
    assert list(obstacles) == ["plate"] and len(obstacles["plate"]["force"]) == PRESS_STEPS
    assert len(obstacles["plate"]["moment"]) == PRESS_STEPS
    # the plate pushes the top down and the support holds the base: the force on the plate is the
    # support's reaction on the body; pressed twice as far, about twice the force (Hooke)
    plate = np.array(obstacles["plate"]["force"])
    reaction = np.array(summary["reactions"]["fixed[0]"]["force"])
    assert plate[-1, 2] > 0 and np.abs(plate[-1] - reaction).max() <= 1e-6 * abs(reaction[2])
    assert 1.5 < plate[1, 2] / plate[0, 2] < 3.0


def test_ipc_drop_on_a_floor_with_friction_is_free_of_intersections():
    sim, summary, states = _run(DROP)
    assert summary["status"] == "ok"
    _check_free(sim, states, DROP_STEPS)
    pairs = summary.per_step["contact"]["pairs"]
    assert len(pairs) == DROP_STEPS and pairs[0] == 0 and pairs[-1] > 0          # falls, then lands
    floor = np.array(summary.per_step["obstacles"]["floor"]["force"])
    assert floor.shape == (DROP_STEPS, 3) and not floor[0].any() and floor[-1, 2] < 0   # pushed down


def test_history_columns_and_the_contact_force_field(tmp_path):
    data = copy.deepcopy(PRESS)
    data["output"] = {"fields": ["contact_force"]}
    out = tmp_path / "out"
    sim, summary, _ = _run(data, output=out)
    assert summary["status"] == "ok"
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert len(rows) == PRESS_STEPS
    for key in ("contact.pairs", "contact.min_distance [m]", "contact.ccd_fraction", "obstacle.plate.Fx [N]",
                "obstacle.plate.Fz [N]", "obstacle.plate.Mz [N m]"):
        assert key in rows[0], key
    for row, force in zip(rows, summary.per_step["obstacles"]["plate"]["force"]):
        fz, reaction = float(row["obstacle.plate.Fz [N]"]), float(row["reaction.fixed[0].Fz [N]"])
        assert fz == pytest.approx(force[2], rel=1e-12) and fz == pytest.approx(reaction, rel=1e-6)
        assert int(row["contact.pairs"]) > 0
    # the field: the contact's nodal forces, summing to minus the force on the plate
    last = meshio.read(sorted(out.glob("frame_*.vtu"))[-1])
    f = np.asarray(last.point_data["contact_force"])
    plate = np.array(summary.per_step["obstacles"]["plate"]["force"][-1])
    assert f.shape == (sim.model.n_points, 3) and np.abs(f.sum(axis=0) + plate).max() <= 1e-9 * plate[2]
    top = np.isclose(np.asarray(sim.model.mesh.points)[:, 2], 0.1)
    assert not f[~top].any() and np.all(f[top, 2] < 0)
    point_fields, _ = sim.fields(["contact_force"])
    assert np.allclose(point_fields["contact_force"], f, rtol=0, atol=1e-9 * plate[2])
    # the pressure: the force over each node's third of the surrounding rest triangles; integrated
    # over the loaded top it is the plate's force, its largest value near the mean pressure there
    p = sim.fields(["contact_pressure"])[0]["contact_pressure"]
    surface = sim.model.contact.surface
    X = np.asarray(sim.model.mesh.points)[surface.nodes][surface.triangles]
    area = 0.5 * np.linalg.norm(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), axis=1)
    share = np.bincount(surface.triangles.ravel(), np.repeat(area / 3, 3), minlength=surface.size)
    assert np.sum(p[surface.nodes] * share) == pytest.approx(np.linalg.norm(f, axis=1).sum(), rel=1e-12)
    assert not p[~top].any() and p[top].max() >= plate[2] / (0.1 * 0.1)


# ------------------------------------------------------------------ penalty, explicit integrator

PENALTY_STEPS = 60
PENALTY_DROP = bar([{"name": "table", "shape": "box", "box": [[-0.05, -0.05, -0.05], [0.15, 0.15, 0.0]]}],
                   contact={"method": "penalty"}, cells=(2, 2, 1),
                   solver={"kind": "explicit", "dt": 2e-4, "steps": PENALTY_STEPS}, loads={"gravity": [0, 0, -9.81]})
PENALTY_DROP["mesh"].update(size=[0.1, 0.1, 0.05], origin=[0.0, 0.0, 2e-5])
del PENALTY_DROP["fixed"]


def test_penalty_explicit_drop_records_penetration_and_warns_when_too_soft():
    sim, summary, _ = _run(PENALTY_DROP)
    depth = summary.per_step["contact"]["penetration"]
    assert summary["status"] == "ok", summary["message"]
    assert len(depth) == PENALTY_STEPS and depth[0] == 0.0 and max(depth) > 0
    assert max(depth) < sim.model.contact.max_penetration
    table = np.array(summary.per_step["obstacles"]["table"]["force"])
    assert table[-1, 2] < 0                            # the block pushes the table down
    soft = copy.deepcopy(PENALTY_DROP)
    soft["contact"]["stiffness"] = 1.0
    sim, summary, _ = _run(soft)
    assert summary["status"] == "warnings"
    warned = [w for w in summary["warnings"] if "penetration" in str(w)]
    assert warned and "raise contact.stiffness" in str(warned[0])
    assert max(summary.per_step["contact"]["penetration"]) > sim.model.contact.max_penetration


def test_the_contact_force_field_without_contact_is_refused_before_anything_is_written(tmp_path):
    from tensormass.runtime.base.errors import TensormassError
    data = bar(output={"fields": ["contact_force"]})
    with pytest.raises(TensormassError, match=r"output.fields: field 'contact_force' is computed by runtime.contact"):
        Simulation(Scene.from_dict(data), output=tmp_path / "out").run()
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------ energy balance with moving obstacles


def test_a_scene_driven_by_a_moving_obstacle_alone_balances_its_energy():
    """No load, no fixed node, no gravity: a plate pushes the bar onto a floor (backward Euler). The
    plate's work on the body is the balance's external work, and scales it: without it the scene's
    energy scale is zero and the first joule stops the run as a blow-up."""
    plate = {"name": "plate", "shape": "plane", "point": [0.05, 0.05, 0.102], "normal": [0, 0, -1],
             "translation": [0, 0, -0.012]}
    floor = {"name": "floor", "shape": "plane", "point": [0.05, 0.05, -0.001], "normal": [0, 0, 1]}
    data = bar(obstacles=[plate, floor], solver={"kind": "backward_euler", "dt": 0.05, "steps": 6})
    del data["fixed"]
    sim, summary, _ = _run(data)
    assert summary["status"] == "ok"
    work, elastic = summary.per_step["external_work"][-1], summary.per_step["elastic"][-1]
    kinetic = summary.per_step["kinetic"][-1]
    # backward Euler dissipates: the work put in covers what is stored, with a little to spare
    assert work > 0 and elastic > 0.5 * work and elastic + kinetic <= work * (1 + 1e-9)
    assert sim.monitor.energy_scale >= work


def test_generalized_alpha_starts_from_an_acceleration_with_the_penalty_forces():
    """The start acceleration solves M a = f_ext + f_int + f_contact: a rigid lift into a plate (no
    elastic force) accelerates exactly the vertices pushed back, by k (offset - d) n / m."""
    from tensormass.runtime.model.model import Model
    from tensormass.runtime.physics.integrators import make_integrator
    from tensormass.runtime.physics.newton import Context
    plate = {"name": "plate", "shape": "plane", "point": [0.05, 0.05, 0.102], "normal": [0, 0, -1]}
    data = bar(obstacles=[plate], contact={"method": "penalty", "stiffness": 1e4},
               solver={"kind": "generalized_alpha", "dt": 1e-3, "steps": 1})
    model = Model.from_scene(Scene.from_dict(copy.deepcopy(data)))
    ctx = Context(model)
    integ = make_integrator(ctx)
    u = np.zeros(model.n_dofs)
    u.reshape(-1, 3)[:, 2] = 0.005                  # 3 mm into the plate at the top face
    a = integ.initial_acceleration(u, np.zeros_like(u), 0.0).reshape(-1, 3)
    top = np.isclose(np.asarray(model.mesh.points)[:, 2], 0.1)
    m = model.mass.reshape(-1, 3)[:, 2]
    assert np.allclose(a[top, 2], -1e4 * 0.003 / m[top], rtol=1e-9)
    free = np.asarray(model.free_dofs)
    rest = np.ones(model.n_points, bool)
    rest[top] = False
    assert np.allclose(a.ravel()[np.intersect1d(free, np.flatnonzero(np.repeat(rest, 3)))], 0.0, atol=1e-9)


def test_the_run_report_names_each_obstacles_last_and_largest_force():
    """`tensormass run` prints, per obstacle, the force at the end and the largest one with its step
    (a tool that has left the body at the end would otherwise show nothing)."""
    from tensormass.apps.commands import _contact_rows
    contact = {"method": "ipc", "max_pairs": 3, "min_distance": 1e-5, "dhat": 1e-4, "min_ccd_fraction": 0.5}
    per_step = {"step": [1, 2, 3], "obstacles": {"tool": {"force": [[0, 0, 1.0], [0, 3.0, 4.0], [0, 0, 0]]}}}
    rows = dict(_contact_rows(contact, per_step))
    assert rows["obstacle tool"] == "F = [0, 0, 0] N at the end; largest [0, 3, 4] N at step 2"
    assert "up to 3 pair(s)" in rows["contact"] and "dhat 0.0001 m" in rows["contact"]


def test_the_explicit_stable_step_adds_the_penalty_springs_to_the_body():
    """A block pressed into a penalty floor: 2 / omega_max of the lumped M^-1 (K + K_penalty) there is
    above the run's stable step (a safe bound), and below the smaller of the elastic and spring
    steps taken alone (what taking the smaller one missed)."""
    sim = Simulation(Scene.from_dict(copy.deepcopy(PENALTY_DROP)), output=False)
    sim.run()
    model, contact, u = sim.model, sim.model.contact, sim.ctx.u.copy()
    u[2::3] -= 5e-4                                    # every bottom node inside the floor
    H = contact.hessian(u, False)
    assert H is not None and contact.stable_time_step() < np.inf
    K = sim.ctx.asm.matrix(sim.ctx.asm.stiffness(u))
    scale = 1.0 / np.sqrt(np.asarray(model.mass, dtype=float))
    A = (K + H).toarray() * scale[:, None] * scale[None, :]
    dt_true = 2.0 / np.sqrt(np.linalg.eigvalsh(0.5 * (A + A.T)).max())
    alone = min(stable_time_step(sim.ctx), contact.stable_time_step())
    assert sim.stable_dt <= dt_true < alone
