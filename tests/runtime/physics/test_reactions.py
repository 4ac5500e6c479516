"""Reaction forces (runtime.physics.reactions): balance with the loads, the twisted bar's torque, dynamics, keys."""
import math

import numpy as np
import pytest

from tensormass.runtime.base.errors import SceneError, TensormassError
from tensormass.runtime.physics.reactions import Reactions
from tensormass.runtime.scene.types import Fixed, Loads, Material, MeshSpec, NodalLoad, PressureLoad, Solver
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.physics.motion import Amplitude, Rotation
from tensormass.runtime.run.simulation import Simulation

L, B, H = 1.2, 0.2, 0.2
RHO, G = 800.0, 9.81
CLAMP = Fixed(box=((-1, -1, -1), (1e-9, 1, 1)))


def cantilever(law="hooke", loads=None, fixed=(CLAMP,), cells=(6, 2, 2), **solver):
    return Scene(mesh=MeshSpec(generate="bar", size=(L, B, H), cells=cells, element="hexahedron"),
                 materials=[Material(law=law, quadrature="gauss2", E=1e6, nu=0.3, density=RHO)],
                 fixed=list(fixed), loads=loads or Loads(gravity=(0.0, 0.0, -G)), solver=Solver(**solver))


def test_reactions_balance_the_gravity_of_a_clamped_cantilever():
    sim = Simulation(cantilever())
    sim.run()
    (name, r), = sim.reactions().items()
    weight = RHO * G * L * B * H                      # independent of the model's load vector
    assert name == "fixed[0]"
    np.testing.assert_allclose(r["force"], [0.0, 0.0, weight], rtol=0, atol=1e-8 * weight)
    np.testing.assert_allclose(r["point"], [0.0, B / 2, H / 2])     # default: the clamped nodes' centroid
    # linear elasticity balances moments in the reference configuration: the weight acts at L/2
    assert r["moment"][1] == pytest.approx(-weight * L / 2, rel=1e-3)


def test_reactions_balance_gravity_and_a_traction_forces_and_moments():
    t = (0.0, 30.0, -50.0)                            # Pa on the end face x = L
    loads = Loads(gravity=(0.0, 0.0, -G), nodal=[NodalLoad(box=((L, -1, -1), (L, 1, 1)), force=t, kind="traction")])
    clamp = Fixed(box=CLAMP.box, name="clamp", moment_about=(0.0, 0.0, 0.0))
    sim = Simulation(cantilever("stvk", loads, fixed=(clamp,), steps=2))
    summary = sim.run()
    r = sim.reactions()["clamp"]
    applied = np.array(t) * B * H + np.array([0.0, 0.0, -RHO * G * L * B * H])
    np.testing.assert_allclose(r["force"] + applied, 0.0, atol=1e-8 * np.abs(applied).max())
    # moments too, about the origin, with the deformed positions (stvk is objective)
    x = sim.model.mesh.points + sim.displacement
    load_moment = np.cross(x, sim.model.f_ext.reshape(-1, 3)).sum(axis=0)
    np.testing.assert_allclose(r["moment"] + load_moment, 0.0, atol=1e-8 * np.abs(load_moment).max())
    assert np.array_equal(r["point"], [0.0, 0.0, 0.0])
    # the history's last row is the same reaction
    assert summary.per_step["reactions"]["clamp"]["force"][-1] == r["force"].tolist()


def test_two_dimensional_reactions_give_the_z_moment():
    scene = Scene(mesh=MeshSpec(generate="bar", size=(L, H), cells=(6, 2), element="triangle6"),
                  materials=[Material(law="hooke", quadrature="gauss2", E=1e6, nu=0.3, density=RHO)],
                  fixed=[Fixed(box=((-1, -1), (0, 1)))], loads=Loads(gravity=(0.0, -G)))
    sim = Simulation(scene)
    summary = sim.run()
    r = sim.reactions()["fixed[0]"]
    weight = RHO * G * L * H
    np.testing.assert_allclose(r["force"], [0.0, weight], atol=1e-8 * weight)
    assert isinstance(r["moment"], float) and r["moment"] == pytest.approx(weight * L / 2, rel=1e-3)
    assert summary.per_step["reactions"]["fixed[0]"]["moment"] == [[r["moment"]]]
    assert summary.units["reactions.force"] == "N/m"


# --------------------------------------------------------------------------- the twisted bar

AXIS_POINT = (1.0, 0.05, 0.05)


def twisted(angle, steps=3):
    end = Fixed(box=((1.0 - 1e-9, -1, -1), (1.0 + 1e-7, 1, 1)), name="end", moment_about=AXIS_POINT,
                rotation=Rotation(point=AXIS_POINT, angle=angle, axis=(1.0, 0.0, 0.0)))
    return Scene(mesh=MeshSpec(generate="bar", size=(1.0, 0.1, 0.1), cells=(6, 2, 2), element="hexahedron"),
                 materials=[Material(law="neohookean", quadrature="gauss2", E=1e6, nu=0.3, density=1100.0)],
                 fixed=[Fixed(box=((-1, -1, -1), (1e-9, 1, 1)), name="clamp"), end],
                 loads=Loads(gravity=(0.0, 0.0, 0.0)), solver=Solver(steps=steps, linear="direct"))


def test_twisted_bar_torque_is_the_derivative_of_the_energy():
    angle, delta = 40.0, 0.05                        # degrees
    sim = Simulation(twisted(angle))
    sim.run()
    r = sim.reactions()
    torque = r["end"]["moment"][0]                    # about the bar's axis, through the rotation point
    # independent: the equilibrium energy at angle +- delta (no loads: Pi = W), by the envelope theorem
    energies = []
    for sign in (1, -1):
        other = Simulation(twisted(angle + sign * delta, steps=1), u0=sim.dofs)
        energies.append(other.run().energy)
    dW = (energies[0] - energies[1]) / (2 * math.radians(delta))
    assert torque > 0 and torque == pytest.approx(dW, rel=1e-6)      # measured: 7e-9
    # nothing else acts: the clamp holds the opposite force and moment (moments about the same point)
    clamp = Reactions(sim.model).groups[0]
    assert clamp.name == "clamp"
    np.testing.assert_allclose(r["clamp"]["force"], -r["end"]["force"], atol=1e-8 * abs(torque))
    x = sim.model.mesh.points + sim.displacement
    residual = sim._reaction_residual().reshape(-1, 3)
    nodes = np.unique(clamp.nodes)                  # clamped: every component of these nodes
    total = np.cross(x[nodes] - AXIS_POINT, residual[nodes]).sum(axis=0)
    np.testing.assert_allclose(total, -np.asarray(r["end"]["moment"]), atol=1e-7 * abs(torque))


# --------------------------------------------------------------------------- dynamics


@pytest.mark.parametrize("kind", ["backward_euler", "implicit_euler", "explicit"])
def test_dynamic_reactions_balance_the_momentum_change(kind):
    """sum(reactions) + sum(loads) = dP/dt + alpha P (mass-proportional damping), P = sum(M v)."""
    dt = 2e-4 if kind == "explicit" else 2e-3
    # the support accelerates (a kinked amplitude), so its own inertia enters the reaction
    push = Fixed(box=((-1, -1, -1), (1e-9, 1, 1)), displacement=(0.0, 0.01, 0.02), amplitude="go")
    scene = cantilever("stvk", fixed=(push,), cells=(4, 1, 1), kind=kind, dt=dt, steps=6, rayleigh=(2.0, 0.0))
    scene.amplitudes = [Amplitude("go", "time", (0.0, 2 * dt, 6 * dt), (0.0, 0.1, 1.0))]
    rows = []

    def progress(k, n):
        v = sim.ctx.v
        P = (sim.model.mass_matrix @ v).reshape(-1, 3).sum(axis=0)
        rows.append((P, sim.reactions()["fixed[0]"]["force"], v))

    sim = Simulation(scene, progress=progress)
    sim.run()
    loads = sim.model.f_ext.reshape(-1, 3).sum(axis=0)
    scale = np.abs(loads).max()
    for (P0, _, _), (P1, F, _) in zip(rows, rows[1:]):
        damping = 2.0 * (P0 if kind == "explicit" else P1)       # explicit: forces at the step's start
        np.testing.assert_allclose(F + loads, (P1 - P0) / dt + damping, atol=1e-6 * scale)
    if kind == "backward_euler":
        # the state evaluation (a = 0) + M a is the step's own residual on the fixed dofs
        from tensormass.runtime.physics import reactions
        fixed, ctx = sim.model.fixed_dofs, sim.ctx
        inertia = sim.model.mass_matrix @ ((rows[-1][2] - rows[-2][2]) / dt)
        known = ctx.residual[1]
        ctx.residual = None
        again = reactions.residual(ctx, sim.integrator)
        np.testing.assert_allclose((again + inertia)[fixed], known[fixed], atol=1e-9 * np.abs(known[fixed]).max())


def test_generalized_alpha_reactions_balance_and_settle_on_the_weight():
    """The scheme's residual at its intermediate times (runtime.physics.reactions): sum(r) + sum(loads) =
    sum(M a) at t_{n+1-alpha_m} + alpha sum(M v) at t_{n+1-alpha_f}; heavily damped, the body settles
    and the clamp carries the weight."""
    scene = cantilever("stvk", cells=(4, 1, 1), kind="generalized_alpha", dt=0.04, steps=60, rayleigh=(10.0, 0.0))
    scene.solver.rho_inf = 0.5
    rows = []

    def progress(k, n):
        M = sim.model.mass_matrix
        total = (lambda x: (M @ x).reshape(-1, 3).sum(axis=0))
        rows.append((total(sim.integrator.a), total(sim.ctx.v), sim.reactions()["fixed[0]"]["force"]))

    sim = Simulation(scene, progress=progress)
    sim.run()
    am, af = sim.integrator.alpha_m, sim.integrator.alpha_f
    loads = sim.model.f_ext.reshape(-1, 3).sum(axis=0)
    weight = RHO * G * L * B * H
    for (A0, V0, _), (A1, V1, F) in zip(rows[:5], rows[1:6]):
        expected = (1 - am) * A1 + am * A0 + 10.0 * ((1 - af) * V1 + af * V0)
        np.testing.assert_allclose(F + loads, expected, atol=1e-6 * weight)
    assert rows[0][2][2] < 0.5 * weight                # gravity acts from t = 0: the body first falls
    np.testing.assert_allclose(rows[-1][2], [0.0, 0.0, weight], atol=1e-4 * weight)


# --------------------------------------------------------------------------- keys


def test_a_dof_held_by_two_entries_counts_for_the_first():
    first = Fixed(box=((-1, -1, -1), (1e-9, 1, 1)), name="a")
    second = Fixed(box=((-1, -1, -1), (1e-9, 1, 0.5 * H)), name="b", components=(2,))
    sim = Simulation(cantilever(fixed=(first, second)))
    sim.run()
    r = sim.reactions()
    assert np.all(r["b"]["force"] == 0.0)
    np.testing.assert_allclose(r["a"]["force"][2], RHO * G * L * B * H, rtol=1e-8)
    # the other order: b takes its nodes' z components
    sim = Simulation(cantilever(fixed=(second, first)))
    sim.run()
    r = sim.reactions()
    assert r["b"]["force"][2] != 0.0
    np.testing.assert_allclose(r["a"]["force"][2] + r["b"]["force"][2], RHO * G * L * B * H, rtol=1e-8)


def test_reaction_field_is_the_nodal_forces_on_the_supports():
    from tensormass.runtime.physics.reactions import reaction_field
    sim = Simulation(cantilever())
    sim.run()
    field = reaction_field(sim)
    held = np.zeros(sim.model.n_points, bool)
    held[sim.model.fixed_dofs // 3] = True
    assert field.shape == (sim.model.n_points, 3) and np.all(field[~held] == 0.0)
    np.testing.assert_allclose(field.sum(axis=0), sim.reactions()["fixed[0]"]["force"], rtol=1e-12)


def _scene_text(fixed_extra, second=""):
    return f"""
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [2, 1, 1]
element = "hexahedron"
[[material]]
law = "hooke"
quadrature = "gauss2"
E = 1e6
nu = 0.3
density = 100.0
[[fixed]]
box = [[-1, -1, -1], [0, 1, 1]]
{fixed_extra}
[[fixed]]
box = [[1, -1, -1], [1, 1, 1]]
{second}
"""


@pytest.mark.parametrize("extra, second, message", [
    ("", "moment_about = [0.0, 1.0]", "fixed[1].moment_about"),
    ("", 'moment_about = [0.0, "a", 1.0]', "fixed[1].moment_about[1]"),
    ('name = "x"', 'name = "x"', "fixed[1].name: duplicate"),
    ('name = "fixed[1]"', "", "fixed[1].name: duplicate"),
    ("name = 3", "", "fixed[0].name: expected a string"),
    ('name = " "', "", "fixed[0].name: must not be empty"),
])
def test_reaction_keys_are_checked(tmp_path, extra, second, message):
    path = tmp_path / "s.toml"
    path.write_text(_scene_text(extra, second))
    with pytest.raises(SceneError, match=message.replace("[", r"\[").replace("]", r"\]")):
        Scene.from_toml(path)


def test_scene_keys_reach_the_reactions(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(_scene_text('name = "clamp"\nmoment_about = [0.0, 0.0, 0.0]'))
    scene = Scene.from_toml(path)
    assert scene.fixed[0].name == "clamp" and scene.fixed[0].moment_about == (0.0, 0.0, 0.0)
    sim = Simulation(scene)
    with pytest.raises(TensormassError, match="not started"):
        sim.reactions()
    sim.run()
    r = sim.reactions()
    assert list(r) == ["clamp", "fixed[1]"]
    np.testing.assert_allclose(r["clamp"]["point"], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(r["fixed[1]"]["point"], [1.0, 0.1, 0.1])


def test_the_state_evaluation_matches_the_solvers_residual():
    """Outside a step (step 0, a state set from outside) the reactions come from one assembly at the
    state: at a static equilibrium (every load step) it agrees with Newton's residual."""
    from tensormass.runtime.physics import reactions
    end = ((L, -1, -1), (L, 1, 1))
    loads = Loads(gravity=(0.0, 0.0, -G), nodal=[NodalLoad(box=end, force=(0, 5.0, 0), kind="traction")],
                  pressure=[PressureLoad(box=((-1, -1, H), (2 * L, 1, H)), value=400.0)])   # top face, clamped edge too
    checked = []

    def progress(k, n):
        ctx = sim.ctx
        fixed = sim.model.fixed_dofs
        known = ctx.residual[1][fixed]
        saved, ctx.residual = ctx.residual, None
        again = reactions.residual(ctx, sim.integrator)[fixed]
        ctx.residual = saved
        np.testing.assert_allclose(again, known, atol=1e-9 * np.abs(known).max())
        checked.append(k)

    sim = Simulation(cantilever("stvk", loads, steps=2), progress=progress)
    sim.run()
    assert checked == [1, 2]
    # a state set from outside is not the solver's: the reactions follow it
    before = sim.reactions()["fixed[0]"]["force"]
    sim.ctx.u = sim.ctx.u * 1.01
    assert not np.allclose(sim.reactions()["fixed[0]"]["force"], before, rtol=1e-4)


def test_entries_selecting_mesh_regions(tmp_path):
    """[[fixed]] by a mesh group (tests/runtime/mesh/test_mesh_regions.py's bar: 'clamp' at x = 0, 'tip' at x = 1)."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).parents[1] / "mesh"))
    from test_mesh_regions import write_bar
    from tensormass.runtime.mesh.io import read_mesh
    from tensormass.runtime.model.model import Model

    mesh = read_mesh(write_bar(tmp_path / "bar.msh", element="hexahedron"))
    fixed = [Fixed(box=None, region="clamp", name="clamp"), Fixed(box=None, region="tip", components=(2,), name="tip")]
    model = Model(mesh, [Material(law="hooke", quadrature="gauss2", E=1e6, nu=0.3, density=RHO)], fixed=fixed,
                  loads=Loads(gravity=(0.0, 0.0, -G)))
    sim = Simulation(model)
    sim.run()
    r = sim.reactions()
    weight = RHO * G * 1.0 * 0.2 * 0.2
    assert r["tip"]["force"][0] == r["tip"]["force"][1] == 0.0 and r["tip"]["force"][2] > 0
    np.testing.assert_allclose(r["clamp"]["force"] + r["tip"]["force"], [0.0, 0.0, weight], atol=1e-8 * weight)
    np.testing.assert_allclose(r["tip"]["point"], [1.0, 0.1, 0.1])
