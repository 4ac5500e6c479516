"""Follower pressure (runtime/assembly/pressure.py): forces, stiffness by finite differences, work, Newton."""
from __future__ import annotations

import numpy as np
import pytest

from tensormass.runtime.assembly import loads
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.physics.newton import Context
from tensormass.runtime.physics.integrators import make_integrator
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.model.model import Model
from tensormass.runtime.assembly.pressure import FollowerPressure
from tensormass.runtime.scene.types import Fixed, Loads, Material, NodalLoad, PressureLoad, Solver
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.base.errors import SceneError
from tensormass.runtime.run.simulation import Simulation


def _faces(mesh, box=None):
    faces = loads.boundary_faces_by_type(mesh)
    return faces if box is None else loads.faces_in_box(mesh, box, 1e-9)


def _dense(P, u):
    K = np.zeros((P.n_dofs, P.n_dofs))
    d = P.dim
    for name, Ke in P.element_stiffness(u).items():
        faces = P.groups[name][0]
        dofs = (faces[:, :, None] * d + np.arange(d)).reshape(len(faces), -1)
        for e in range(len(faces)):
            K[np.ix_(dofs[e], dofs[e])] += Ke[e]
    return K


@pytest.mark.parametrize("element,cells", [("tetra10", (2, 1, 1)), ("hexahedron", (2, 1, 1)),
                                           ("wedge", (2, 1, 1)), ("triangle6", (2, 1)), ("quad", (2, 1))])
def test_pressure_stiffness_is_minus_the_force_derivative(element, cells):
    dim = len(cells)
    mesh = generate_bar((1.0, 0.4, 0.3)[:dim], cells, element)
    P = FollowerPressure(mesh.points, [(_faces(mesh), 1.7e3)], dim)
    rng = np.random.default_rng(2)
    u = 0.05 * rng.standard_normal(P.n_dofs)
    K = _dense(P, u)
    eps = 1e-6
    fd = np.zeros_like(K)
    for j in range(P.n_dofs):
        e = np.zeros(P.n_dofs)
        e[j] = eps
        fd[:, j] = -(P.forces(u + e) - P.forces(u - e)) / (2 * eps)
    assert np.abs(K - fd).max() <= 1e-7 * np.abs(K).max()
    # a closed surface: conservative, so the assembled stiffness is symmetric
    assert np.abs(K - K.T).max() <= 1e-10 * np.abs(K).max()


def test_open_surface_stiffness_is_not_symmetric():
    mesh = generate_bar((1.0, 0.4, 0.3), (2, 1, 1), "tetra10")
    P = FollowerPressure(mesh.points, [(_faces(mesh, ((-1, -1, 0.3 - 1e-9), (2, 2, 1))), 1e3)], 3)
    K = _dense(P, 0.02 * np.random.default_rng(0).standard_normal(P.n_dofs))
    assert np.abs(K - K.T).max() > 1e-3 * np.abs(K).max()


@pytest.mark.parametrize("element,cells", [("tetra10", (2, 1, 1)), ("pyramid", (1, 1, 1)), ("triangle6", (3, 2))])
def test_closed_surface_work_is_minus_p_times_the_volume_change(element, cells):
    dim = len(cells)
    size = (1.0, 0.4, 0.3)[:dim]
    mesh = generate_bar(size, cells, element)
    p = 2.5e3
    P = FollowerPressure(mesh.points, [(_faces(mesh), p)], dim)
    zero = np.zeros(P.n_dofs)
    assert P.volume(zero) == pytest.approx(np.prod(size), rel=1e-12)
    rng = np.random.default_rng(5)
    u0, u1 = 0.03 * rng.standard_normal(P.n_dofs), 0.03 * rng.standard_normal(P.n_dofs)
    assert P.work(u0, u1) == pytest.approx(-p * (P.volume(u1) - P.volume(u0)), rel=1e-10)
    # at rest, a uniform pressure on a closed surface is self-equilibrated
    assert np.abs(P.forces(zero).reshape(-1, dim).sum(axis=0)).max() < 1e-9 * p


def _bar_model(element, load, kind="static", steps=2, mass="lumped"):
    mesh = generate_bar((1.0, 0.2, 0.2), (6, 2, 2), element)
    top = ((-1.0, -1.0, 0.2 - 1e-9), (2.0, 2.0, 1.0))
    loads_ = Loads(pressure=[PressureLoad(box=top, value=load)]) if load else Loads()
    return Model(mesh, [Material(law="neohookean", quadrature="gauss2", E=1e5, nu=0.3, density=1000.0)],
                 fixed=[Fixed(box=((-1, -1, -1), (1e-9, 1, 1)))], loads=loads_,
                 solver=Solver(kind=kind, steps=steps, dt=2e-3, mass=mass, newton_tolerance=1e-10))


def test_small_pressure_acts_like_the_inward_traction():
    """At small deflection the follower pressure on the top face is the traction -p e_z."""
    p = 1.0
    model = _bar_model("tetra10", p)
    sim = Simulation(model)
    sim.run()
    mesh = model.mesh
    top = ((-1.0, -1.0, 0.2 - 1e-9), (2.0, 2.0, 1.0))
    ref = Model(mesh, model.materials, fixed=[Fixed(box=((-1, -1, -1), (1e-9, 1, 1)))],
                loads=Loads(nodal=[NodalLoad(box=top, force=(0.0, 0.0, -p), kind="traction")]),
                solver=Solver(kind="static", steps=2, newton_tolerance=1e-10))
    sim_ref = Simulation(ref)
    sim_ref.run()
    u, u_ref = sim.displacement, sim_ref.displacement
    assert np.abs(u_ref).max() > 0
    assert np.abs(u - u_ref).max() < 1e-3 * np.abs(u_ref).max()


def test_newton_converges_quadratically_under_a_large_follower_pressure(monkeypatch):
    """200 Pa on the top face (an open surface) bends the bar by ~35 % of its length: Newton with
    the full pressure stiffness (LU) converges quadratically in the end."""
    from tensormass.runtime.physics import newton as integrators
    model = _bar_model("tetra10", 200.0, steps=2)
    assert not model.pressure.closed and not model.pressure.symmetric
    residuals = []
    search = integrators.line_search

    def spy(potential, u, d, g, *args, **kwargs):
        residuals.append(float(np.linalg.norm(g[potential.free])))
        return search(potential, u, d, g, *args, **kwargs)

    monkeypatch.setattr(integrators, "line_search", spy)
    ctx = Context(model)
    integ = make_integrator(ctx)
    its = [integ.step(k)["newton"] for k in range(1, integ.n_steps + 1)]
    tip = ctx.u.reshape(-1, 3)[np.argmax(model.mesh.points[:, 0])]
    assert tip[2] < -0.3                                    # a large deflection
    assert max(its) <= 10, its
    r = residuals[-3:]                                     # the last iterations of the last step
    assert r[1] < 1e-3 * r[0] and r[2] < 1e-2 * r[1], residuals      # superlinear, not a fixed ratio
    # the solution is an equilibrium of the pressure at the deformed surface
    g = -ctx.asm.forces(ctx.u) - model.pressure.forces(ctx.u)
    assert np.linalg.norm(g[model.free_dofs]) < 1e-8 * np.linalg.norm(model.pressure.forces(ctx.u))


def test_dynamic_pressure_runs_with_consistent_mass_and_the_health_monitor():
    for kind in ("backward_euler", "implicit_euler"):
        model = _bar_model("tetra10", 200.0, kind=kind, steps=5, mass="consistent")
        summary = Simulation(model).run()
        assert summary["status"] == "ok", summary["message"]


def test_scene_keys():
    text = """
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [4, 1, 1]
element = "tetra10"
[[material]]
law = "hooke"
E = 1e5
nu = 0.3
[[fixed]]
box = [[-1, -1, -1], [0, 1, 1]]
[[loads.pressure]]
box = [[-1, -1, 0.2], [2, 2, 1]]
value = 300.0
[solver]
mass = "consistent"
kind = "backward_euler"
"""
    scene = Scene.from_string(text)
    assert scene.loads.pressure[0].value == 300.0 and scene.solver.mass == "consistent"
    model = Model.from_scene(scene)
    assert model.pressure is not None and model.mass_matrix.kind == "consistent"
    with pytest.raises(SceneError, match=r"loads.pressure\[0\].value: missing"):
        Scene.from_string(text.replace("value = 300.0", ""))
    with pytest.raises(SceneError, match=r"loads.pressure\[0\].value: expected a number"):
        Scene.from_string(text.replace("value = 300.0", "value = [1, 2, 3]"))
    with pytest.raises(SceneError, match=r"solver.mass: unknown value 'diagonal'"):
        Scene.from_string(text.replace('mass = "consistent"', 'mass = "diagonal"'))
    with pytest.raises(SceneError, match="solver.mass: 'consistent' needs an implicit solver"):
        Scene.from_string(text.replace('kind = "backward_euler"', 'kind = "explicit"'))
    with pytest.raises(SceneError, match=r"loads.pressure\[0\].box: no mesh node inside"):
        Scene.from_string(text.replace("box = [[-1, -1, 0.2], [2, 2, 1]]", "box = [[5, 5, 5], [6, 6, 6]]"))
    # a box with nodes but no whole boundary face
    with pytest.raises(TensormassError, match=r"loads.pressure\[0\]: no boundary face inside box"):
        Model.from_scene(Scene.from_string(text.replace("box = [[-1, -1, 0.2], [2, 2, 1]]",
                                                        "box = [[0.99, -1, 0.19], [1.1, 2, 1]]")))
