"""Shells in the runtime: scenes of CST-DKT triangles against plate and beam theory, the
co-rotational wrapper (rigid rotations, small-displacement limit, Euler's elastica), masses with
rotary inertia, moments and rotation constraints, and the errors a shell scene can meet."""
from __future__ import annotations

import math

import numpy as np
import pytest

import tensormass as tm
from tensormass.runtime.kernels.corotational import CorotationalShell, rotation_matrices
from tensormass.runtime.base.errors import SceneError
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.run.simulation import Simulation

E, NU, H = 1.0e7, 0.3, 0.01
D_PLATE = E * H**3 / (12 * (1 - NU**2))
# Kirchhoff plates, square a x a under uniform q: w_centre = c q a^4 / D (Timoshenko & Woinowsky-Krieger,
# Navier's series for simply supported edges, the clamped plate's series solution)
SIMPLY_SUPPORTED, CLAMPED = 0.00406235, 0.00126532


def plate_scene(n, edges, corotational=0, q=1.0):
    """A unit square plate of n x n cells (2 triangles each) under pressure q, edges "clamped" or
    "simply" supported (w = 0, in-plane displacements held, rotations free)."""
    comps = "" if edges == "clamped" else "components = [0, 1, 2]"
    boxes = ["[[-1, -1, -1], [1e-9, 2, 1]]", "[[0.999999, -1, -1], [2, 2, 1]]",
             "[[-1, -1, -1], [2, 1e-9, 1]]", "[[-1, 0.999999, -1], [2, 2, 1]]"]
    fixed = "".join(f"[[fixed]]\nbox = {b}\n{comps}\n" for b in boxes)
    return Scene.from_string(f"""
name = "plate"
[mesh]
generate = "plate"
size = [1.0, 1.0]
cells = [{n}, {n}]
[[material]]
law = "cst_dkt"
E = {E}
nu = {NU}
thickness = {H}
corotational = {corotational}
{fixed}
[[loads.pressure]]
box = [[-1, -1, -1], [2, 2, 1]]
value = {q}
[solver]
kind = "static"
steps = 1
backend = "c"
[[probe]]
name = "centre"
point = [0.5, 0.5, 0.0]
""")


def centre_deflection(scene):
    summary = Simulation(scene, output=False).run()
    assert summary.status == "ok", summary.message
    return -summary.probes["centre"][2]


@pytest.mark.parametrize("edges, coefficient", [("simply", SIMPLY_SUPPORTED), ("clamped", CLAMPED)])
def test_square_plate_matches_kirchhoff_and_converges(edges, coefficient):
    exact = coefficient * 1.0 / D_PLATE
    errors = [abs(centre_deflection(plate_scene(n, edges)) / exact - 1) for n in (8, 16)]
    assert errors[1] < 0.02                 # the target on 16 x 16 (x 2 triangles)
    assert errors[1] < errors[0]


def test_corotational_plate_is_the_linear_one_under_a_small_load():
    # deflection ~ h / 70: membrane stiffening ~ (w / h)^2 ~ 2e-4.  (Much smaller loads meet the
    # co-rotational forces' rounding floor, ~1e-16 x E h per node, below Newton's relative tolerance.)
    q = 0.1
    linear = centre_deflection(plate_scene(8, "clamped", 0, q))
    corotational = centre_deflection(plate_scene(8, "clamped", 1, q))
    assert abs(corotational / linear - 1) < 2e-3


def test_corotational_element_ignores_rigid_motions_and_keeps_its_energy_under_rotation():
    lin = tm.load_kernel("shell", "cst_dkt", "exact", backend="c")
    k = CorotationalShell(lin)
    rng = np.random.default_rng(3)
    X = rng.standard_normal((5, 3, 3))
    D = k.constants(X, E=E, nu=NU, thickness=H)
    psi = np.array([2.1, -0.4, 1.3])                        # a rotation of 2.5 rad
    Q = rotation_matrices(psi[None])[0]
    rigid = np.zeros((5, 3, 6))
    rigid[:, :, :3] = X @ Q.T - X + [0.3, -1.0, 2.0]
    rigid[:, :, 3:] = psi
    assert np.abs(k.forces(D, rigid)).max() < 1e-9 * np.abs(lin.stiffness(lin.constants(X, E=E, nu=NU, thickness=H),
                                                                          np.zeros((5, 3, 6)))).max()
    # a deformation, then the same deformation rotated: same energy, forces rotated with it
    u = 1e-3 * rng.standard_normal((5, 3, 6))
    R = np.stack([rotation_matrices(u[e, :, 3:]) for e in range(5)])
    from scipy.spatial.transform import Rotation
    turned = np.zeros_like(u)
    turned[:, :, :3] = (X + u[:, :, :3]) @ Q.T - X
    turned[:, :, 3:] = Rotation.from_matrix((Q @ R).reshape(-1, 3, 3)).as_rotvec().reshape(5, 3, 3)
    assert np.allclose(k.energy(D, turned), k.energy(D, u), rtol=1e-9)
    # the nodal forces turn with it (the moments are conjugate to the rotation vectors, which
    # do not turn linearly: the energy's equality covers them)
    f, g = k.forces(D, u).reshape(5, 3, 6)[:, :, :3], k.forces(D, turned).reshape(5, 3, 6)[:, :, :3]
    assert np.allclose(g, f @ Q.T, atol=1e-9 * np.abs(f).max())


def test_corotational_forces_are_the_gradient_of_its_energy():
    """f = -B^T K_bar u_bar with B the exact derivative of the local dofs (the frame's spin and the
    Jacobians of exp and log included): central differences of W agree at large rotations."""
    lin = tm.load_kernel("shell", "cst_dkt", "exact", backend="c")
    k = CorotationalShell(lin)
    rng = np.random.default_rng(11)
    X = rng.standard_normal((3, 3, 3))
    D = k.constants(X, E=E, nu=NU, thickness=0.05)
    u = 0.3 * rng.standard_normal((3, 3, 6))
    u[:, :, 3:] += [0.9, -1.4, 0.6]                          # rotation vectors of ~1.8 rad
    f, h = k.forces(D, u), 1e-6
    fd = np.zeros_like(f)
    for r in range(18):
        step = np.zeros(18)
        step[r] = h
        step = step.reshape(3, 6)
        fd[:, r] = -(k.energy(D, u + step) - k.energy(D, u - step)) / (2 * h)
    assert np.abs(f - fd).max() < 1e-7 * np.abs(fd).max()
    K = k.stiffness(D, u)
    assert np.allclose(K, np.swapaxes(K, 1, 2)) and np.linalg.eigvalsh(K).min() > -1e-9 * np.abs(K).max()


def test_corotational_small_displacements_match_the_linear_kernel():
    lin = tm.load_kernel("shell", "cst_dkt", "exact", backend="c")
    k = CorotationalShell(lin)
    X = np.random.default_rng(5).standard_normal((4, 3, 3))
    D, Dl = k.constants(X, E=E, nu=NU, thickness=H), lin.constants(X, E=E, nu=NU, thickness=H)
    u = 1e-8 * np.random.default_rng(6).standard_normal((4, 3, 6))
    f, fl = k.forces(D, u), lin.forces(Dl, u)
    assert np.abs(f - fl).max() < 1e-5 * np.abs(fl).max()
    assert np.allclose(k.stiffness(D, np.zeros((4, 3, 6))), lin.stiffness(Dl, np.zeros((4, 3, 6))),
                       atol=1e-9 * np.abs(lin.stiffness(Dl, np.zeros((4, 3, 6)))).max())


def test_strip_rolled_by_an_end_moment_follows_the_elastica(tmp_path):
    """Quarter circle: M = (pi / 2) E I / L bends the strip to radius R = E I / M = 2 L / pi."""
    scene = Scene.from_toml(tm_example("strip_rollup.toml"))
    summary = Simulation(scene, output=False).run()
    assert summary.status == "ok", summary.message
    tip = np.array(summary.probes["tip"])
    R = 2.0 / math.pi
    assert abs(tip[0] - (R - 1.0)) < 2e-3 and abs(tip[2] - R) < 2e-3


def tm_example(name):
    from pathlib import Path
    return Path(__file__).resolve().parents[3] / "examples" / "shells" / name


def test_shell_masses_carry_rotary_inertia():
    scene = plate_scene(4, "clamped")
    from tensormass.runtime.model.model import Model
    m = Model.from_scene(scene)
    M = m.mass.reshape(-1, 6)
    rho = scene.materials[0].density
    assert np.isclose(M[:, 0].sum(), rho * H * 1.0)          # the plate's mass on each translation
    assert np.allclose(M[:, 3], M[:, 0] * H**2 / 12)          # rotary inertia m h^2 / 12


def test_shell_scene_errors_name_the_key():
    base = """
[mesh]
generate = "plate"
size = [1.0, 1.0]
cells = [2, 2]
[[material]]
law = "cst_dkt"
E = 1e6
nu = 0.3
{extra}
[[fixed]]
box = [[-1, -1, -1], [1e-9, 2, 1]]
{fixed}
[solver]
kind = "static"
"""
    with pytest.raises(SceneError, match="thickness"):
        Scene.from_string(base.format(extra="", fixed=""))
    with pytest.raises(SceneError, match="components"):
        Scene.from_string(base.format(extra="thickness = 0.01", fixed="components = [6]"))
    with pytest.raises(SceneError, match="mesh.size"):
        Scene.from_string(base.format(extra="thickness = 0.01", fixed="").replace("size = [1.0, 1.0]",
                                                                                  "size = [1.0, 1.0, 1.0]"))


def squeezed_ball(preserve: bool, steps: int = 8) -> str:
    return f"""
name = "ball"
[mesh]
generate = "sphere"
radius = 1.0
subdivisions = 2
[[material]]
law = "cst_dkt"
E = 3000.0
nu = 0.49
thickness = 0.1
density = 100.0
[[fixed]]
box = [[-2, -2, -2], [2, 2, -0.9]]
[[fixed]]
box = [[-2, -2, 0.9], [2, 2, 2]]
displacement = [0.0, 0.0, -0.4]
[solver]
kind = "implicit_euler"
dt = 0.02
steps = {steps}
backend = "c"
preserve_volume = {str(preserve).lower()}
"""


def test_volume_constraint_keeps_a_squeezed_ball_at_its_rest_volume_after_every_step():
    from tensormass.runtime.physics.volume_constraint import VolumeConstraint
    volumes = {}
    for preserve in (False, True):
        scene = Scene.from_string(squeezed_ball(preserve))
        seen = []

        def record(sim):
            m = sim.model
            U = sim.ctx.u.reshape(m.n_points, 6)
            vc = VolumeConstraint(m.mesh.blocks[0].cells, m.mesh.points)
            seen.append(vc.volume(m.mesh.points + U[:, :3]) / vc.rest_volume - 1.0)

        summary = Simulation(scene, on_step=record).run()
        assert summary.status == "ok", summary.message
        volumes[preserve] = np.array(seen)
    assert np.abs(volumes[True]).max() <= 1e-8               # the bound, after every step
    assert volumes[False].min() < -0.01                      # without it the squeezed ball loses volume


def test_volume_constraint_needs_a_closed_shell():
    text = squeezed_ball(True).replace('generate = "sphere"\nradius = 1.0\nsubdivisions = 2',
                                       'generate = "plate"\nsize = [1.0, 1.0]\ncells = [2, 2]')
    text = text.replace("[[fixed]]\nbox = [[-2, -2, 0.9], [2, 2, 2]]\ndisplacement = [0.0, 0.0, -0.4]\n", "")
    text = text.replace("box = [[-2, -2, -2], [2, 2, -0.9]]", "box = [[-1, -1, -1], [1e-9, 2, 1]]")
    with pytest.raises(Exception, match="preserve_volume"):
        Simulation(Scene.from_string(text)).run()


def test_corotational_results_do_not_depend_on_the_thread_count():
    from tensormass.runtime.base import parallel
    lin = tm.load_kernel("shell", "cst_dkt", "exact", backend="c")
    k = CorotationalShell(lin)
    rng = np.random.default_rng(9)
    X = rng.standard_normal((64, 3, 3))
    D = k.constants(X, E=E, nu=NU, thickness=H)
    u = 0.1 * rng.standard_normal((64, 3, 6))
    with parallel.threads(1):
        f1, K1 = k.forces_and_stiffness(D, u)
    with parallel.threads(parallel.available()):
        f2, K2 = k.forces_and_stiffness(D, u)
    assert np.array_equal(f1, f2) and np.array_equal(K1, K2)


def pinched_hemisphere(n, folder):
    """MacNeal & Harder's pinched hemisphere with an 18 deg hole (R = 10, h = 0.04, E = 6.825e7,
    nu = 0.3, +-2 N at four equator points), as the usual quarter model with symmetry conditions:
    the radial displacement at the loads is 0.094 (MacNeal-Harder; 0.0924 converged, Simo et al.)."""
    import meshio
    from tensormass.runtime.mesh import surfaces
    P, T = surfaces.hemisphere(10.0, n, 4 * n, hole_degrees=18.0)
    T = T[np.all((P[T][:, :, 0] > -1e-9) & (P[T][:, :, 1] > -1e-9), axis=1)]
    used, inverse = np.unique(T, return_inverse=True)
    P, T = P[used], inverse.reshape(T.shape)
    P[np.abs(P) < 1e-12] = 0.0
    path = folder / f"hemisphere_{n}.vtu"
    meshio.write(path, meshio.Mesh(P, [("triangle", T)]))
    on_x, on_y = "[[9.99, -1e-6, -1e-6], [10.01, 1e-6, 1e-6]]", "[[-1e-6, 9.99, -1e-6], [1e-6, 10.01, 1e-6]]"
    text = f"""
[mesh]
file = "{path}"
element = "shell"
[[material]]
law = "cst_dkt"
E = 6.825e7
nu = 0.3
thickness = 0.04
corotational = 0
[[fixed]]
box = [[-1e-6, -1, -1], [1e-6, 11, 11]]
components = [0, 4, 5]
[[fixed]]
box = [[-1, -1e-6, -1], [11, 1e-6, 11]]
components = [1, 3, 5]
[[fixed]]
box = {on_x}
components = [2]
[[loads.force]]
box = {on_x}
value = [1.0, 0.0, 0.0]
[[loads.force]]
box = {on_y}
value = [0.0, -1.0, 0.0]
[solver]
kind = "static"
steps = 1
backend = "c"
[[probe]]
name = "A"
point = [10.0, 0.0, 0.0]
[[probe]]
name = "B"
point = [0.0, 10.0, 0.0]
"""
    summary = Simulation(Scene.from_string(text), output=False).run()
    assert summary.status == "ok", summary.message
    return summary.probes["A"][0], -summary.probes["B"][1]


def test_pinched_hemisphere_against_its_published_reference(tmp_path):
    coarse, _ = pinched_hemisphere(8, tmp_path)
    a, b = pinched_hemisphere(16, tmp_path)
    assert abs(a - b) < 0.01 * a                       # the two loads: the same radial displacement
    assert abs(a / 0.094 - 1) < 0.025 and abs(a / 0.0924 - 1) < 0.01
    assert coarse < a                                  # converging from below (0.0915, 0.0926, 0.0929 at 32)


def test_pressure_amplitudes_scale_follower_pressures_over_time():
    """A pressure with an amplitude follows it in dynamic runs (+1 and -1: mirror responses, 0:
    none); a static run refuses one (it ramps its pressures with the load factor)."""
    def run(values, kind="implicit_euler"):
        text = squeezed_ball(False, steps=4).replace(
            "[[fixed]]\nbox = [[-2, -2, 0.9], [2, 2, 2]]\ndisplacement = [0.0, 0.0, -0.4]\n", "")
        text = text.replace('kind = "implicit_euler"', f'kind = "{kind}"')
        text += f"""
[[amplitude]]
name = "a"
time = [0.0, 1.0]
value = {values}
[[loads.pressure]]
box = [[-2, -2, 0.0], [2, 2, 2]]
value = 5.0
amplitude = "a"
[[probe]]
name = "top"
point = [0.0, 0.0, 1.0]
"""
        summary = Simulation(Scene.from_string(text), output=False).run()
        return np.array(summary.probes["top"])
    up, down, none = run([1.0, 1.0]), run([-1.0, -1.0]), run([0.0, 0.0])
    assert up[2] < 0 < down[2] and np.isclose(up[2], -down[2], rtol=0.05)
    assert np.abs(none).max() < 1e-12 * abs(up[2])          # rounding only
    with pytest.raises(Exception, match="amplitude"):
        run([1.0, 1.0], kind="static")


def test_a_surface_file_becomes_shells_and_quadratic_surfaces_are_refused(tmp_path):
    """file = ... with element = "shell": the file's triangles (its curves and points left out);
    a quadratic surface is refused by name, with what to do."""
    import meshio
    from tensormass.runtime.mesh import surfaces
    P, T = surfaces.icosphere(1.0, 1)
    path = tmp_path / "ball.vtu"
    meshio.write(path, meshio.Mesh(P, [("triangle", T), ("line", T[:3, :2]), ("vertex", T[:2, :1])]))
    text = squeezed_ball(True, steps=2).replace(
        'generate = "sphere"\nradius = 1.0\nsubdivisions = 2', f'file = "{path}"\nelement = "shell"')
    summary = Simulation(Scene.from_string(text), output=False).run()
    assert summary.status == "ok", summary.message
    six = np.hstack([T, T])                                  # any 6-node rows: refused before any use
    meshio.write(tmp_path / "ball6.vtu", meshio.Mesh(P, [("triangle6", six)]))
    with pytest.raises(SceneError, match=r"triangle6 .*element order 1"):
        Scene.from_string(text.replace("ball.vtu", "ball6.vtu"))


def test_a_probe_between_nodes_interpolates_on_its_triangle():
    """A probe inside a triangle reads the barycentric mean of its nodes' displacements (the shell's
    translations are linear on the triangle); one off the surface is refused naming the probe."""
    from tensormass.runtime.mesh.probes import ProbeError, locate_point
    sim = Simulation(plate_scene(8, "simply"), output=False)
    sim.run()
    mesh = sim.model.mesh
    probe = locate_point(mesh, [0.3, 0.45, 0.0], "inside")
    assert probe.nodes.size == 3 and np.all(probe.weights > 0) and probe.weights.sum() == pytest.approx(1.0)
    x = probe.weights @ mesh.points[probe.nodes]
    assert np.allclose(x, [0.3, 0.45, 0.0], atol=1e-12)
    U = sim.displacement[:, :3]
    assert np.allclose(probe.value(U), probe.weights @ U[probe.nodes])
    with pytest.raises(ProbeError, match="'above' .* not on the shell surface"):
        locate_point(mesh, [0.5, 0.5, 0.5], "above")


def test_an_explicit_shell_whose_rotations_run_away_is_stopped_naming_them():
    """Explicit shells: a nodal rotation past MAX_ROTATION while the translations stay bounded stops
    the run saying so (not blaming dt); a translation past 1e3 body sizes still reads as dt."""
    from tensormass.runtime.base.errors import TensormassError
    from tensormass.runtime.physics.integrators import MAX_ROTATION
    scene = Scene.from_dict({"mesh": {"generate": "plate", "size": [1.0, 1.0], "cells": [2, 2]},
                             "material": [{"law": "cst_dkt", "E": E, "nu": NU, "thickness": H, "density": 100.0}],
                             "solver": {"kind": "explicit", "dt": 1e-5, "steps": 1, "backend": "c"}})
    sim = Simulation(scene, output=False)
    sim.run()
    integ, model = sim.integrator, sim.model
    dpn = model.dofs_per_node
    u = np.zeros(model.n_dofs)
    u[3::dpn] = 2 * MAX_ROTATION                       # a rotation about x at every node
    with pytest.raises(TensormassError, match=r"rotations reached 2e\+03 rad while no node moved more than 0 m"):
        integ._check(u, np.zeros_like(u), 7)
    u[0::dpn] = 2e3 * model.size
    with pytest.raises(TensormassError, match="stable step"):
        integ._check(u, np.zeros_like(u), 8)
