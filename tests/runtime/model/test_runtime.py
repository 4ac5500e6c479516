"""Tests for the runtime: model building, assembly, solvers, integrators and the Simulation driver.

Meshes are kept small: the whole file should run in well under a minute once
the numba caches are warm.
"""
import numpy as np
import pytest

from tensormass.runtime.kernels import kernels as kernels_module
from tensormass.runtime.assembly.assembly import Assembler, assemble, project_psd
from tensormass.runtime.base.errors import RunStopped, TensormassError
from tensormass.runtime.physics.newton import Context
from tensormass.runtime.physics.integrators import stable_time_step
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.model.model import Model
from tensormass.runtime.scene.types import Fixed, Loads, Material, MeshSpec, NodalLoad, Probe, Solver
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.run.simulation import Simulation
from tensormass.runtime.solve.solvers import LinearSolver

# The thesis' cantilever: 1.2 x 0.2 x 0.2 m, clamped at x = 0, under its own weight.
L, B, H = 1.2, 0.2, 0.2
E, NU, RHO, G = 1e6, 0.3, 800.0, 0.1
CLAMP = Fixed(box=((-1, -1, -1), (0, 1, 1)))


def tip_deflection_theory() -> float:
    """Euler-Bernoulli plus Timoshenko's shear term, for self weight."""
    area, inertia = B * H, B * H**3 / 12
    shear = E / (2 * (1 + NU))
    return RHO * G * area * L**4 / (8 * E * inertia) + RHO * G * area * L**2 / (2 * 5 / 6 * shear * area)


def beam(element="hexahedron", cells=(12, 2, 2), law="hooke", quadrature="gauss2", gravity=G, **solver):
    return Scene(mesh=MeshSpec(generate="bar", size=(L, B, H), cells=cells, element=element),
                 materials=[Material(law=law, quadrature=quadrature, E=E, nu=NU, density=RHO)],
                 fixed=[CLAMP], loads=Loads(gravity=(0.0, 0.0, -gravity)),
                 solver=Solver(**solver), probes=[Probe("tip", (L, B / 2, H / 2))])


def tip(summary) -> float:
    return -summary.probes["tip"][2]


# --------------------------------------------------------------------------- static accuracy


def test_hexahedron_cantilever_converges_to_beam_theory():
    w = tip_deflection_theory()
    errors = [abs(tip(Simulation(beam(cells=c)).run()) - w) / w for c in [(12, 2, 2), (24, 4, 4), (48, 8, 8)]]
    # hex8 with full integration locks in bending: slow, but monotone, convergence
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.04


def test_tetra10_cantilever_is_accurate_on_a_coarse_mesh():
    w = tip_deflection_theory()
    summary = Simulation(beam("tetra10", cells=(12, 2, 2))).run()
    assert abs(tip(summary) - w) / w < 0.03
    assert summary.iterations["newton"] == 1          # linear law: one Newton step


@pytest.mark.parametrize("law", ["hooke", "stvk"])
def test_mixed_bar_matches_hexahedron_bar(law):
    hexa = tip(Simulation(beam("hexahedron", cells=(24, 4, 4), law=law)).run())
    mixed = Simulation(beam("mixed", cells=(24, 4, 4), law=law)).run()
    assert {k["element"] for k in mixed.kernels} == {"hexahedron", "wedge", "pyramid", "tetra"}
    assert abs(tip(mixed) - hexa) / hexa < 0.03


def test_two_dimensional_cantilever_runs():
    scene = Scene(mesh=MeshSpec(generate="bar", size=(L, H), cells=(12, 2), element="triangle6"),
                  materials=[Material(law="hooke", quadrature="gauss2", E=E, nu=NU, density=RHO)],
                  fixed=[Fixed(box=((-1, -1), (0, 1)))], loads=Loads(gravity=(0.0, -G, 0.0)),
                  probes=[Probe("tip", (L, H / 2, 0.0))])
    summary = Simulation(scene).run()
    # plane strain: stiffer than the 3D beam by 1/(1 - nu^2) in bending, same order of magnitude
    assert 0.5 * tip_deflection_theory() < -summary.probes["tip"][1] < 1.2 * tip_deflection_theory()


# --------------------------------------------------------------------------- nonlinear statics


@pytest.mark.parametrize("law", ["stvk", "neohookean"])
def test_nonlinear_static_converges_quadratically(law):
    summary = Simulation(beam(law=law, steps=2)).run()
    assert max(summary.per_step["newton"]) <= 4
    hooke = tip(Simulation(beam()).run())
    assert abs(tip(summary) - hooke) / hooke < 0.01    # small load: close to linear


def test_large_load_with_load_stepping():
    summary = Simulation(beam(law="neohookean", gravity=150 * G * 10, steps=3, newton_max_iterations=40)).run()
    assert np.all(np.isfinite(summary.probes["tip"]))
    assert tip(summary) > 0.5 * L                        # large deflection, far beyond linear range
    assert summary.per_step["newton"][-1] <= 8
    assert summary.status == "ok" and summary.health["min_det_F"] > 0


def test_stvk_collapse_under_a_huge_load_is_not_a_result():
    # StVK softens in compression: under this load its elements invert near the clamp, an
    # equilibrium of the formula but not of a material; the run must say so (exit code 3)
    with pytest.raises(RunStopped, match="inverted") as info:
        Simulation(beam(law="stvk", gravity=150 * G * 10, steps=3, newton_max_iterations=40)).run()
    summary = info.value.summary
    assert info.value.status == "invalid" and summary.exit_code == 3
    assert summary.health["inverted_final"] > 0 and summary.health["min_det_F_final"] <= 0
    assert any(w["kind"] == "inverted" for w in summary.warnings)


def test_psd_projection_only_when_asked():
    always = Simulation(beam(law="neohookean", gravity=20 * G * 10, project_psd=True, newton_max_iterations=60)).run()
    auto = Simulation(beam(law="neohookean", gravity=20 * G * 10, newton_max_iterations=60)).run()
    assert abs(tip(always) - tip(auto)) < 1e-6 * tip(auto)
    assert auto.iterations["newton"] < always.iterations["newton"]   # projection costs quadratic convergence


def test_prescribed_displacement_stretches_the_bar():
    scene = beam(gravity=0.0)
    scene.fixed = [CLAMP, Fixed(box=((L, -1, -1), (L + 1, 1, 1)), displacement=(0.01, 0.0, 0.0), components=(0,))]
    scene.probes = [Probe("end", (L, B / 2, H / 2)), Probe("middle", (L / 2, B / 2, H / 2))]
    summary = Simulation(scene).run()
    assert summary.probes["end"][0] == pytest.approx(0.01)
    assert summary.probes["middle"][0] == pytest.approx(0.005, rel=0.05)


def test_unconverged_newton_raises_clear_error():
    with pytest.raises(TensormassError, match="did not converge at|did not converge"):
        Simulation(beam(law="neohookean", gravity=20 * G * 10, newton_max_iterations=1)).run()


def test_unfixed_body_gives_a_clear_error():
    scene = beam()
    scene.fixed = []
    with pytest.raises(TensormassError, match="no node is fixed"):
        Simulation(scene).run()
    scene.fixed = [Fixed(box=CLAMP.box, components=(2,))]      # x, y and rotations free
    with pytest.raises(TensormassError, match="rigid-body|singular|NaN"):
        Simulation(scene).run()


# --------------------------------------------------------------------------- dynamics


def test_damped_implicit_euler_settles_to_static_solution():
    static = tip(Simulation(beam()).run())
    for kind in ("implicit_euler", "backward_euler"):
        summary = Simulation(beam(kind=kind, steps=60, dt=0.05, rayleigh=(5.0, 0.0))).run()
        assert abs(tip(summary) - static) / static < 0.01, kind


@pytest.mark.parametrize("kind,law", [("implicit_euler", "hooke"), ("implicit_euler", "stvk"),
                                      ("backward_euler", "neohookean")])
def test_released_beam_never_gains_energy(kind, law):
    bent = Simulation(beam(law=law))
    bent.run()
    scene = beam(law=law, gravity=0.0, kind=kind, steps=40, dt=0.02)
    model = Model.from_scene(scene)
    summary = Simulation(model, u0=bent.displacement).run()
    start = assemble(model, bent.displacement.ravel())[0]
    total = np.concatenate([[start], np.add(summary.per_step["elastic"], summary.per_step["kinetic"])])
    assert np.all(np.diff(total) <= 1e-9 * total[0])
    assert total[-1] < total[0]                            # implicit Euler dissipates


def test_explicit_half_stable_step_is_stable_and_twice_raises():
    model = Model.from_scene(beam(kind="explicit", steps=1))
    dt = stable_time_step(Context(model))
    ok = Simulation(beam(kind="explicit", steps=1500, dt=0.5 * dt)).run()
    assert ok.stable_dt == pytest.approx(dt)
    assert np.all(np.isfinite(ok.probes["tip"])) and 0 < tip(ok) < 3 * tip_deflection_theory()
    frames = []
    unstable = "explicit integration unstable at step .*exceeds the estimated stable step"
    with pytest.raises(TensormassError, match=unstable):
        Simulation(beam(kind="explicit", steps=1500, dt=2.0 * dt), writer=RecordingWriter(frames)).run()
    assert frames and all(np.all(np.isfinite(d)) for _, _, d in frames)


def test_stable_step_matches_dense_eigenvalue():
    model = Model.from_scene(beam(kind="explicit", cells=(6, 1, 1)))
    _, _, K = assemble(model, np.zeros(model.n_dofs))
    free = model.free_dofs
    s = 1 / np.sqrt(model.mass[free])
    lam = np.linalg.eigvalsh(s[:, None] * K[free][:, free].toarray() * s[None, :]).max()
    assert stable_time_step(Context(model)) == pytest.approx(2 / np.sqrt(lam), rel=1e-4)


def test_inverting_implicit_step_retries_then_stops_clearly():
    scene = beam(law="neohookean", gravity=5e5, kind="implicit_euler", steps=3, dt=1.0)
    try:
        summary = Simulation(scene).run()
    except TensormassError as exc:
        assert "implicit_euler: step" in str(exc)
    else:
        assert np.all(np.isfinite(summary.probes["tip"]))


# --------------------------------------------------------------------------- leave out


def test_required_kernels_follow_the_solver():
    explicit = Model.required_kernels(beam(kind="explicit"))
    # explicit: forces to step, energy for the health monitor's energy balance; never stiffness
    assert explicit == {("hexahedron", "hooke", "gauss2", ("forces", "energy"))}
    static = Model.required_kernels(beam("mixed", law="stvk"))
    assert {k[0] for k in static} == {"hexahedron", "wedge", "pyramid", "tetra"}
    assert all(k[3] == ("energy", "forces", "stiffness") for k in static)


def test_hooke_scene_loads_no_other_kernel(monkeypatch):
    loaded = []
    real = kernels_module.load_kernel

    def spy(*args, **kwargs):
        loaded.append(args[:3])
        return real(*args, **kwargs)

    monkeypatch.setattr(kernels_module, "load_kernel", spy)
    summary = Simulation(beam(kind="explicit", steps=2, dt=1e-4)).run()
    assert loaded == [("hexahedron", "hooke", "gauss2")]
    assert summary.kernels[0]["outputs"] == ["forces", "energy"] and summary.energy is not None


def test_materials_by_region_and_box():
    scene = beam("mixed", cells=(8, 1, 1))
    scene.materials = [Material(region="tetra", law="stvk", E=E, nu=NU),
                       Material(box=((0, -1, -1), (0.3, 1, 1)), law="neohookean", E=2 * E, nu=NU),
                       Material(law="hooke", E=E, nu=NU)]
    laws = {(k["element"], k["law"]) for k in Model.from_scene(scene).kernel_info()}
    assert ("tetra", "stvk") in laws and ("hexahedron", "neohookean") in laws and ("wedge", "hooke") in laws
    scene.materials = [Material(region="tetra", law="stvk", E=E, nu=NU)]
    with pytest.raises(TensormassError, match="match no material"):
        Model.from_scene(scene)


def test_loads_masses_and_traction():
    scene = beam(cells=(6, 2, 2))
    scene.loads.nodal = [NodalLoad(box=((L, -1, -1), (L + 1, 1, 1)), force=(0, 0, -3.0)),
                         NodalLoad(box=((L, -1, -1), (L + 1, 1, 1)), force=(0, 5.0, 0), kind="traction")]
    model = Model.from_scene(scene)
    assert model.mass.sum() / 3 == pytest.approx(RHO * L * B * H)
    total = model.f_ext.reshape(-1, 3).sum(axis=0)
    assert total == pytest.approx([0.0, 5.0 * B * H, -3.0 - RHO * L * B * H * G])


# --------------------------------------------------------------------------- assembly


def tiny_mixed_model(law="stvk"):
    mesh = generate_bar(size=(1.0, 0.5, 0.5), cells=(4, 1, 1), element="mixed")
    return Model(mesh, [Material(law=law, quadrature="gauss2", E=E, nu=NU)], fixed=[CLAMP])


def test_global_stiffness_equals_dense_reference():
    model = tiny_mixed_model()
    u = 0.01 * np.random.default_rng(1).standard_normal(model.n_dofs)
    W, f, K = assemble(model, u)
    K_ref, f_ref, W_ref = np.zeros((model.n_dofs,) * 2), np.zeros(model.n_dofs), 0.0
    for part in model.parts:                                # the obvious python loop
        ue = model.element_displacements(part, u)
        fe, Ke = part.kernel.forces_and_stiffness(part.D, ue)
        W_ref += part.kernel.energy(part.D, ue).sum()
        for e, dofs in enumerate(part.dofs):
            f_ref[dofs] += fe[e]
            K_ref[np.ix_(dofs, dofs)] += Ke[e]
    assert np.allclose(K.toarray(), K_ref, rtol=1e-12, atol=1e-12 * np.abs(K_ref).max())
    assert np.allclose(f, f_ref) and W == pytest.approx(W_ref)
    assert abs(K - K.T).max() <= 1e-10 * abs(K).max()


def test_parallel_coloured_scatter_equals_serial():
    model = tiny_mixed_model()
    u = 0.01 * np.random.default_rng(2).standard_normal(model.n_dofs)
    serial = Assembler(model, parallel=False).forces_and_stiffness(u)[1]
    coloured = Assembler(model, parallel=True).forces_and_stiffness(u)[1]
    assert np.allclose(serial, coloured, rtol=1e-13, atol=0)


def test_internal_forces_are_minus_energy_gradient():
    model = tiny_mixed_model("neohookean")
    rng = np.random.default_rng(3)
    u = 0.02 * rng.standard_normal(model.n_dofs)
    asm = Assembler(model)
    f = asm.forces(u)
    h = 1e-6
    for dof in rng.choice(model.n_dofs, 12, replace=False):
        du = np.zeros(model.n_dofs)
        du[dof] = h
        grad = (asm.energy(u + du) - asm.energy(u - du)) / (2 * h)
        assert -grad == pytest.approx(f[dof], rel=1e-5, abs=1e-6 * np.abs(f).max())


def test_psd_projection_clamps_negative_eigenvalues():
    rng = np.random.default_rng(4)
    A = rng.standard_normal((5, 6, 6))
    P = project_psd(A + np.swapaxes(A, 1, 2))
    w = np.linalg.eigvalsh(P)
    assert w.min() > -1e-12 and np.allclose(P, np.swapaxes(P, 1, 2))


def test_linear_solvers_agree():
    model = tiny_mixed_model("hooke")
    ctx = Context(model)
    _, K = ctx.asm.forces_and_stiffness(np.zeros(model.n_dofs))
    b = np.random.default_rng(5).standard_normal(model.n_dofs)
    x_direct, _ = ctx.system.solve(LinearSolver("direct"), K, b)
    x_cg, its = ctx.system.solve(LinearSolver("cg", tol=1e-12, max_iterations=5000), K, b)
    assert its > 1 and np.allclose(x_cg, x_direct, rtol=1e-6, atol=1e-9 * np.abs(x_direct).max())


# --------------------------------------------------------------------------- the driver


class RecordingWriter:
    def __init__(self, frames):
        self.frames, self.closed = frames, False

    def write_frame(self, step, time, points, displacement, fields):
        self.frames.append((step, time, displacement.copy()))

    def close(self):
        self.closed = True


def test_summary_writer_and_progress():
    frames, calls = [], []
    writer = RecordingWriter(frames)
    scene = beam(kind="implicit_euler", steps=5, dt=0.01)
    scene.output.every = 2
    sim = Simulation(scene, progress=lambda k, n: calls.append((k, n)), writer=writer)
    summary = sim.run()
    assert [f[0] for f in frames] == [0, 2, 4, 5] and writer.closed
    assert calls[-1] == (5, 5)
    d = summary.to_dict()
    assert set(d["time"]) >= {"setup", "first_step", "assembly", "linear_solve", "total"}
    assert d["iterations"]["newton"] == 5 and d["steps"] == 5
    assert d["kernels"] == [{"element": "hexahedron", "law": "hooke", "quadrature": "gauss2",
                             "backend": scene.solver.backend, "outputs": ["energy", "forces", "stiffness"], "elements": 48,
                             "colours": 1, "segments": 1}]
    assert sim.displacement.shape == (sim.model.n_points, 3)
    assert summary["energy"] == pytest.approx(summary.per_step["elastic"][-1])
