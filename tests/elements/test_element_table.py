"""The element table (tensormass.elements): consistency of every entry, agreement with what the
mesh checks and the generator used before the table existed, and a toy element (a 2-node bar in
3D, topological dimension 1 < space dimension 3) registered through the table."""
import math
from fractions import Fraction

import numpy as np
import pytest
import sympy as sp

from tensormass import elements
from tensormass.elements import SIMPLEX, ElementType, Face
from tensormass.generator.elements import ELEMENTS, element
from tensormass.generator.quadrature import rule
from tensormass.runtime.mesh import checks, container, faces
from tensormass.runtime.mesh.container import CellBlock, Mesh, MeshError
from tensormass.runtime.mesh.checks import check_mesh, orient_cells
from tensormass.runtime.mesh.io import read_mesh

SOLIDS = ("tetra", "tetra10", "hexahedron", "wedge", "pyramid", "triangle", "triangle6", "quad")
BUILTIN = SOLIDS + ("shell",)         # shell: a triangle with 6 dofs per node (elements/shell.py)
FACE_NODES = {"vertex": 1, "line": 2, "line3": 3, "triangle": 3, "triangle6": 6, "quad": 4}

# What runtime/mesh/mesh.py, runtime/change/adapt.py and generator/elements.py restated before the table.
OLD_NODES = {"tetra": 4, "tetra10": 10, "hexahedron": 8, "wedge": 6, "pyramid": 5,
             "triangle": 3, "triangle6": 6, "quad": 4, "shell": 3}
OLD_CORNERS = {"tetra": 4, "tetra10": 4, "hexahedron": 8, "wedge": 6, "pyramid": 5,
               "triangle": 3, "triangle6": 3, "quad": 4}
OLD_FACES = {
    "tetra": [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)],
    "hexahedron": [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)],
    "wedge": [(0, 1, 2), (3, 5, 4), (0, 3, 4, 1), (0, 2, 5, 3), (1, 4, 5, 2)],
    "pyramid": [(0, 3, 2, 1), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)],
    "triangle": [(0, 1), (1, 2), (2, 0)],
    "quad": [(0, 1), (1, 2), (2, 3), (3, 0)],
}
OLD_FACES["tetra10"], OLD_FACES["triangle6"] = OLD_FACES["tetra"], OLD_FACES["triangle"]
OLD_EDGE_COUNT = {"triangle": 3, "triangle6": 3, "quad": 4, "tetra": 6, "tetra10": 6, "hexahedron": 12,
                  "wedge": 9, "pyramid": 8}
OLD_REGULAR = {"triangle": np.sqrt(3) / 4, "triangle6": np.sqrt(3) / 4, "quad": 1.0,
               "tetra": 1 / (6 * np.sqrt(2)), "tetra10": 1 / (6 * np.sqrt(2)), "hexahedron": 1.0,
               "wedge": np.sqrt(3) / 4, "pyramid": np.sqrt(2) / 6}
OLD_VOLUME = {"triangle": sp.Rational(1, 2), "triangle6": sp.Rational(1, 2), "quad": 4, "tetra": sp.Rational(1, 6),
              "tetra10": sp.Rational(1, 6), "hexahedron": 8, "wedge": 1, "pyramid": sp.Rational(4, 3)}
OLD_MIRROR = {
    "tetra": [0, 2, 1, 3], "tetra10": [0, 2, 1, 3, 6, 5, 4, 7, 9, 8],
    "hexahedron": [4, 5, 6, 7, 0, 1, 2, 3], "wedge": [3, 4, 5, 0, 1, 2], "pyramid": [0, 3, 2, 1, 4],
    "triangle": [0, 2, 1], "triangle6": [0, 2, 1, 5, 4, 3], "quad": [0, 3, 2, 1],
}
# Corners of the regular element with unit edges (for the measures used by R_M / R_HM).
_S3 = math.sqrt(3)
REGULAR = {
    "triangle": [(0, 0), (1, 0), (0.5, _S3 / 2)],
    "quad": [(0, 0), (1, 0), (1, 1), (0, 1)],
    "tetra": [(0, 0, 0), (1, 0, 0), (0.5, _S3 / 2, 0), (0.5, _S3 / 6, math.sqrt(2 / 3))],
    "hexahedron": [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)],
    "wedge": [(0, 0, 0), (0.5, _S3 / 2, 0), (1, 0, 0), (0, 0, 1), (0.5, _S3 / 2, 1), (1, 0, 1)],
    "pyramid": [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0.5, 0.5, math.sqrt(0.5))],
}
REGULAR["triangle6"], REGULAR["tetra10"] = REGULAR["triangle"], REGULAR["tetra"]


def _ref(t):
    return np.array(t.nodes, dtype=float)


# --------------------------------------------------------------------------- registry


def test_registry_names_and_lookups():
    assert elements.names() == BUILTIN == elements.builtin()
    assert elements.names(dim=3) == ("tetra", "tetra10", "hexahedron", "wedge", "pyramid") == container.SOLID_TYPES_3D
    assert elements.names(dim=2) == ("triangle", "triangle6", "quad", "shell")
    assert container.SOLID_TYPES_2D == ("triangle", "triangle6", "quad")          # a shell is no 2D solid
    assert not elements.get("shell").solid and elements.get("shell").dofs_per_node == 6
    assert [t.name for t in elements.by_dim(2)] == list(elements.names(dim=2))
    assert container.NODES_PER_CELL == OLD_NODES
    with pytest.raises(ValueError, match="unknown element type 'hexahedron27'"):
        elements.get("hexahedron27")
    with pytest.raises(ValueError, match="already registered"):
        elements.register(ElementType(**{**elements.get("tetra").__dict__, "regular_measure": 2.0}))
    with pytest.raises(ValueError, match="built-in"):
        elements.unregister("tetra")


def test_element_types_are_frozen():
    with pytest.raises(Exception):
        elements.get("tetra").dim = 2


# --------------------------------------------------------------------------- consistency


@pytest.mark.parametrize("name", SOLIDS)
def test_counts_equal_what_mesh_and_generator_used(name):
    t = elements.get(name)
    assert t.n_nodes == OLD_NODES[name] == element(name).n_nodes
    assert t.n_corners == OLD_CORNERS[name]
    assert [f.corners for f in t.faces] == OLD_FACES[name]
    assert len(t.edges) == OLD_EDGE_COUNT[name]
    assert list(t.flip) == OLD_MIRROR[name]
    assert element(name).volume() == OLD_VOLUME[name] == t.reference_measure
    assert t.regular_measure == OLD_REGULAR[name]
    assert t.dim == element(name).dim and t.dofs_per_node is None and t.space_dims == (t.dim,)
    assert t.n_dofs(t.dim) == t.n_nodes * t.dim
    assert elements.get(t.linear).order == 1 and elements.get(t.linear).n_nodes == t.n_corners


@pytest.mark.parametrize("name", SOLIDS)
def test_faces_and_edges_are_made_of_the_element(name):
    t = elements.get(name)
    edges = {frozenset(e) for e in t.edges}
    assert len(edges) == len(t.edges) and all(max(e) < t.n_corners for e in t.edges)
    for f in t.faces:
        assert set(f.nodes) <= set(range(t.n_nodes)) and len(set(f.nodes)) == len(f.nodes)
        assert len(f.nodes) == FACE_NODES[f.type]
        assert max(f.corners) < t.n_corners
        c = f.corners
        ring = [frozenset((c[i], c[(i + 1) % len(c)])) for i in range(len(c))] if len(c) > 2 else [frozenset(c)]
        assert set(ring) <= edges
        if t.quadratic:   # the face's own midsides: those of its corner edges, in the face type's order
            assert f.nodes[len(c):] == tuple(t.midside(*tuple(e)) for e in
                                              [(c[i], c[(i + 1) % len(c)]) for i in range(len(c))][:len(f.nodes) - len(c)])
            assert elements.get(f.type).quadratic if f.type in elements.names() else f.type == "line3"
    if t.dim == 3:        # Euler: V - E + F = 2
        assert t.n_corners - len(t.edges) + len(t.faces) == 2


@pytest.mark.parametrize("name", SOLIDS)
def test_faces_point_outward(name):
    t = elements.get(name)
    X = _ref(t)
    centre = X[: t.n_corners].mean(axis=0)
    for f in t.faces:
        V = X[list(f.corners)]
        if t.dim == 3:
            n = np.cross(V[1] - V[0], V[2] - V[0])
        else:   # edge direction with the element on its left: the outward normal is (dy, -dx)
            d = V[1] - V[0]
            n = np.array([d[1], -d[0]])
        assert n @ (V.mean(axis=0) - centre) > 0, f


@pytest.mark.parametrize("name", SOLIDS)
def test_midsides_at_edge_midpoints(name):
    t = elements.get(name)
    assert t.quadratic == (t.order == 2) == (t.n_nodes > t.n_corners)
    for m, (a, b) in enumerate(t.midside_edges):
        mid = t.nodes[t.n_corners + m]
        assert all(Fraction(x) == (Fraction(p) + Fraction(q)) / 2 for x, p, q in zip(mid, t.nodes[a], t.nodes[b]))
        assert t.midside(a, b) == t.midside(b, a) == t.n_corners + m
    assert {frozenset(e) for e in t.midside_edges} <= {frozenset(e) for e in t.edges}


@pytest.mark.parametrize("name", SOLIDS)
def test_regular_measures(name):
    from scipy.spatial import ConvexHull

    t = elements.get(name)
    P = np.array(REGULAR[name], float)
    lengths = [np.linalg.norm(P[a] - P[b]) for a, b in t.edges]
    np.testing.assert_allclose(lengths, 1.0, rtol=1e-12)
    assert ConvexHull(P).volume == pytest.approx(t.regular_measure, rel=1e-12)
    # the regular element is positively oriented in this node order
    blk = CellBlock(t.linear, [list(range(t.n_corners))])
    assert np.all(faces.sample_dets(P, blk) > 0)


@pytest.mark.parametrize("name", SOLIDS)
def test_flip_mirrors_the_reference_element(name):
    t = elements.get(name)
    X = _ref(t)
    ok = faces.sample_dets(X, CellBlock(name, [list(range(t.n_nodes))]))
    flipped = faces.sample_dets(X, CellBlock(name, [list(t.flip)]))
    assert np.all(ok > 0) and np.all(flipped < 0)


@pytest.mark.parametrize("name", [n for n in SOLIDS if n != "pyramid"])
def test_numeric_lagrange_gradients_match_the_closed_forms(name):
    """The fallback a new element type (hexahedron27, wedge15, ...) gets its mesh-check tables from."""
    t = elements.get(name)
    corners = np.array(t.corner_nodes, float)
    for q, x in enumerate(list(corners) + [corners.mean(axis=0)]):
        np.testing.assert_allclose(faces._grad_lagrange(t, x), faces._gradient_table(t)[q], atol=1e-12)


@pytest.mark.parametrize("name", SOLIDS)
def test_generator_nodes_and_kind_come_from_the_table(name):
    t, ref = elements.get(name), ELEMENTS[name]
    assert ref.type is t and ref.nodes == tuple(tuple(sp.sympify(c) for c in p) for p in t.nodes)
    assert ref.simplex == (t.domain == SIMPLEX) and ref.polynomial == (name != "pyramid")


# --------------------------------------------------------------------------- a toy element


BAR = ElementType(name="line", dim=1, domain=SIMPLEX, order=1, nodes=((0,), (1,)), n_corners=2,
                  edges=((0, 1),), faces=(Face("vertex", (0,)), Face("vertex", (1,))),
                  regular_measure=1.0, flip=(1, 0), dofs_per_node=3, space_dims=(3,))


@pytest.fixture
def bar():
    elements.register(BAR)
    try:
        yield BAR
    finally:
        elements.unregister("line")


def test_toy_bar_through_the_table(bar):
    assert elements.get("line") is bar and elements.names(dim=1) == ("line",)
    assert bar.n_dofs(3) == 6 and bar.reference_measure == 1
    # shape functions and quadrature by domain from the generator's element code
    ref = element("line")
    xi = ref.xi[0]
    assert [sp.simplify(n - e) for n, e in zip(ref.shape_functions, (1 - xi, xi))] == [0, 0]
    assert ref.gradients() == sp.Matrix([[-1], [1]]) and ref.volume() == 1
    r = rule("line", "gauss2")
    assert r.n_points == 2 and r.degree == 3
    assert float(sum(w * p[0] ** 3 for p, w in zip(r.points, r.weights))) == pytest.approx(0.25, abs=1e-25)
    assert rule("line", "collapsed3").n_points == 3
    with pytest.raises(ValueError, match="unknown element 'spring'"):
        rule("spring", "gauss1")
    assert "line" not in ELEMENTS           # no kernels exist: the catalogue is unchanged


def test_toy_bar_mesh_checks(bar, tmp_path):
    import meshio

    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1.0]])
    m = Mesh(pts, [CellBlock("line", [[0, 1], [1, 2], [2, 3]])])
    check_mesh(m)                                           # lengths, not volumes; no faces to match
    assert faces.boundary_faces(m) == []
    np.testing.assert_array_equal(orient_cells(m).blocks[0].cells, m.blocks[0].cells)
    with pytest.raises(MeshError, match=r"degenerate cells .* \[1\]"):
        check_mesh(Mesh(np.vstack([pts, pts[2]]), [CellBlock("line", [[0, 1], [2, 4]])]))
    with pytest.raises(MeshError, match="line do not fit a 2D mesh"):
        check_mesh(Mesh(pts[:, :2], [CellBlock("line", [[0, 1]])]))
    # a mixed mesh: the bars ride along, the solid's faces are still checked
    check_mesh(Mesh(np.vstack([np.eye(3), [[0, 0, 0]]]), [CellBlock("tetra", [[3, 0, 1, 2]]),
                                                          CellBlock("line", [[0, 1]])]))
    path = tmp_path / "bars.vtu"
    meshio.write(path, meshio.Mesh(pts, [("line", np.array([[0, 1], [1, 2], [2, 3]]))]))
    read = read_mesh(path)
    assert read.dim == 3 and read.blocks[0].type == "line" and len(read.blocks[0]) == 3
    check_mesh(read)


def test_unregistered_lower_dimensional_cells_are_refused(tmp_path):
    import meshio

    assert "line" not in elements.names()
    path = tmp_path / "bars.vtu"
    meshio.write(path, meshio.Mesh(np.eye(3), [("line", np.array([[0, 1], [1, 2]]))]))
    with pytest.raises(MeshError, match="no 2D or 3D cells"):
        read_mesh(path)
    with pytest.raises(MeshError, match="unsupported cell type 'line'"):
        CellBlock("line", [[0, 1]])


# --------------------------------------------------------------------------- adding a type = one table entry


QUAD9 = ElementType(
    name="quad9", dim=2, domain=elements.BOX, order=2, linear="quad",
    nodes=((-1, -1), (1, -1), (1, 1), (-1, 1), (0, -1), (1, 0), (0, 1), (-1, 0), (0, 0)),
    n_corners=4, midside_edges=((0, 1), (1, 2), (2, 3), (3, 0)),
    edges=((0, 1), (1, 2), (2, 3), (3, 0)),
    faces=(Face("line3", (0, 1, 4)), Face("line3", (1, 2, 5)), Face("line3", (2, 3, 6)), Face("line3", (3, 0, 7))),
    regular_measure=1.0, flip=(0, 3, 2, 1, 7, 6, 5, 4, 8))


@pytest.fixture
def quad9():
    elements.register(QUAD9)
    try:
        yield QUAD9
    finally:
        elements.unregister("quad9")


def _quad9_mesh():
    x, y = np.meshgrid(np.linspace(0, 2, 5), np.linspace(0, 1, 3), indexing="ij")
    pts = np.column_stack([x.ravel(), y.ravel()])
    idx = np.arange(15).reshape(5, 3)
    cells = [[idx[i, 0], idx[i + 2, 0], idx[i + 2, 2], idx[i, 2], idx[i + 1, 0], idx[i + 2, 1], idx[i + 1, 2],
              idx[i, 1], idx[i + 1, 1]] for i in (0, 2)]
    return Mesh(pts, [CellBlock("quad9", cells)])


def test_a_new_type_needs_only_its_table_entry(quad9):
    """A 9-node quadrilateral (the 2D analogue of hexahedron27, face/interior node included) works
    through the table alone: shape functions, quadrature, mesh checks, faces, orientation fix."""
    ref = element("quad9")
    assert sp.simplify(sum(ref.shape_functions) - 1) == 0 and ref.polynomial and not ref.simplex
    assert rule("quad9", "gauss3").n_points == 9 and ref.volume() == 4
    m = _quad9_mesh()
    check_mesh(m)
    boundary = faces.boundary_faces(m)
    assert len(boundary) == 6 and all(len(f[2]) == 3 for f in boundary)
    assert sum(faces.face_measure(m.points, f[2], 2) for f in boundary) == pytest.approx(6.0)
    flipped = Mesh(m.points, [CellBlock("quad9", m.blocks[0].cells[:, list(QUAD9.flip)])])
    with pytest.raises(MeshError, match="inverted"):
        check_mesh(flipped)
    np.testing.assert_array_equal(orient_cells(flipped).blocks[0].cells, m.blocks[0].cells)
    cells = m.blocks[0].cells.copy()
    cells[1, 7] = 15                        # the second cell's own copy of the shared midside node (1, 0.5)
    with pytest.raises(MeshError, match="midside"):
        check_mesh(Mesh(np.vstack([m.points, [[1.0, 0.5]]]), [CellBlock("quad9", cells)]))


def test_a_new_type_gets_a_resource_estimate(quad9):
    """The resource estimate reads node counts from the table too: no table of its own to extend."""
    from tensormass.runtime.scene import resources
    est = resources.estimate(resources.MeshCounts.of_mesh(_quad9_mesh()))
    assert est.bytes > 0 and est.nodes == 15 and est.cells == {"quad9": 2}
