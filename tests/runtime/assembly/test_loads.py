"""Consistent loads and masses (runtime/assembly/loads.py, runtime/assembly/mass.py) and the generated shape tables.

References are computed here independently: closed-form simplex shape functions in numpy and
Gauss rules from numpy.polynomial.legendre, never the tables under test.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tensormass import elements
from tensormass.generator import shape_tables
from tensormass.runtime.assembly import loads
from tensormass.runtime.assembly.mass import element_mass, lump
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.model.model import Model
from tensormass.runtime.scene.types import Fixed, Loads, Material, NodalLoad, Solver

RNG = np.random.default_rng(12)


# shape tables exist for the solid types (a shell has its kernel's measure: elements/shell.py)
SOLIDS = tuple(n for n in elements.builtin() if elements.get(n).solid)

def _affine(name, seed=0):
    """Node coordinates of the reference element of `name` under a random affine map, and |det A|."""
    t = shape_tables.type_of(name)
    ref = np.array([[float(c) for c in p] for p in t.nodes])
    r = t.dim
    rng = np.random.default_rng(seed)
    A = np.eye(r) + 0.3 * rng.standard_normal((r, r))
    if np.linalg.det(A) < 0:
        A[:, 0] *= -1
    return ref @ A.T + rng.standard_normal(r), abs(np.linalg.det(A)), float(t.reference_measure)


# --------------------------------------------------------------------------- tables


COMMITTED_TABLES = Path(loads.__file__).resolve().parents[2] / "generated" / shape_tables.FILE


@pytest.mark.heavy
def test_committed_tables_are_the_generated_ones():
    # 3 s of sympy: the quick suite checks the same bytes through `tensormass generate`
    # (tests/generator/test_shape_tables.py::test_generate_writes_the_tables)
    assert COMMITTED_TABLES.read_text() == shape_tables.render()        # byte-identical, deterministic


def test_committed_tables_hold_every_solid_and_face_type():
    data = json.loads(COMMITTED_TABLES.read_text())
    for name in SOLIDS:
        assert name in data["types"]
        for f in elements.get(name).faces:
            assert f.type in data["types"]


@pytest.mark.parametrize("name", sorted(set(SOLIDS) | set(shape_tables.face_types())))
def test_tables_partition_of_unity_and_weights(name):
    t = loads.shape_table(name)
    np.testing.assert_allclose(t.N.sum(axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(t.dN.sum(axis=1), 0.0, atol=1e-13)
    assert t.weights.sum() == pytest.approx(float(shape_tables.type_of(name).reference_measure), rel=1e-14)


# --------------------------------------------------------------------------- sums = totals


@pytest.mark.parametrize("name", SOLIDS)
def test_body_shares_sum_to_the_volume(name):
    X, det, measure = _affine(name, 3)
    shares = loads.volume_shares(X, name, np.arange(len(X))[None])
    assert shares.sum() == pytest.approx(det * measure, rel=1e-13)


@pytest.mark.parametrize("name", shape_tables.face_types())
def test_face_shares_sum_to_the_area(name):
    """A face mapped into the space one dimension up: sum of int N_a dA = the area."""
    X, det, measure = _affine(name, 5)
    r = X.shape[1]
    Q, _ = np.linalg.qr(RNG.standard_normal((r + 1, r + 1)))
    x = X @ Q[:, :r].T                                 # isometric embedding: the area is kept
    shares = loads.face_shares(x, name, np.arange(len(x))[None])
    assert shares.sum() == pytest.approx(det * measure, rel=1e-13)


BARS = [("hexahedron", (3, 2, 2)), ("tetra", (3, 2, 2)), ("tetra10", (3, 2, 2)), ("wedge", (3, 2, 2)),
        ("pyramid", (3, 2, 2)), ("mixed", (8, 2, 2)), ("quad", (4, 2)), ("triangle", (4, 2)),
        ("triangle6", (4, 2)), ("mixed", (8, 2))]


@pytest.mark.parametrize("element,cells", BARS)
def test_model_loads_sum_to_the_total_load(element, cells):
    dim = len(cells)
    size = (1.2, 0.3, 0.2)[:dim]
    mesh = generate_bar(size, cells, element)
    g = np.array([0.5, -2.0, -9.81])[:dim]
    t = np.array([3.0, 7.0, -11.0])[:dim]
    end = (tuple([size[0] - 1e-9] + [-1.0] * (dim - 1)), tuple([size[0] + 1] + [1.0] * (dim - 1)))
    model = Model(mesh, [Material(law="hooke", quadrature="gauss2", E=1e5, nu=0.3, density=800.0)],
                  fixed=[Fixed(box=(tuple([-1.0] * dim), tuple([1e-9] + [1.0] * (dim - 1))))],
                  loads=Loads(gravity=tuple(g), nodal=[NodalLoad(box=end, force=tuple(t), kind="traction")]))
    volume, end_area = np.prod(size), np.prod(size[1:])
    total = model.f_ext.reshape(-1, dim).sum(axis=0)
    np.testing.assert_allclose(total, 800.0 * volume * g + end_area * t, rtol=1e-12)
    # the lumped masses carry the whole mass too, on every component
    np.testing.assert_allclose(model.mass.reshape(-1, dim).sum(axis=0), 800.0 * volume, rtol=1e-12)
    assert np.all(model.mass >= 0)


# --------------------------------------------------------------------------- exact fractions

_TET_EDGES = ((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3))


def test_tetra10_body_force_fractions_on_an_affine_element():
    X, det, measure = _affine("tetra10", 7)
    shares = loads.body_force(X, {"tetra10": np.arange(10)[None]}, {"tetra10": 2.0}, [0, 0, -3.0])
    weight = 2.0 * 3.0 * det * measure
    np.testing.assert_allclose(shares[:4, 2] / -weight, -1 / 20, rtol=1e-12)
    np.testing.assert_allclose(shares[4:, 2] / -weight, 1 / 5, rtol=1e-12)
    np.testing.assert_allclose(shares[:, :2], 0.0, atol=1e-15)


def test_line3_edge_and_triangle6_face_fractions():
    x = np.array([[0.0, 0.0], [2.0, 1.0], [1.0, 0.5]])          # straight edge of length sqrt(5)
    f = loads.traction(x, {"line3": np.array([[0, 1, 2]])}, [0.0, -1.0])
    np.testing.assert_allclose(-f[:, 1] / np.sqrt(5), [1 / 6, 1 / 6, 2 / 3], rtol=1e-13)
    X, det, measure = _affine("triangle6", 9)
    x3 = np.c_[X, 0.2 * X[:, 0] - 0.1 * X[:, 1] + 1.0]           # a flat face tilted in 3D
    area = 0.5 * np.linalg.norm(np.cross(x3[1] - x3[0], x3[2] - x3[0]))
    f = loads.traction(x3, {"triangle6": np.arange(6)[None]}, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(f[:3, 2] / area, 0.0, atol=1e-13)
    np.testing.assert_allclose(f[3:, 2] / area, 1 / 3, rtol=1e-13)


# --------------------------------------------------------------------------- curved tetra10


def _tetra10_N(L):
    """Closed-form tetra10 shape functions (VTK order) from barycentrics L (q, 4)."""
    corners = [L[:, i] * (2 * L[:, i] - 1) for i in range(4)]
    mids = [4 * L[:, a] * L[:, b] for a, b in _TET_EDGES]
    return np.stack(corners + mids, axis=1)


def _tetra10_dN(L):
    """(q, 10, 3) gradients wrt (xi, eta, zeta), L0 = 1 - xi - eta - zeta."""
    dL = np.array([[-1, -1, -1], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    out = np.zeros((len(L), 10, 3))
    for i in range(4):
        out[:, i] = (4 * L[:, i] - 1)[:, None] * dL[i]
    for m, (a, b) in enumerate(_TET_EDGES):
        out[:, 4 + m] = 4 * (L[:, a][:, None] * dL[b] + L[:, b][:, None] * dL[a])
    return out


def _collapsed_tetra_rule(n=6):
    """Duffy-collapsed Gauss-Legendre rule on the unit tetrahedron (exact to degree 2n - 3 at least)."""
    x, w = np.polynomial.legendre.leggauss(n)
    t, wt = (x + 1) / 2, w / 2
    pts, wts = [], []
    for u, wu in zip(t, wt):
        for v, wv in zip(t, wt):
            for s, ws in zip(t, wt):
                pts.append((u * (1 - v) * (1 - s), v * (1 - s), s))
                wts.append(wu * wv * ws * (1 - v) * (1 - s) ** 2)
    return np.array(pts), np.array(wts)


def test_body_force_matches_int_N_on_a_curved_tetra10_patch():
    """Two tetra10 sharing a face, every midside node moved off its edge (curved, det J cubic)."""
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.8, 0.9, 0.7]], float)
    tets = [(0, 1, 2, 3), (1, 2, 3, 4)]
    points, cells, mid = list(corners), [], {}
    rng = np.random.default_rng(4)
    for tet in tets:
        row = list(tet)
        for a, b in _TET_EDGES:
            key = tuple(sorted((tet[a], tet[b])))
            if key not in mid:
                mid[key] = len(points)
                points.append(0.5 * (corners[key[0]] + corners[key[1]]) + 0.06 * rng.standard_normal(3))
            row.append(mid[key])
        cells.append(row)
    points, cells = np.array(points), np.array(cells)
    # orientation of the second tet: make det J > 0 at its centroid
    P, W = _collapsed_tetra_rule()
    L = np.c_[1 - P.sum(axis=1), P]
    N, dN = _tetra10_N(L), _tetra10_dN(L)
    for c in range(len(cells)):
        J = np.einsum("kd,qkr->qdr", points[cells[c]], dN)
        if np.linalg.det(J).mean() < 0:
            cells[c, [1, 2]] = cells[c, [2, 1]]
            cells[c, 4:] = cells[c, [4 + i for i in (2, 1, 0, 3, 5, 4)]]
    reference = np.zeros(len(points))
    for c in cells:
        detJ = np.linalg.det(np.einsum("kd,qkr->qdr", points[c], dN))
        assert np.all(detJ > 0)
        assert np.ptp(detJ) > 0.05 * detJ.mean()                 # really curved
        np.add.at(reference, c, (W * detJ) @ N)
    got = loads.body_force(points, {"tetra10": cells}, {"tetra10": 1.0}, [0, 0, 1.0])[:, 2]
    np.testing.assert_allclose(got, reference, rtol=1e-12, atol=1e-15)


# --------------------------------------------------------------------------- masses


@pytest.mark.parametrize("name", ["tetra10", "triangle6"])
def test_hrz_lumping_is_positive_and_conserves_mass(name):
    X, det, measure = _affine(name, 11)
    t = shape_tables.type_of(name)
    # the row sums would not do: zero (triangle6) or negative (tetra10) corner masses
    rows = element_mass(X, name, np.arange(len(X))[None], 3.0).sum(axis=2)[0, :t.n_corners]
    assert rows.max() <= 1e-14 * abs(rows).max() + 1e-15
    X[t.n_corners:] += 0.03 * np.random.default_rng(1).standard_normal(X[t.n_corners:].shape)   # curved
    Me = element_mass(X, name, np.arange(len(X))[None], 3.0)
    m = lump(Me, name)
    assert np.all(m > 0)
    assert m.sum() == pytest.approx(Me.sum(), rel=1e-13)
    assert Me.sum() == pytest.approx(3.0 * loads.volume_shares(X, name, np.arange(len(X))[None]).sum(), rel=1e-13)


@pytest.mark.parametrize("name", ["tetra", "triangle"])
def test_row_sum_lumping_of_simplices_is_the_equal_split(name):
    X, det, measure = _affine(name, 13)
    m = lump(element_mass(X, name, np.arange(len(X))[None], 2.0), name)
    np.testing.assert_allclose(m, 2.0 * det * measure / len(X), rtol=1e-13)


def test_consistent_mass_operator_conserves_mass_and_is_symmetric():
    mesh = generate_bar((1.0, 0.2, 0.2), (4, 1, 1), "tetra10")
    model = Model(mesh, [Material(law="hooke", quadrature="gauss2", E=1e5, nu=0.3, density=500.0)],
                  fixed=[Fixed(box=((-1, -1, -1), (1e-9, 1, 1)))], solver=Solver(mass="consistent"))
    M = model.mass_matrix
    assert M.kind == "consistent"
    ones = np.zeros(model.n_dofs)
    ones[0::3] = 1.0
    assert float(ones @ (M @ ones)) == pytest.approx(500.0 * 0.04, rel=1e-12)
    A = M.matrix()
    assert abs(A - A.T).max() < 1e-14 * abs(A).max()
    assert np.linalg.eigvalsh(A.toarray()).min() > 0                     # positive definite
    np.testing.assert_allclose(M.diagonal, A.diagonal())
    # on the assembler's pattern it is the same matrix
    from tensormass.runtime.assembly.assembly import Assembler
    asm = Assembler(model)
    data = M.add_to(np.zeros(asm.pattern.nnz), asm.pattern, 2.0)
    assert abs(asm.matrix(data) - 2.0 * A).max() < 1e-14 * abs(A).max()
    with pytest.raises(TypeError):
        np.ones(model.n_dofs) * M                                # never an elementwise product


# --------------------------------------------------------------------------- the gmsh organ

ORGAN = Path(__file__).parents[1].joinpath("data") / "organ_tetra10.msh"
E_ORGAN, NU_ORGAN, RHO_ORGAN, G_ORGAN = 5.0e3, 0.45, 1000.0, 9.81
ORGAN_SCENE = f"""
name = "organ"
[mesh]
file = "{ORGAN.as_posix()}"
[[material]]
law = "neohookean"
quadrature = "gauss2"
E = {E_ORGAN}
nu = {NU_ORGAN}
density = {RHO_ORGAN}
[[fixed]]
box = [[-1, -1, -1e-6], [1, 1, 1]]
[loads]
gravity = [0.0, 0.0, -{G_ORGAN}]
[solver]
kind = "static"
steps = 4
newton_tolerance = 1e-10
"""


def _numpy_organ_load(points, cells):
    """Independent consistent gravity load: closed-form tetra10 N, a 216-point collapsed rule."""
    P, W = _collapsed_tetra_rule()
    L = np.c_[1 - P.sum(axis=1), P]
    N, dN = _tetra10_N(L), _tetra10_dN(L)
    f = np.zeros(len(points))
    for c in cells:
        detJ = np.linalg.det(np.einsum("kd,qkr->qdr", points[c], dN))
        np.add.at(f, c, (W * detJ) @ N)
    out = np.zeros((len(points), 3))
    out[:, 2] = -RHO_ORGAN * G_ORGAN * f
    return out


def _solve_static(model):
    from tensormass.runtime.run.simulation import Simulation
    sim = Simulation(model)
    summary = sim.run()
    assert summary["status"] == "ok", summary["message"]
    return sim.displacement.reshape(-1, 3)


@pytest.fixture(scope="module")
def organ():
    from tensormass.runtime.scene.scene import Scene
    scene = Scene.from_string(ORGAN_SCENE)
    model = Model.from_scene(scene)
    pole = int(np.argmin(model.mesh.points[:, 2]))
    assert model.mesh.blocks[0].type == "tetra10" and model.mesh.n_cells > 300
    return scene, model, pole, _solve_static(model)


def test_organ_gravity_is_the_independent_consistent_load(organ):
    scene, model, pole, u = organ
    cells = model.mesh.blocks[0].cells
    reference = _numpy_organ_load(model.mesh.points, cells)
    np.testing.assert_allclose(model.f_ext.reshape(-1, 3), reference, rtol=0, atol=1e-12 * np.abs(reference).max())
    # the static deflection under the independent load (same solver) agrees within 0.1 %
    other = Model.from_scene(scene)
    other.f_ext = reference.ravel()
    u_ref = _solve_static(other)
    assert abs(u[pole, 2] - u_ref[pole, 2]) <= 1e-3 * abs(u_ref[pole, 2])
    assert u[pole, 2] < -1e-3                                        # it really sags (1.5 mm)


def _felupe_pole(points, cells, pole, exact_load: bool):
    fem = pytest.importorskip("felupe")
    mesh = fem.Mesh(points, cells, "tetra10")
    mu = E_ORGAN / (2 * (1 + NU_ORGAN))
    lam = E_ORGAN * NU_ORGAN / ((1 + NU_ORGAN) * (1 - 2 * NU_ORGAN))
    region = fem.RegionQuadraticTetra(mesh)                          # 4-point rule: tensormass' gauss2
    field = fem.FieldContainer([fem.Field(region, dim=3)])
    bounds = {"fixed": fem.Boundary(field[0], fz=lambda z: z > -1e-6)}
    solid = fem.SolidBody(fem.NeoHookeCompressible(mu=mu, lmbda=lam), field)
    g = np.array([0.0, 0.0, -G_ORGAN])
    ramp = np.linspace(0, 1, 5)[1:]
    if exact_load:   # FElupe's own body force integrated with its degree-5 rule (exact on curved tetra10)
        r5 = fem.RegionQuadraticTetra(mesh, quadrature=fem.TetrahedronQuadrature(order=5))
        f5 = fem.FieldContainer([fem.Field(r5, dim=3)])
        load = fem.SolidBodyForce(f5, values=g, scale=RHO_ORGAN).assemble.vector(f5).toarray().reshape(-1, 3)
        item = fem.PointLoad(field, np.arange(len(points)), values=load)
        values = np.array([s * load for s in ramp])
    else:            # FElupe's default: the body force with the region's 4-point rule
        item = fem.SolidBodyForce(field, values=g, scale=RHO_ORGAN)
        values = np.array([s * g for s in ramp])
    step = fem.Step(items=[solid, item], ramp={item: values}, boundaries=bounds)
    fem.Job(steps=[step]).evaluate(tol=1e-10, verbose=0)
    return field[0].values[pole].copy()


def test_organ_deflection_agrees_with_felupe(organ):
    """Same mesh, law (compressible neo-Hooke), rule, clamp and gravity as FElupe 11.3."""
    scene, model, pole, u = organ
    cells = model.mesh.blocks[0].cells
    exact = _felupe_pole(model.mesh.points, cells, pole, exact_load=True)
    assert abs(u[pole, 2] - exact[2]) <= 1e-5 * abs(exact[2])       # measured: 3e-8
    default = _felupe_pole(model.mesh.points, cells, pole, exact_load=False)
    assert abs(u[pole, 2] - default[2]) <= 1e-3 * abs(default[2])   # measured: 5.7e-4 (FElupe's load rule)
