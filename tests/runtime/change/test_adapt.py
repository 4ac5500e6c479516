"""Tests for dynamic adaptation (runtime.change.adapt): criteria, law switching on masks, constant-K
assembly, hysteresis, reachable kernels, conforming refinement, VTU fields and scene errors.

Meshes are tiny and every kernel is a committed numba one: the file runs in a few seconds.
"""
from __future__ import annotations

import copy

import meshio
import numpy as np
import pytest

import tensormass as tm
from tensormass import laws
from tensormass.runtime.kernels import kernels as kernels_module
from tensormass.runtime.change.adapt import CRITERIA, Adapter, Change, criteria
from tensormass.runtime.assembly.assembly import Assembler
from tensormass.apps.commands import run_scene
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.physics.newton import Context
from tensormass.runtime.mesh.container import CellBlock, Mesh
from tensormass.runtime.mesh.checks import check_mesh
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.model.model import Model
from tensormass.runtime.scene.types import Adapt, Fixed, Material
from tensormass.runtime.base.errors import SceneError

E, NU, RHO = 1e6, 0.3, 800.0
L, B, H = 1.2, 0.2, 0.2
CLAMP_3D = Fixed(box=((-1, -1, -1), (0, 1, 1)))
CLAMP_2D = Fixed(box=((-1, -1), (0, 1)))


# --------------------------------------------------------------------------- helpers


def bar(element="hexahedron", cells=(6, 1, 1)):
    size = (L, B, H) if len(cells) == 3 else (L, H)
    return generate_bar(size, cells, element)


def model_of(mesh, law="hooke", rules=(), quadrature=None, fixed=None):
    """A Model straight from a mesh (no scene): one material, optionally clamped at x = 0."""
    if quadrature is None:      # the kernels other tests compile too (the checks hold at any quadrature)
        quadrature = "gauss1" if mesh.blocks[0].type == "tetra" else "gauss2"
    if fixed is None:
        fixed = [CLAMP_3D if mesh.dim == 3 else CLAMP_2D]
    return Model(mesh, [Material(law=law, quadrature=quadrature, E=E, nu=NU, density=RHO)],
                 fixed=fixed, adapt=list(rules))


def rotation_matrix(degrees, dim=3, axis=(0.0, 0.0, 1.0)):
    t = np.radians(degrees)
    if dim == 2:
        return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(t) * Kx + (1 - np.cos(t)) * Kx @ Kx       # Rodrigues


def rigid_rotation(points, degrees, axis=(0.0, 0.0, 1.0)):
    """u = (R - I) X, flat."""
    R = rotation_matrix(degrees, points.shape[1], axis)
    return (points @ R.T - points).ravel()


def scene_text(element="hexahedron", cells=(8, 2, 2), law="hooke", quadrature="gauss2", gravity=9.81,
               E_=E, kind="static", steps=1, rules="", extra=""):
    dim = len(cells)
    size = [L, B, H] if dim == 3 else [L, H]
    g = [0.0] * (dim - 1) + [-gravity]
    lo, hi = [-1] * dim, [0] + [1] * (dim - 1)
    tip = [L, B / 2, H / 2] if dim == 3 else [L, H / 2]
    return f"""
name = "adapt"
[mesh]
generate = "bar"
size = {size}
cells = {list(cells)}
element = "{element}"
[[material]]
law = "{law}"
quadrature = "{quadrature}"
E = {E_!r}
nu = {NU}
density = {RHO}
[[fixed]]
box = [{lo}, {hi}]
[loads]
gravity = {g}
[solver]
kind = "{kind}"
steps = {steps}
[[probe]]
name = "tip"
point = {tip}
{extra}
{rules}
"""


def rule_text(**keys) -> str:
    body = "\n".join(f"{'from' if k == 'from_' else k} = {_toml(v)}" for k, v in keys.items())
    return f"[[adapt]]\n{body}\n"


def _toml(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    return repr(v)


def group_parts(model, group=0):
    g = model.groups[group]
    return g, [model.parts[i] for i in g.parts]


def fresh_constants(model, part, local):
    """Constants of the given part-local cells from a freshly loaded kernel (not the model's D)."""
    kernel = tm.load_kernel(part.element, part.law, part.quadrature)
    return kernel, kernel.constants(model.mesh.points[part.cells[local]], E=E, nu=NU)


# --------------------------------------------------------------------------- 1. criteria on known states


@pytest.mark.parametrize("element, cells", [("hexahedron", (6, 1, 1)), ("tetra", (3, 1, 1)),
                                            ("triangle", (6, 2)), ("quad", (6, 2))])
def test_criteria_at_rest(element, cells):
    model = model_of(bar(element, cells))
    values = criteria(model, np.zeros(model.n_dofs), CRITERIA, Assembler(model))
    assert set(values) == set(CRITERIA)
    for name in CRITERIA:
        assert values[name].shape == (model.mesh.n_cells,) and np.all(np.isfinite(values[name]))
    for name in ("R_L", "R_A", "R_S", "rotation"):
        assert np.abs(values[name]).max() < 1e-12, name


@pytest.mark.parametrize("element, cells", [("hexahedron", (6, 1, 1)), ("tetra", (3, 1, 1))])
@pytest.mark.parametrize("axis", [(0.0, 0.0, 1.0), (1.0, 2.0, 3.0)])
def test_rigid_rotation_3d(element, cells, axis):
    model = model_of(bar(element, cells))
    u = rigid_rotation(model.mesh.points, 30.0, axis)
    values = criteria(model, u, ("R_L", "R_A", "rotation"))
    assert np.allclose(values["rotation"], 30.0, rtol=0, atol=1e-8)
    assert np.abs(values["R_L"]).max() < 1e-12
    assert np.abs(values["R_A"]).max() < 1e-12


@pytest.mark.parametrize("element", ["triangle", "quad"])
@pytest.mark.parametrize("degrees", [30.0, -30.0, 120.0])
def test_rigid_rotation_2d(element, degrees):
    model = model_of(bar(element, (6, 2)))
    values = criteria(model, rigid_rotation(model.mesh.points, degrees), ("R_L", "R_A", "rotation"))
    assert np.allclose(values["rotation"], abs(degrees), rtol=0, atol=1e-8)
    assert np.abs(values["R_L"]).max() < 1e-12 and np.abs(values["R_A"]).max() < 1e-12


def test_rotation_beyond_90_degrees_3d():
    model = model_of(bar())
    values = criteria(model, rigid_rotation(model.mesh.points, 150.0, (0, 1, 1)), ("rotation",))
    assert np.allclose(values["rotation"], 150.0, rtol=0, atol=1e-7)


@pytest.mark.parametrize("element, cells", [("hexahedron", (6, 1, 1)), ("tetra", (3, 1, 1)), ("triangle", (6, 2))])
def test_uniform_stretch(element, cells):
    model = model_of(bar(element, cells))
    X = model.mesh.points
    u = np.zeros_like(X)
    u[:, 0] = 0.1 * X[:, 0]                                 # x -> 1.1 x
    values = criteria(model, u.ravel(), ("R_L", "R_A", "rotation", "R_S"), Assembler(model))
    # every cell has an edge along x (stretched by 10 %) and no edge is stretched more
    assert np.allclose(values["R_L"], 0.1, rtol=0, atol=1e-12)
    assert np.allclose(values["R_A"], 0.1, rtol=0, atol=1e-12)
    assert np.allclose(values["rotation"], 0.0, rtol=0, atol=1e-8)
    assert np.all(values["R_S"] > 0)


def test_stress_criterion_definition():
    """R_S = sum_j (S0 / k) |f_j| / S: the lumped nodal weights over the current measure."""
    model = model_of(bar("triangle", (6, 2)))
    asm = Assembler(model)
    rng = np.random.default_rng(3)
    u = 0.01 * rng.standard_normal(model.n_dofs)
    R_S = criteria(model, u, ("R_S",), asm)["R_S"]
    part = model.parts[0]
    kernel, D = fresh_constants(model, part, np.arange(len(part.cells)))
    ue = u.reshape(-1, 2)[part.cells]
    fe = kernel.forces(D, ue).reshape(len(part.cells), 3, 2)
    x = model.mesh.points[part.cells] + ue
    a, b = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]
    S = 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    expected = np.empty(model.mesh.n_cells)
    expected[part.cell_ids] = np.linalg.norm(fe, axis=2).sum(axis=1) * (part.volume / 3) / S
    np.testing.assert_allclose(R_S, expected, rtol=1e-10)


def test_stress_criterion_under_load_and_objectivity():
    mesh = bar()
    hooke, stvk = model_of(mesh, "hooke"), model_of(mesh, "stvk")
    X = mesh.points
    stretch = np.zeros_like(X)
    stretch[:, 0] = 0.01 * X[:, 0]
    for model in (hooke, stvk):
        asm = Assembler(model)
        assert np.all(criteria(model, stretch.ravel(), ("R_S",), asm)["R_S"] > 0)
        assert np.abs(criteria(model, np.zeros(model.n_dofs), ("R_S",), asm)["R_S"]).max() == 0.0
        translated = np.tile([0.3, -0.2, 0.1], mesh.n_points)
        assert np.abs(criteria(model, translated, ("R_S",), asm)["R_S"]).max() < 1e-9
    # StVK is frame-invariant: a rigid rotation is stress free; linear elasticity is not
    rotated = rigid_rotation(X, 30.0)
    loaded = criteria(stvk, stretch.ravel(), ("R_S",), Assembler(stvk))["R_S"].max()
    assert criteria(stvk, rotated, ("R_S",), Assembler(stvk))["R_S"].max() < 1e-9 * loaded
    assert criteria(hooke, rotated, ("R_S",), Assembler(hooke))["R_S"].min() > loaded


def _triangle(h=np.sqrt(3) / 2, scale=1.0):
    return Mesh(scale * np.array([[0.0, 0.0], [1.0, 0.0], [0.5, h]]), [CellBlock("triangle", np.array([[0, 1, 2]]))])


def _tetra(flatten=1.0, scale=1.0):
    p = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])
    p[:, 2] *= flatten
    cells = np.array([[0, 1, 2, 3]])
    if np.linalg.det(p[1:] - p[0]) < 0:
        cells = cells[:, [0, 2, 1, 3]]
    return Mesh(scale * p, [CellBlock("tetra", cells)])


@pytest.mark.parametrize("scale", [1.0, 0.037, 25.0])
def test_quality_of_regular_simplices_is_one(scale):
    for mesh in (_triangle(scale=scale), _tetra(scale=scale)):
        model = model_of(mesh, fixed=())
        values = criteria(model, np.zeros(model.n_dofs), ("R_M", "R_HM"))
        assert values["R_M"] == pytest.approx([1.0], abs=1e-12)
        assert values["R_HM"] == pytest.approx([1.0], abs=1e-12)
        # invariant under rigid motions and uniform scaling of the current shape
        u = rigid_rotation(mesh.points, 40.0, (1, 1, 0)) if mesh.dim == 3 else rigid_rotation(mesh.points, 40.0)
        moved = criteria(model, u, ("R_M", "R_HM"))
        assert moved["R_M"] == pytest.approx([1.0], abs=1e-10) and moved["R_HM"] == pytest.approx([1.0], abs=1e-10)
        grown = criteria(model, 0.5 * mesh.points.ravel(), ("R_M", "R_HM"))
        assert grown["R_M"] == pytest.approx([1.0], abs=1e-10) and grown["R_HM"] == pytest.approx([1.0], abs=1e-10)


@pytest.mark.parametrize("h", [0.5, 0.1, 0.01])
def test_quality_of_a_flat_triangle(h):
    model = model_of(_triangle(h=h), fixed=())
    values = criteria(model, np.zeros(model.n_dofs), ("R_M", "R_HM"))
    edges = np.array([1.0, np.hypot(0.5, h), np.hypot(0.5, h)])
    c, mean, area = np.sqrt(3) / 4, edges.mean(), h / 2
    assert values["R_M"][0] == pytest.approx(area / (c * mean**2), rel=1e-12)
    assert values["R_HM"][0] == pytest.approx(area * np.mean(1 / edges) / (c * mean), rel=1e-12)
    assert values["R_M"][0] < 1 and values["R_HM"][0] < 1


def test_quality_drops_when_flattened():
    tet = model_of(_tetra(flatten=0.2), fixed=())
    assert criteria(tet, np.zeros(tet.n_dofs), ("R_M",))["R_M"][0] < 0.5
    regular = model_of(_tetra(), fixed=())
    X = regular.mesh.points
    squash = np.zeros_like(X)
    squash[:, 2] = -0.9 * X[:, 2]                           # the current shape gets flat
    values = criteria(regular, squash.ravel(), ("R_M", "R_HM"))
    assert values["R_M"][0] < 0.2 and values["R_HM"][0] < 0.3
    tri = model_of(_triangle(), fixed=())
    flat = np.zeros((3, 2))
    flat[2, 1] = -0.8 * tri.mesh.points[2, 1]
    h = 0.2 * np.sqrt(3) / 2                                # the same as a flat triangle at rest
    mean = (1 + 2 * np.hypot(0.5, h)) / 3
    assert criteria(tri, flat.ravel(), ("R_M",))["R_M"][0] == pytest.approx((h / 2) / (np.sqrt(3) / 4 * mean**2),
                                                                           rel=1e-12)


def test_criteria_errors():
    model = model_of(bar())
    with pytest.raises(TensormassError, match="unknown criterion 'R_X'"):
        criteria(model, np.zeros(model.n_dofs), ("R_X",))
    with pytest.raises(TensormassError, match="R_S needs the assembler"):
        criteria(model, np.zeros(model.n_dofs), ("R_S",))


# --------------------------------------------------------------------------- 2. switching keeps the state


def bending(points, c=0.1):
    """u_z = c x^2, u_x = -2 c x (z - H/2): the section rotates by about atan(2 c x)."""
    u = np.zeros_like(points)
    x, z = points[:, 0], points[:, 2]
    u[:, 2] = c * x**2
    u[:, 0] = -2 * c * x * (z - H / 2)
    return u.ravel()


def test_switching_keeps_the_state_pattern_and_masses():
    rule = Adapt(criterion="rotation", threshold=5.0, law="stvk")
    model = model_of(bar(cells=(8, 2, 2)), rules=[rule])
    ctx, adapter = Context(model), Adapter(model)
    u = bending(model.mesh.points)
    ctx.u = u.copy()
    ctx.v = np.random.default_rng(0).standard_normal(model.n_dofs)
    v, mass = ctx.v.copy(), model.mass.copy()
    indptr, indices = ctx.asm.pattern.indptr.copy(), ctx.asm.pattern.indices.copy()
    rotation = criteria(model, u, ("rotation",))["rotation"]
    W0 = ctx.asm.energy(u)
    group, (hooke, stvk) = group_parts(model)
    assert hooke.law == "hooke" and stvk.law == "stvk" and stvk.n_active == 0

    change = adapter.update(ctx, 1)

    switched = np.flatnonzero(group.current == 1)
    assert change and change.switched == switched.size and change.split == 0 and change.model is None
    assert 0 < switched.size < model.mesh.n_cells
    np.testing.assert_array_equal(hooke.cell_ids[switched], np.flatnonzero(rotation > 5.0))
    assert hooke.n_active + stvk.n_active == model.mesh.n_cells == model.n_elements
    # the state, the masses and the sparsity pattern are untouched
    np.testing.assert_array_equal(ctx.u, u)
    np.testing.assert_array_equal(ctx.v, v)
    np.testing.assert_array_equal(model.mass, mass)
    np.testing.assert_array_equal(ctx.asm.pattern.indptr, indptr)
    np.testing.assert_array_equal(ctx.asm.pattern.indices, indices)
    # the energy changes by exactly the law difference on the switched cells
    ue = u.reshape(-1, 3)[hooke.cells[switched]]
    k_h, D_h = fresh_constants(model, hooke, switched)
    k_s, D_s = fresh_constants(model, stvk, switched)
    jump = float(np.sum(k_s.energy(D_s, ue) - k_h.energy(D_h, ue)))
    assert abs(jump) > 1e-6 * W0                            # the laws do differ at this strain
    assert ctx.asm.energy(u) - W0 == pytest.approx(jump, rel=1e-9, abs=1e-12 * W0)
    # a second update at the same state changes nothing
    assert not adapter.update(ctx, 2)
    assert adapter.summary(model)["switched"] == switched.size


def test_simulation_switches_some_cells_and_ends_in_equilibrium():
    rules = rule_text(criterion="rotation", threshold=2.0, law="stvk")
    scene = tm.Scene.from_string(scene_text(E_=1e7, steps=2, rules=rules))
    sim = tm.Simulation(scene)
    summary = sim.run()
    n_cells = sim.model.mesh.n_cells
    adapt = summary.adapt
    assert adapt["rules"] == 1 and adapt["split"] == 0 and adapt["switched_back"] == 0
    assert 0 < adapt["switched"] < n_cells
    assert set(adapt["elements_per_law"]) == {"hooke", "stvk"}
    assert sum(adapt["elements_per_law"].values()) == n_cells == summary.n_elements
    assert adapt["elements_per_law"]["stvk"] == adapt["switched"]
    assert sum(e["count"] for e in adapt["events"] if e["action"] == "switch_law") == adapt["switched"]
    assert {(k["law"], k["elements"]) for k in summary.kernels} == {
        ("hooke", adapt["elements_per_law"]["hooke"]), ("stvk", adapt["elements_per_law"]["stvk"])}
    # cells switched are the rotated ones: those near the tip
    law = sim.model.cell_law()
    centres = sim.model.mesh.points[sim.model.mesh.blocks[0].cells].mean(axis=1)[:, 0]
    assert centres[law == 1].min() > centres[law == 0].max()
    # the last load step was re-solved with the adapted model
    ctx, model = sim.ctx, sim.model
    residual = (ctx.asm.forces(ctx.u) + model.f_ext)[model.free_dofs]
    assert np.abs(residual).max() < 1e-6 * np.abs(model.f_ext).max()
    plain = tm.Simulation(tm.Scene.from_string(scene_text(E_=1e7, steps=2))).run()
    assert summary.probes["tip"][2] == pytest.approx(plain.probes["tip"][2], rel=0.05)


def test_dynamic_run_with_switch_and_back():
    rules = rule_text(criterion="rotation", threshold=1.0, back=0.5, law="stvk")
    scene = tm.Scene.from_string(scene_text(cells=(6, 1, 1), E_=2e5, kind="implicit_euler", steps=6,
                                            rules=rules).replace("kind =", "dt = 0.05\nkind ="))
    summary = tm.Simulation(scene).run()
    assert summary.adapt["switched"] > 0
    assert sum(summary.adapt["elements_per_law"].values()) == 6
    assert np.all(np.isfinite(summary.probes["tip"]))


# --------------------------------------------------------------------------- 3. assembly with masks


def brute_force(model, u):
    """(W, f_int, dense K) by a Python loop over the active cells of every part, fresh kernels."""
    n, dim = model.n_dofs, model.dim
    W, f, K = 0.0, np.zeros(n), np.zeros((n, n))
    for part in model.parts:
        for e in np.flatnonzero(part.active):
            kernel, D = fresh_constants(model, part, np.array([e]))
            ue = u.reshape(-1, dim)[part.cells[e]][None]
            dofs = part.dofs[e]
            W += float(kernel.energy(D, ue)[0])
            f[dofs] += kernel.forces(D, ue)[0]
            K[np.ix_(dofs, dofs)] += kernel.stiffness(D, ue)[0]
    return W, f, K


@pytest.mark.parametrize("element, cells, split", [("hexahedron", (6, 1, 1), [0, 2, 5]),
                                                   ("triangle", (4, 2), [1, 2, 3, 8, 9, 15])])
def test_masked_assembly_equals_brute_force(element, cells, split):
    rule = Adapt(criterion="rotation", threshold=5.0, law="stvk")
    model = model_of(bar(element, cells), rules=[rule])
    asm = Assembler(model)
    group, (hooke, stvk) = group_parts(model)
    assert asm.constant[group.parts[0]] and not asm.constant[group.parts[1]]
    rng = np.random.default_rng(7)
    u = 0.02 * rng.standard_normal(model.n_dofs)
    for cells_to_stvk in ([], split, list(range(len(hooke.cells)))):
        group.switch(model, np.array(cells_to_stvk, dtype=np.int64), "stvk")
        asm.refresh()
        assert hooke.n_active == len(hooke.cells) - len(cells_to_stvk) and stvk.n_active == len(cells_to_stvk)
        W, f_ref, K_ref = brute_force(model, u)
        f, data = asm.forces_and_stiffness(u)
        scale_f, scale_K = np.abs(f_ref).max(), np.abs(K_ref).max()
        assert np.abs(f - f_ref).max() <= 1e-10 * scale_f
        assert np.abs(asm.matrix(data).toarray() - K_ref).max() <= 1e-10 * scale_K
        assert np.abs(asm.forces(u) - f_ref).max() <= 1e-10 * scale_f
        assert np.abs(asm.matrix(asm.stiffness(u)).toarray() - K_ref).max() <= 1e-10 * scale_K
        assert asm.energy(u) == pytest.approx(W, rel=1e-10)
    # and back again: every cell to hooke
    group.switch(model, np.arange(len(hooke.cells)), "hooke")
    asm.refresh()
    W, f_ref, _ = brute_force(model, u)
    assert np.abs(asm.forces(u) - f_ref).max() <= 1e-10 * np.abs(f_ref).max()
    assert asm.energy(u) == pytest.approx(W, rel=1e-10)


def test_constant_stiffness_equals_the_hooke_kernel(monkeypatch):
    model = model_of(bar(cells=(6, 1, 1)))
    asm = Assembler(model)
    assert asm.constant == [True]
    rng = np.random.default_rng(11)
    u = 0.05 * rng.standard_normal(model.n_dofs)
    W, f_ref, K_ref = brute_force(model, u)
    f, data = asm.forces_and_stiffness(u)
    assert np.abs(f - f_ref).max() <= 1e-10 * np.abs(f_ref).max()
    assert np.abs(asm.matrix(data).toarray() - K_ref).max() <= 1e-10 * np.abs(K_ref).max()
    assert asm.energy(u) == pytest.approx(W, rel=1e-10)
    # K is assembled once: later calls do not run the Hooke kernel at all
    kernel = model.parts[0].kernel

    def boom(*args, **kwargs):
        raise AssertionError("the Hooke kernel ran again")

    for name in ("energy", "forces", "stiffness", "forces_and_stiffness"):
        monkeypatch.setattr(kernel, name, boom)
    u2 = 0.05 * rng.standard_normal(model.n_dofs)
    f2, data2 = asm.forces_and_stiffness(u2)
    np.testing.assert_allclose(data2, data, rtol=0, atol=0)
    assert np.abs(f2 + asm.matrix(data) @ u2).max() <= 1e-12 * np.abs(f2).max()
    asm.forces(u2)
    asm.energy(u2)
    asm.stiffness(u2)


def test_explicit_scene_uses_the_kernel_and_switches():
    rules = rule_text(criterion="R_S", threshold=1e-6, law="stvk")
    scene = tm.Scene.from_string(scene_text(cells=(4, 1, 1), kind="explicit", steps=3,
                                            rules=rules).replace("kind =", "dt = 1e-4\nkind ="))
    sim = tm.Simulation(scene)
    summary = sim.run()
    assert sim.ctx.asm.constant == [False, False]            # no stiffness kernel for explicit
    assert summary.adapt["switched"] > 0 and summary.energy is not None     # energy: the health balance
    assert all(k["outputs"] == ["forces", "energy"] for k in summary.kernels)


# --------------------------------------------------------------------------- 4. hysteresis and rule options


def _adapter(mesh, *rules, law="hooke"):
    model = model_of(mesh, law, rules=rules)
    return model, Context(model), Adapter(model)


def test_hysteresis_switches_back_below_back():
    rule = Adapt(criterion="rotation", threshold=5.0, back=2.0, law="stvk")
    model, ctx, adapter = _adapter(bar(), rule)
    n = model.mesh.n_cells
    X = model.mesh.points
    ctx.u = rigid_rotation(X, 30.0)
    assert adapter.update(ctx, 1).switched == n
    assert np.all(model.cell_law() == 1)
    ctx.u = rigid_rotation(X, 3.0)                        # between back and threshold: no change
    assert not adapter.update(ctx, 2)
    assert np.all(model.cell_law() == 1)
    ctx.u = np.zeros(model.n_dofs)
    assert adapter.update(ctx, 3).switched == n
    assert np.all(model.cell_law() == 0)
    summary = adapter.summary(model)
    assert summary["switched"] == n and summary["switched_back"] == n
    assert [e["action"] for e in summary["events"]] == ["switch_law", "switch_back"]
    assert [e["law"] for e in summary["events"]] == ["stvk", "hooke"]
    assert [e["step"] for e in summary["events"]] == [1, 3]
    assert summary["elements_per_law"] == {"hooke": n, "stvk": 0}


def test_without_back_cells_stay_switched():
    model, ctx, adapter = _adapter(bar(), Adapt(criterion="rotation", threshold=5.0, law="stvk"))
    ctx.u = rigid_rotation(model.mesh.points, 30.0)
    adapter.update(ctx, 1)
    ctx.u = np.zeros(model.n_dofs)
    assert not adapter.update(ctx, 2)
    assert np.all(model.cell_law() == 1)


def test_hysteresis_per_cell():
    rule = Adapt(criterion="rotation", threshold=5.0, back=2.0, law="stvk")
    model, ctx, adapter = _adapter(bar(cells=(8, 2, 2)), rule)
    ctx.u = bending(model.mesh.points)
    up = adapter.update(ctx, 1).switched
    assert 0 < up < model.mesh.n_cells
    ctx.u = bending(model.mesh.points, c=0.01)             # all calm again (rotation < 1.5 deg)
    assert adapter.update(ctx, 2).switched == up
    assert np.all(model.cell_law() == 0)


def test_quality_rule_below_with_back():
    rule = Adapt(criterion="R_M", threshold=0.5, back=0.8, below=True, law="stvk")
    model, ctx, adapter = _adapter(_tetra(), rule)
    squash = np.zeros_like(model.mesh.points)
    squash[:, 2] = -0.9 * model.mesh.points[:, 2]
    ctx.u = squash.ravel()
    assert adapter.update(ctx, 1).switched == 1
    ctx.u = 0.7 * squash.ravel()                            # R_M between 0.5 and 0.8: stays
    assert 0.5 < criteria(model, ctx.u, ("R_M",))["R_M"][0] < 0.8
    assert not adapter.update(ctx, 2)
    ctx.u = np.zeros(model.n_dofs)
    assert adapter.update(ctx, 3).switched == 1 and model.cell_law()[0] == 0


def test_every_from_and_relative():
    rot = rigid_rotation(bar().points, 30.0)
    # every = 2: nothing happens at odd steps
    model, ctx, adapter = _adapter(bar(), Adapt(criterion="rotation", threshold=5.0, law="stvk", every=2))
    ctx.u = rot
    assert adapter.due(1) == [] and not adapter.update(ctx, 1)
    assert adapter.update(ctx, 2).switched == model.mesh.n_cells
    # from = "stvk" leaves hooke cells alone (and loads no other kernel)
    model, ctx, adapter = _adapter(bar(), Adapt(criterion="rotation", threshold=5.0, law="neohookean",
                                                from_law="stvk"))
    assert [p.law for p in model.parts] == ["hooke"] and model.groups == []
    ctx.u = rot
    assert not adapter.update(ctx, 1)
    # relative: a fraction of the largest value over the mesh
    rule = Adapt(criterion="rotation", threshold=0.7, relative=True, law="stvk")
    model, ctx, adapter = _adapter(bar(cells=(8, 2, 2)), rule)
    ctx.u = bending(model.mesh.points)
    rotation = criteria(model, ctx.u, ("rotation",))["rotation"]
    adapter.update(ctx, 1)
    np.testing.assert_array_equal(model.cell_law() == 1, rotation > 0.7 * rotation.max())


def test_chain_of_switches():
    rules = [Adapt(criterion="rotation", threshold=5.0, law="stvk", from_law="hooke"),
             Adapt(criterion="rotation", threshold=20.0, law="stable_neohookean", from_law="stvk")]
    model, ctx, adapter = _adapter(bar(), *rules)
    assert [p.law for p in model.parts] == ["hooke", "stvk", "stable_neohookean"]
    assert len(model.groups) == 1 and model.groups[0].laws == ["hooke", "stvk", "stable_neohookean"]
    ctx.u = rigid_rotation(model.mesh.points, 30.0)
    assert adapter.update(ctx, 1).switched == 6             # one move per cell and update
    assert np.all(model.cell_law() == 2)                    # sorted names: hooke, stable_neohookean, stvk
    assert adapter.update(ctx, 2).switched == 6
    assert np.all(model.cell_law() == 1)
    assert model.n_elements == 6 and [k["elements"] for k in model.kernel_info()] == [0, 0, 6]


def test_change_truthiness():
    assert not Change() and Change(switched=1) and Change(split=2)


# --------------------------------------------------------------------------- 5. reachable kernels


def _required(rules, law="hooke", element="hexahedron", cells=(4, 1, 1), quadrature="gauss2"):
    return Model.required_kernels(tm.Scene.from_string(
        scene_text(element, cells, law=law, quadrature=quadrature, rules=rules)))


def test_required_kernels_follow_the_rules(monkeypatch):
    out = ("energy", "forces", "stiffness")
    assert _required("") == {("hexahedron", "hooke", "gauss2", out)}
    switch = rule_text(criterion="rotation", threshold=5.0, law="stvk")
    assert _required(switch) == {("hexahedron", "hooke", "gauss2", out), ("hexahedron", "stvk", "gauss2", out)}
    chain = switch + rule_text(criterion="rotation", threshold=20.0, law="stable_neohookean", from_="stvk")
    assert {k[1] for k in _required(chain)} == {"hooke", "stvk", "stable_neohookean"}
    # rule order does not matter: reachability is transitive
    reverse = (rule_text(criterion="rotation", threshold=20.0, law="stable_neohookean", from_="stvk")
               + rule_text(criterion="rotation", threshold=5.0, law="stvk", from_="hooke"))
    assert {k[1] for k in _required(reverse)} == {"hooke", "stvk", "stable_neohookean"}
    unreachable = rule_text(criterion="rotation", threshold=5.0, law="stvk", from_="neohookean")
    assert {k[1] for k in _required(unreachable)} == {"hooke"}
    refine = rule_text(criterion="R_S", threshold=0.5, relative=True, action="refine")
    assert _required(refine, element="tetra", quadrature="gauss1") == {("tetra", "hooke", "gauss1", out)}
    # the model loads exactly those kernels
    loaded = []
    real = kernels_module.load_kernel

    def spy(*args, **kwargs):
        loaded.append(args[:3])
        return real(*args, **kwargs)

    monkeypatch.setattr(kernels_module, "load_kernel", spy)
    Model.from_scene(tm.Scene.from_string(scene_text(cells=(4, 1, 1), rules=chain)))
    assert sorted(loaded) == sorted(("hexahedron", law, "gauss2") for law in ("hooke", "stvk", "stable_neohookean"))


# --------------------------------------------------------------------------- 6. refinement


REFINE = rule_text(criterion="R_S", relative=True, threshold=0.9, action="refine", rounds=2)


@pytest.mark.parametrize("element, cells", [("triangle", (24, 4)), ("tetra", (8, 2, 2))])
def test_refinement_keeps_the_mesh_conforming(element, cells):
    quadrature = "gauss1" if element == "tetra" else "gauss2"      # kernels other tests compile too
    plain_scene = tm.Scene.from_string(scene_text(element, cells, quadrature=quadrature))
    plain = tm.Simulation(plain_scene)
    before = plain.run()
    sim = tm.Simulation(tm.Scene.from_string(scene_text(element, cells, quadrature=quadrature, rules=REFINE)))
    summary = sim.run()
    mesh = sim.model.mesh
    check_mesh(mesh)
    assert summary.adapt["split"] > 0 and summary.adapt["switched"] == 0
    refines = [e for e in summary.adapt["events"] if e["action"] == "refine"]
    assert 1 <= len(refines) <= 2 and refines[-1]["cells"] == mesh.n_cells
    assert mesh.n_cells > plain.model.mesh.n_cells
    assert summary.n_elements == mesh.n_cells == summary.adapt["elements_per_law"]["hooke"]
    assert mesh.n_points > plain.model.mesh.n_points and sim.model.n_dofs == mesh.n_points * mesh.dim
    assert sim.model.mass.sum() == pytest.approx(plain.model.mass.sum(), rel=1e-12)
    w0, w1 = -before.probes["tip"][-1], -summary.probes["tip"][-1]
    assert np.isfinite(w1) and w1 > 0 and abs(w1 - w0) < 0.2 * w0
    # the answer is the equilibrium of the refined mesh (the last load step was re-solved)
    fresh = tm.Simulation(Model.from_scene(plain_scene, mesh=mesh)).run()
    np.testing.assert_allclose(summary.probes["tip"], fresh.probes["tip"], rtol=1e-6, atol=1e-9 * w0)
    # constraints were rebuilt: new nodes on the clamp are fixed too
    clamped = np.flatnonzero(mesh.points[:, 0] <= 1e-12)
    assert np.all(np.isin(clamped * mesh.dim, sim.model.fixed_dofs))
    assert np.abs(sim.displacement[clamped]).max() == 0.0


def test_refinement_keeps_switched_laws():
    rules = (Adapt(criterion="rotation", threshold=5.0, law="stvk"),
             Adapt(criterion="rotation", threshold=5.0, action="refine"))
    mesh = bar("triangle", (6, 2))
    model, ctx, adapter = _adapter(mesh, *rules)
    ctx.u = bending_2d(mesh.points)
    rotation = criteria(model, ctx.u, ("rotation",))["rotation"]
    change = adapter.update(ctx, 1)
    assert change.switched > 0 and change.split > 0 and change.model is not None
    new = change.model
    check_mesh(new.mesh)
    assert new.mesh.n_cells > mesh.n_cells
    # children carry their parent's law
    law_before = model.cell_law()
    from tensormass.runtime.mesh.refine import refine
    parent = refine(mesh, rotation > 5.0, propagate=True).cell_parent
    np.testing.assert_array_equal(new.cell_law(), law_before[parent])
    assert sum(p.n_active for p in new.parts) == new.mesh.n_cells
    # no more rounds: the refine rule is spent
    assert adapter.due(2) == [0]


def bending_2d(points, c=0.1):
    u = np.zeros_like(points)
    x, y = points[:, 0], points[:, 1]
    u[:, 1] = c * x**2
    u[:, 0] = -2 * c * x * (y - H / 2)
    return u.ravel()


def test_hysteresis_survives_refinement():
    rules = (Adapt(criterion="rotation", threshold=5.0, back=2.0, law="stvk"),
             Adapt(criterion="rotation", threshold=5.0, action="refine"))
    mesh = bar("triangle", (6, 2))
    model, ctx, adapter = _adapter(mesh, *rules)
    ctx.u = rigid_rotation(mesh.points, 30.0)
    change = adapter.update(ctx, 1)
    assert change.switched == mesh.n_cells and change.model is not None
    new = change.model
    assert np.all(new.cell_law() == 1)
    ctx2 = Context(new)                                   # at rest: the criterion is below `back`
    assert adapter.update(ctx2, 2).switched == new.mesh.n_cells
    assert np.all(new.cell_law() == 0)


# --------------------------------------------------------------------------- 7. output


def test_vtu_frames_carry_the_criteria_and_grow(tmp_path):
    rules = (rule_text(criterion="rotation", threshold=0.3, law="stvk")
             + rule_text(criterion="R_S", relative=True, threshold=0.9, action="refine", rounds=2))
    scene = tm.Scene.from_string(scene_text("triangle", (12, 2), steps=2, rules=rules,
                                            extra="[output]\nevery = 1"))
    out = tmp_path / "out"
    data = run_scene(scene, out=out, quiet=True)
    assert data["output"]["frames"] == 3
    assert data["adapt"]["split"] > 0 and data["adapt"]["switched"] > 0
    frames = [meshio.read(out / f"frame_{k:06d}.vtu") for k in range(3)]
    n_cells = [sum(len(c.data) for c in f.cells) for f in frames]
    assert n_cells[0] == 48 and n_cells[2] > n_cells[0]
    for frame, n in zip(frames, n_cells):
        assert set(CRITERIA) | {"law_id"} <= set(frame.cell_data)
        for name in set(CRITERIA) | {"law_id"}:
            values = np.concatenate(frame.cell_data[name])
            assert values.shape == (n,) and np.all(np.isfinite(values))
        assert frame.point_data["displacement"].shape == (len(frame.points), 3)
    law_id = np.concatenate(frames[2].cell_data["law_id"])
    assert set(np.unique(law_id)) <= {0.0, 1.0}
    assert int((law_id == 1).sum()) == data["adapt"]["elements_per_law"]["stvk"] > 0
    assert np.all(np.concatenate(frames[0].cell_data["law_id"]) == 0)
    rotation = np.concatenate(frames[0].cell_data["rotation"])
    assert np.all(rotation == 0)                           # frame 0: at rest


# --------------------------------------------------------------------------- 8. scene errors


BASE = {
    "mesh": {"generate": "bar", "size": [1.2, 0.2, 0.2], "cells": [4, 1, 1], "element": "hexahedron"},
    "material": [{"law": "hooke", "quadrature": "gauss2", "E": 1e6, "nu": 0.3, "density": 800.0}],
    "fixed": [{"box": [[-1, -1, -1], [0, 1, 1]]}],
    "adapt": [{"criterion": "rotation", "threshold": 5.0, "law": "stvk"}],
}
TETRA = dict(BASE, mesh=dict(BASE["mesh"], element="tetra"),
             material=[dict(BASE["material"][0], quadrature="gauss1")])


def with_rule(base=BASE, index=0, drop=(), **keys):
    data = copy.deepcopy(base)
    rule = data["adapt"][index]
    for k in drop:
        rule.pop(k)
    rule.update({("from" if k == "from_" else k): v for k, v in keys.items()})
    return data


def test_valid_rules_parse():
    scene = tm.Scene.from_dict(with_rule(from_="hooke", back=2.0, every=3, relative=False))
    (rule,) = scene.adapt
    assert (rule.criterion, rule.threshold, rule.action, rule.law, rule.from_law, rule.back, rule.every) == (
        "rotation", 5.0, "switch_law", "stvk", "hooke", 2.0, 3)
    refine = tm.Scene.from_dict(with_rule(TETRA, drop=("law",), criterion="R_S", threshold=0.9, relative=True,
                                          action="refine", rounds=2))
    assert refine.adapt[0].rounds == 2 and refine.adapt[0].relative
    below = tm.Scene.from_dict(with_rule(criterion="R_M", threshold=0.3, back=0.5, below=True))
    assert below.adapt[0].below and below.adapt[0].back == 0.5
    assert tm.Scene.from_dict(with_rule(threshold=5)).adapt[0].threshold == 5.0


ERRORS = [
    (with_rule(criterion="R_X"),
     r"^adapt\[0\]\.criterion: unknown value 'R_X'; allowed: R_L, R_A, R_M, R_HM, R_S, rotation"),
    (with_rule(drop=("threshold",)), r"^adapt\[0\]\.threshold: missing"),
    (with_rule(drop=("criterion",)), r"^adapt\[0\]\.criterion: missing"),
    (with_rule(threshold="5"), r"^adapt\[0\]\.threshold: expected a number"),
    (with_rule(threshold=-1.0), r"^adapt\[0\]\.threshold: must be >= 0"),
    (with_rule(drop=("law",)), r"^adapt\[0\]\.law: missing"),
    (with_rule(law="rubber"), r"^adapt\[0\]\.law: unknown law 'rubber'; known: cst_dkt, hgo, hgo2, hooke"),
    (with_rule(from_="rubber"), r"^adapt\[0\]\.from: unknown law 'rubber'"),
    (with_rule(from_="stvk"), r"^adapt\[0\]\.from: same law as adapt\[0\]\.law \('stvk'\)"),
    (with_rule(back=5.0), r"^adapt\[0\]\.back: must be below the threshold 5 \(got 5\)"),
    (with_rule(back=7.0), r"^adapt\[0\]\.back: must be below the threshold 5"),
    (with_rule(criterion="R_M", threshold=0.5, back=0.3, below=True),
     r"^adapt\[0\]\.back: must be above the threshold 0.5"),
    (with_rule(rounds=2), r"^adapt\[0\]\.rounds: only used with action = \"refine\""),
    (with_rule(drop=("law",), action="refine"),
     r"^adapt\[0\]\.action: refine splits triangle and tetra cells only; the mesh has hexahedron"),
    (with_rule(TETRA, action="refine"), r"^adapt\[0\]\.law: only used with action = \"switch_law\""),
    (with_rule(TETRA, drop=("law",), action="refine", back=1.0), r"^adapt\[0\]\.back: only used with"),
    (with_rule(action="coarsen"), r"^adapt\[0\]\.action: unknown value 'coarsen'; allowed: switch_law, refine"),
    (with_rule(relative=True, threshold=1.5), r"^adapt\[0\]\.threshold: a relative threshold is a fraction"),
    (with_rule(relative=1), r"^adapt\[0\]\.relative: expected true or false"),
    (with_rule(every=0), r"^adapt\[0\]\.every: must be >= 1"),
    (with_rule(TETRA, drop=("law",), action="refine", rounds=0), r"^adapt\[0\]\.rounds: must be >= 1"),
    (with_rule(colour="red"), r"^adapt\[0\]\.colour: unknown key; allowed keys in \[adapt\]: criterion, threshold"),
    (dict(BASE, adapt=[BASE["adapt"][0], {"criterion": "R_L", "threshold": 0.1}]), r"^adapt\[1\]\.law: missing"),
    (dict(BASE, adapt=["rotation"]), r"^adapt: expected an array of tables"),
    # checks against the mesh: the target kernel must exist, and the parameters must carry over
    (with_rule(dict(TETRA, material=[dict(TETRA["material"][0], quadrature="exact")]), law="neohookean"),
     r"^adapt\[0\]\.law: quadrature 'exact' is not available for tetra with law 'neohookean'"),
    (with_rule(dict(BASE, material=[{"law": "hooke", "mu": 1e6, "lam": 1e6}]), law="mooney_rivlin"),
     r"^adapt\[0\]\.law: .*no E, nu"),
]


@pytest.mark.parametrize("data, pattern", ERRORS, ids=[f"case{i}" for i in range(len(ERRORS))])
def test_adapt_errors_name_the_key(data, pattern):
    with pytest.raises(SceneError, match=pattern):
        tm.Scene.from_dict(copy.deepcopy(data))


def test_native_parameters_carry_over_to_a_law_with_the_same_names():
    scene = tm.Scene.from_dict(with_rule(dict(BASE, material=[{"law": "hooke", "mu": 1e6, "lam": 1e6}])))
    model = Model.from_scene(scene)
    assert [p.law for p in model.parts] == ["hooke", "stvk"]


def test_transitively_reached_law_is_checked():
    data = copy.deepcopy(TETRA)
    data["material"][0]["quadrature"] = "exact"
    data["adapt"] = [{"criterion": "rotation", "threshold": 5.0, "law": "stvk", "from": "hooke"},
                     {"criterion": "rotation", "threshold": 10.0, "law": "neohookean", "from": "stvk"}]
    with pytest.raises(SceneError, match=r"^adapt\[1\]\.law: quadrature 'exact' is not available"):
        tm.Scene.from_dict(data)


# --------------------------------------------------------------------------- 9. quadratic laws


def test_only_hooke_is_quadratic():
    assert {name: laws.is_quadratic(name) for name in laws.names()} == {
        name: name == "hooke" for name in laws.names()}
    assert "hooke" in laws.names() and len(laws.names()) >= 5
