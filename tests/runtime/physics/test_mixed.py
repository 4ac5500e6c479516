"""The mixed u-p formulation (runtime.assembly.mixed, runtime.physics.saddle): the saddle system is
the derivative of the Lagrangian, constant pressures pass the patch test, nu = 0.5 meets the
incompressible closed form, runs converge to it as nu -> 0.5, and the scene refuses what it cannot run."""
from __future__ import annotations

import numpy as np
import pytest

from tensormass.runtime.assembly.assembly import Assembler
from tensormass.runtime.assembly.mixed import MINI_TAU, MixedCoupling
from tensormass.runtime.base.errors import SceneError
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.mesh.container import CellBlock, Mesh
from tensormass.runtime.mesh.uniform import to_quadratic
from tensormass.runtime.model.model import Model
from tensormass.runtime.physics.saddle import Pressures
from tensormass.runtime.run.simulation import Simulation
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.scene.types import Material, Solver

# (element, quadrature): the kernels the locking-free formulations' quick tests compile anyway
ELEMENTS = [("tetra", "gauss1"), ("tetra10", "gauss2"), ("hexahedron", "gauss2")]


def _model(element, quadrature, nu=0.45, law="neohookean", seed=0):
    linear = "tetra" if element == "tetra10" else element
    mesh = generate_bar((1.0, 0.8, 0.6), (2, 2, 2), linear)
    pts = mesh.points.copy()
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    inner = np.all((pts > lo + 1e-9) & (pts < hi - 1e-9), axis=1)
    pts[inner] += 0.04 * np.random.default_rng(seed).standard_normal((inner.sum(), 3))
    mesh = Mesh(pts, [CellBlock(b.type, b.cells) for b in mesh.blocks])
    if linear != element:
        mesh = to_quadratic(mesh)
    model = Model(mesh, [Material(law=law, quadrature=quadrature, E=1.0, nu=nu, formulation="mixed")])
    pts = mesh.points
    return model, Assembler(model), np.all((pts > lo + 1e-9) & (pts < hi - 1e-9), axis=1)


def _residual(asm, P, u, p):
    """(dL/du, dL/dp) at (u, p)."""
    P.set(p)
    return -asm.forces(u), P.residual(u)


# laws beyond neo-Hookean on kernels the quick suite compiles anyway (stable neo-Hookean: nodal pressure's)
CASES = [(e, q, "neohookean", 0.45) for e, q in ELEMENTS] + [
    ("tetra", "gauss1", "neohookean", 0.5)] + [("tetra", "gauss1", "stable_neohookean", nu) for nu in (0.45, 0.5)] + [
    # each other law's split (bulk parameter kappa or lam, measures det F, 1 + tr eps, 1 + tr E): CI's heavy step
    pytest.param("tetra", "gauss1", law, 0.5, marks=pytest.mark.heavy) for law in ("mooney_rivlin", "hooke", "stvk")]


@pytest.mark.parametrize("element,quadrature,law,nu", CASES)
def test_the_saddle_matrix_is_the_derivative_of_the_lagrangian(element, quadrature, law, nu):
    model, asm, _ = _model(element, quadrature, nu=nu, law=law)
    (c,) = model.couplings
    assert isinstance(c, MixedCoupling)
    P = Pressures(model, model.couplings)
    rng = np.random.default_rng(1)
    u = 0.02 * rng.standard_normal(model.n_dofs)
    p = 0.3 * rng.standard_normal(P.n)
    P.set(p)
    K = asm.matrix(asm.stiffness(u)).toarray()
    B = P.constraint_matrix(u).toarray()
    C = P.C.toarray()
    assert np.abs(K - K.T).max() <= 1e-12 * np.abs(K).max()
    assert np.abs(C - C.T).max() <= 1e-14 * np.abs(C).max() and np.linalg.eigvalsh(C).min() > -1e-14 * np.abs(C).max()
    d, q, h = rng.standard_normal(u.size), rng.standard_normal(P.n), 1e-6
    gp, rp = _residual(asm, P, u + h * d, p + h * q)
    gm, rm = _residual(asm, P, u - h * d, p - h * q)
    dg, dr = (gp - gm) / (2 * h), (rp - rm) / (2 * h)
    assert np.abs(dg - (K @ d + B.T @ q)).max() <= 1e-6 * np.abs(dg).max()
    assert np.abs(dr - (B @ d - C @ q)).max() <= 1e-6 * np.abs(dr).max()
    # and the residuals are the Lagrangian's gradient: dL along (d, q)
    P.set(p + h * q)
    Lp = asm.energy(u + h * d)
    P.set(p - h * q)
    Lm = asm.energy(u - h * d)
    g, r = _residual(asm, P, u, p)
    assert (Lp - Lm) / (2 * h) == pytest.approx(g @ d + r @ q, rel=1e-6)


@pytest.mark.parametrize("element,quadrature", ELEMENTS)
def test_a_constant_pressure_under_a_homogeneous_deformation_leaves_interior_nodes_in_equilibrium(element, quadrature):
    model, asm, inner = _model(element, quadrature)
    P = Pressures(model, model.couplings)
    pts = model.mesh.points
    A = np.eye(3) + 0.05 * np.random.default_rng(3).standard_normal((3, 3))
    u = (pts @ A.T - pts).ravel()
    P.set(np.full(P.n, 0.7))
    f = asm.forces(u).reshape(-1, 3)
    assert inner.any()
    assert np.abs(f[inner]).max() <= 1e-12 * np.abs(f).max()
    # every group's volume ratio is det A
    assert np.allclose(P.couplings[0].volume_ratio(u.reshape(-1, 3)), np.linalg.det(A), rtol=1e-12)


def test_the_mini_stabilisation_is_the_condensed_bubble():
    """tau of a regular tetrahedron from the bubble 256 l1 l2 l3 l4 integrated numerically."""
    X = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    Ginv = np.linalg.inv(np.column_stack([X[1] - X[0], X[2] - X[0], X[3] - X[0]]))
    grads = np.vstack([-Ginv.sum(axis=0), Ginv])                      # grad l_a, rows
    rng = np.random.default_rng(0)
    lam = rng.dirichlet(np.ones(4), 400_000)                          # uniform points of the tetrahedron
    b = 256 * lam.prod(axis=1)
    grad_b = 256 * sum(np.prod(np.delete(lam, i, axis=1), axis=1)[:, None] * grads[i] for i in range(4))
    V = 1.0 / 6.0
    int_b, int_grad2 = V * b.mean(), V * (grad_b ** 2).sum(axis=1).mean()
    tau = int_b ** 2 / (V * int_grad2)                                  # mu = 1
    assert tau * (grads ** 2).sum() == pytest.approx(MINI_TAU, rel=2e-3)
    # and the pressure block the model assembles on that tetrahedron (E = 3, nu = 0.5: mu = 1)
    model = Model(Mesh(X, [CellBlock("tetra", np.array([[0, 1, 2, 3]]))]),
                  [Material(law="neohookean", quadrature="gauss1", E=3.0, nu=0.5, formulation="mixed")])
    assert np.allclose(model.couplings[0].C.toarray(), tau * V * grads @ grads.T, rtol=3e-3, atol=0)


UNIAXIAL = """
[mesh]
generate = "bar"
size = [1.0, 1.0, 1.0]
cells = [{n}, {n}, {n}]
element = "{element}"

[[material]]
law = "neohookean"
E = 3000.0
nu = {nu}
quadrature = "{quadrature}"
formulation = "mixed"
""" + "".join(f"""
[[fixed]]
box = {[[-1] * a + [-0.01] + [-1] * (2 - a), [2] * a + [0.01] + [2] * (2 - a)]}
components = [{a}]
""" for a in range(3)) + """
[[fixed]]
name = "top"
box = [[-1, -1, 0.99], [2, 2, 1.01]]
components = [2]
displacement = [0, 0, {stretch_minus_one}]

[solver]
kind = "static"
steps = 3
"""


@pytest.mark.parametrize("element,quadrature", ELEMENTS)
def test_incompressible_uniaxial_tension_meets_the_closed_form(element, quadrature):
    """nu = 0.5: P = mu (l - 1/l^2), mu = E / 3, and every pressure group keeps its volume."""
    stretch = 1.5
    text = UNIAXIAL.format(n=1, element=element, nu=0.5, quadrature=quadrature, stretch_minus_one=stretch - 1)
    sim = Simulation(Scene.from_string(text))
    assert sim.run().status == "ok"
    force = sim.reactions()["top"]["force"][2]
    assert force == pytest.approx(1000.0 * (stretch - stretch ** -2), rel=1e-8)
    assert sim.ctx.pressures.volume_error(sim.ctx.u) < 1e-8          # solver.newton_tolerance


def test_runs_converge_to_the_incompressible_one_as_nu_goes_to_one_half():
    """A tetra cantilever bent by gravity: |u(nu) - u(0.5)| falls tenfold per decade of 0.5 - nu."""
    text = """
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [6, 2, 2]
element = "tetra"
[[material]]
law = "neohookean"
E = 1e5
nu = {nu}
density = 100.0
quadrature = "gauss1"
formulation = "mixed"
[[fixed]]
box = [[-0.01, -1, -1], [0.01, 1, 1]]
[loads]
gravity = [0, 0, -9.81]
[probe]
name = "tip"
point = [1.0, 0.1, 0.1]
[solver]
kind = "static"
steps = 1
"""
    tips = {}
    for nu in (0.499, 0.4999, 0.49999, 0.5):
        sim = Simulation(Scene.from_string(text.format(nu=nu)))
        assert sim.run().status == "ok"
        tips[nu] = sim.probes()["tip"][2]
    gaps = [abs(tips[nu] - tips[0.5]) for nu in (0.499, 0.4999, 0.49999)]
    assert tips[0.5] < 0
    assert all(8 < a / b < 12 for a, b in zip(gaps, gaps[1:]))
    assert gaps[0] < 0.01 * abs(tips[0.5])


DROP = """
[mesh]
generate = "bar"
size = [0.1, 0.02, 0.02]
cells = [5, 1, 1]
element = "tetra"
[[material]]
law = "neohookean"
E = 5000.0
nu = 0.5
quadrature = "gauss1"
formulation = "mixed"
[[fixed]]
box = [[-0.001, -1, -1], [0.001, 1, 1]]
[loads]
gravity = [0, 0, -9.81]
[solver]
kind = "{kind}"
dt = 0.01
steps = 5
"""


@pytest.mark.parametrize("kind,bound", [("backward_euler", 1e-8), ("implicit_euler", 1e-2)])
def test_dynamic_steps_keep_the_volume(kind, bound):
    """Backward Euler solves the constraint at every step; the linearly implicit step holds it to
    first order (its next step corrects what the last one left).  On tetra the body's volume is
    kept: the stabilisation moves volume between the pressure groups, not in or out."""
    sim = Simulation(Scene.from_string(DROP.format(kind=kind)))
    assert sim.run().status == "ok"
    assert np.abs(sim.ctx.u).max() > 1e-3
    assert sim.ctx.pressures.volume_change(sim.ctx.u) < bound


@pytest.mark.parametrize("change, message", [
    (('formulation = "mixed"', 'formulation = "displacement"'),
     r"^material\[0\]\.nu: Poisson's ratio must be < 0.5 \(got 0.5\) with this formulation; nu = 0.5 "
     r"\(incompressible\) needs formulation = \"mixed\""),
    (('kind = "{kind}"', 'kind = "explicit"'), r"^material\[0\]\.formulation: \"mixed\" \(pressure unknowns\) runs "
                                              r"with kind = \"static\""),
    (('kind = "{kind}"', 'kind = "implicit_euler"\nmode = "interactive"'),
     r"^material\[0\]\.formulation: \"mixed\" solves every step exactly"),
    (('kind = "{kind}"', 'kind = "static"\nlinear = "cg"'), r"^material\[0\]\.formulation: \"mixed\" solves its "
                                                            r"symmetric indefinite"),
    (('element = "tetra"', 'element = "wedge"'), r"material\[0\]\.formulation: wedge: mixed does not apply"),
    (("nu = 0.5", "nu = 0.6"), r"^material\[0\]\.nu: Poisson's ratio must be <= 0.5 \(got 0.6\)"),
])
def test_scene_errors(change, message):
    text = DROP.replace(*change).format(kind="static")
    with pytest.raises(SceneError, match=message):
        Scene.from_string(text)


@pytest.mark.heavy           # compiles two numba kernel modules cold: CI's heavy step runs it
def test_c_and_numba_give_the_same_saddle_system():
    systems = []
    for backend in ("c", "numba"):
        mesh = generate_bar((1.0, 0.8, 0.6), (2, 1, 1), "tetra")
        model = Model(mesh, [Material(law="neohookean", quadrature="gauss1", E=1.0, nu=0.5, formulation="mixed")],
                      solver=Solver(backend=backend))
        asm, P = Assembler(model), Pressures(model, model.couplings)
        rng = np.random.default_rng(4)
        u = 0.02 * rng.standard_normal(model.n_dofs)
        P.set(rng.standard_normal(P.n))
        systems.append((asm.forces(u), asm.matrix(asm.stiffness(u)).toarray(), P.residual(u),
                        P.constraint_matrix(u).toarray()))
    for a, b in zip(*systems):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-14 * np.abs(a).max())


def test_a_saddle_solve_pardiso_leaves_inaccurate_goes_to_superlu(monkeypatch):
    """Pressure pivots PARDISO perturbs can leave a residual refinement does not repair (Q1-P0 at
    nu = 0.5 did): the residual is checked and SuperLU solves instead."""
    import scipy.sparse as sp
    from tensormass.runtime.physics import saddle
    K = sp.diags([4.0, 5.0, 6.0]) + sp.csr_matrix(np.full((3, 3), 0.5))
    B = sp.csr_matrix([[1.0, -1.0, 0.0]])
    A = sp.bmat([[K, B.T], [B, None]], format="csr")
    rhs = np.array([1.0, 2.0, 3.0, 0.25])
    calls = []
    accurate = saddle._accurate
    monkeypatch.setattr(saddle, "_accurate", lambda *a: calls.append(len(a)) or (len(calls) > 1 and accurate(*a)))
    x, method = saddle._factor_solve(A, rhs, 3)
    assert method == "superlu-saddle"
    assert np.allclose(A @ x, rhs, rtol=0, atol=1e-12)
    assert len(calls) == (2 if saddle.pardiso.available() else 1)


def test_the_incompressible_press_example_keeps_its_volume(tmp_path, capsys):
    """examples/tissue/incompressible_press.toml through the CLI: the block bulges, keeps its volume,
    and the summary says so."""
    import json
    from pathlib import Path
    from tensormass.apps.cli import main
    example = Path(__file__).resolve().parents[3] / "examples" / "tissue" / "incompressible_press.toml"
    out = tmp_path / "summary.json"
    assert main(["run", str(example), "--json", str(out), "--out", str(tmp_path / "frames")]) == 0
    assert "incompressible   P2-P1 (Taylor-Hood)" in capsys.readouterr().out
    summary = json.loads(out.read_text())
    info = summary["incompressible"]
    assert info["volume_change"] < 1e-8 and info["group_volume_error"] < 1e-8
    assert summary["probes"]["side"][0] > 1e-3                 # the free side bulges out


def test_an_incompressible_viscous_cube_relaxes_like_the_prony_closed_form():
    """nu = 0.5 with Prony branches: the volumetric part is a constraint, so uniaxial stress is all
    deviatoric and relaxes as E (1 + sum beta exp(-t / tau)); normalised by the elastic mixed run."""
    from test_viscous import BRANCHES, E, NU, PULL, cube_text, relaxation
    text = lambda viscous: cube_text(viscous, PULL, steps=20).replace(f"nu = {NU}", 'nu = 0.5\nformulation = "mixed"')
    runs = []
    for viscous in (BRANCHES, ()):
        sim = Simulation(Scene.from_string(text(viscous)))
        summary = sim.run()
        assert summary.status == "ok" and sim.ctx.pressures is not None
        runs.append((np.array(summary.per_step["time"]), np.array(summary.per_step["reactions"]["pulled"]["force"])[:, 0]))
    (t, F), (_, F_elastic) = runs
    expected = np.array([relaxation(x) for x in t]) / (E * 1e-3)
    assert np.abs(F / F_elastic[-1] / expected - 1).max() < 3e-3


@pytest.mark.parametrize("quadrature", ["gauss2"] + [pytest.param(q, marks=pytest.mark.heavy) for q in ("gauss1", "gauss3")])
def test_the_pressure_shapes_at_the_points_are_the_rules_barycentric_coordinates(quadrature):
    """tetra10: read from the kernel's shape gradients, they equal the rule's (generator.quadrature)."""
    from tensormass.generator.quadrature import rule
    from tensormass.runtime.assembly.mixed import pressure_shapes
    from tensormass.runtime.kernels.kernels import load_kernel
    points = np.array([[float(c) for c in p] for p in rule("tetra10", quadrature).points])
    expected = np.vstack([1.0 - points.sum(axis=1), points.T])
    assert np.allclose(pressure_shapes(load_kernel("tetra10", "measure_volume", quadrature)), expected,
                       rtol=0, atol=1e-14)
