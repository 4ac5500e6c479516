"""Tests for the mesh wing (runtime.mesh): generators, checks, reading and writing."""

import meshio
import numpy as np
import pytest

from tensormass.runtime.mesh.io import GMSH_TO_VTK, read_mesh, to_meshio
from tensormass.runtime.mesh.container import NODES_PER_CELL, SOLID_TYPES_2D, SOLID_TYPES_3D, CellBlock, Mesh, MeshError
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.mesh.faces import boundary_faces
from tensormass.runtime.mesh.checks import check_mesh, orient_cells

SIZE3, CELLS3 = (1.0, 0.2, 0.3), (8, 2, 3)
SIZE2, CELLS2 = (1.0, 0.3), (6, 3)
ELEMENTS3 = ["hexahedron", "tetra", "tetra10", "wedge", "pyramid", "mixed"]
ELEMENTS2 = ["quad", "triangle", "triangle6", "mixed"]

# ---------------------------------------------------------------- independent geometry helpers
# Orientation and volume are checked here without the module's shape functions:
# corner triple products compared with those of the VTK reference element, and
# volumes from a split into simplices.

REF = {
    "tetra": [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)],
    "hexahedron": [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1),
                   (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)],
    "wedge": [(0, 0, -1), (0, 1, -1), (1, 0, -1), (0, 0, 1), (0, 1, 1), (1, 0, 1)],
    "pyramid": [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0), (0, 0, 1)],
    "triangle": [(0, 0), (1, 0), (0, 1)],
    "quad": [(-1, -1), (1, -1), (1, 1), (-1, 1)],
}
REF["tetra10"], REF["triangle6"] = REF["tetra"], REF["triangle"]

# (corner, neighbour, neighbour[, neighbour]) along element edges
CORNER_FRAMES = {
    "tetra": [(0, 1, 2, 3), (1, 2, 0, 3), (2, 0, 1, 3), (3, 0, 1, 2)],
    "hexahedron": [(0, 1, 3, 4), (1, 2, 0, 5), (2, 3, 1, 6), (3, 0, 2, 7),
                   (4, 7, 5, 0), (5, 4, 6, 1), (6, 5, 7, 2), (7, 6, 4, 3)],
    "wedge": [(0, 1, 2, 3), (1, 2, 0, 4), (2, 0, 1, 5), (3, 4, 5, 0), (4, 5, 3, 1), (5, 3, 4, 2)],
    "pyramid": [(0, 1, 3, 4), (1, 2, 0, 4), (2, 3, 1, 4), (3, 0, 2, 4),
                (4, 0, 1, 2), (4, 1, 2, 3), (4, 2, 3, 0), (4, 3, 0, 1)],
    "triangle": [(0, 1, 2), (1, 2, 0), (2, 0, 1)],
    "quad": [(0, 1, 3), (1, 2, 0), (2, 3, 1), (3, 0, 2)],
}
CORNER_FRAMES["tetra10"], CORNER_FRAMES["triangle6"] = CORNER_FRAMES["tetra"], CORNER_FRAMES["triangle"]

SIMPLICES = {
    "tetra": [(0, 1, 2, 3)], "tetra10": [(0, 1, 2, 3)],
    "hexahedron": [(0, 1, 2, 6), (0, 1, 6, 5), (0, 2, 3, 7), (0, 2, 7, 6), (0, 4, 5, 6), (0, 4, 6, 7)],
    "wedge": [(0, 1, 2, 3), (1, 2, 3, 4), (2, 3, 4, 5)],
    "pyramid": [(0, 1, 2, 4), (0, 2, 3, 4)],
    "triangle": [(0, 1, 2)], "triangle6": [(0, 1, 2)], "quad": [(0, 1, 2), (0, 2, 3)],
}


def frame_dets(X, frames):
    """Determinants of the edge vectors from each frame's corner: (n, frames)."""
    f = np.array(frames)
    E = X[:, f[:, 1:]] - X[:, f[:, :1]]            # (n, frames, d, d)
    return np.linalg.det(np.swapaxes(E, -1, -2))


def orientation_ok(mesh):
    """Every corner frame of every cell turns the same way as in the reference cell."""
    for b in mesh.blocks:
        ref = frame_dets(np.array(REF[b.type], float)[None], CORNER_FRAMES[b.type])[0]
        phys = frame_dets(mesh.points[b.cells], CORNER_FRAMES[b.type])
        if not np.all(phys * ref > 0):
            return False
    return True


def total_volume(mesh):
    vol = 0.0
    for b in mesh.blocks:
        S = np.array(SIMPLICES[b.type])
        X = mesh.points[b.cells[:, S]]               # (n, s, d+1, d)
        E = X[:, :, 1:] - X[:, :, :1]
        vol += np.abs(np.linalg.det(E)).sum() / (6.0 if mesh.dim == 3 else 2.0)
    return vol


def single_cell(cell_type, coords):
    return Mesh(np.array(coords, float), [CellBlock(cell_type, np.arange(len(coords))[None])])


# ---------------------------------------------------------------- generators

EXPECTED_CELLS_PER_HEX = {"hexahedron": 1, "tetra": 6, "tetra10": 6, "wedge": 2, "pyramid": 6}


@pytest.mark.parametrize("element", ELEMENTS3)
def test_bar_3d_counts_orientation_volume_conformity(element):
    m = generate_bar(SIZE3, CELLS3, element, origin=(0.5, -1.0, 2.0))
    nh = np.prod(CELLS3)
    if element != "mixed":
        assert m.cell_types() == [element]
        assert m.n_cells == EXPECTED_CELLS_PER_HEX[element] * nh
    grid_points = np.prod(np.array(CELLS3) + 1)
    extra = {"hexahedron": 0, "tetra": 0, "wedge": 0, "pyramid": nh}.get(element)
    if extra is not None:
        assert m.n_points == grid_points + extra
    assert m.dim == 3 and m.points.dtype == np.float64
    assert all(b.cells.dtype == np.int64 for b in m.blocks)
    assert orientation_ok(m)
    assert total_volume(m) == pytest.approx(np.prod(SIZE3), rel=1e-12)
    assert np.allclose(m.points.min(axis=0), (0.5, -1.0, 2.0))
    check_mesh(m)


def test_tetra10_midside_nodes_shared_and_central():
    m = generate_bar(SIZE3, CELLS3, "tetra10")
    tets = generate_bar(SIZE3, CELLS3, "tetra")
    c = m.blocks[0].cells
    assert np.array_equal(c[:, :4], tets.blocks[0].cells)
    edges = [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]
    for k, (a, b) in enumerate(edges):
        assert np.allclose(m.points[c[:, 4 + k]], (m.points[c[:, a]] + m.points[c[:, b]]) / 2)
    # one midside node per unique edge: V - E + F - C = 1 for a box
    n_edges = m.n_points - tets.n_points
    n_faces = (4 * tets.n_cells + len(boundary_faces(tets))) // 2
    assert tets.n_points - n_edges + n_faces - tets.n_cells == 1   # Euler: one midside node per edge
    assert len(np.unique(c[:, 4:])) == n_edges


def test_mixed_bar_contains_all_types_and_is_conforming():
    m = generate_bar(element="mixed")
    assert set(m.cell_types()) == {"hexahedron", "wedge", "pyramid", "tetra"}
    assert all(len(b) > 0 for b in m.blocks)
    check_mesh(m)
    # the boundary of a conforming box only lies on the box's sides
    pts = m.points
    for _, _, face in boundary_faces(m):
        x = pts[list(face)]
        assert np.any(np.all(np.isclose(x, x[:1]), axis=0) & np.any(np.isclose(x[:1], [[0, 0, 0]]) |
                                                                    np.isclose(x[:1], [[1, .2, .2]]), axis=0))
    with pytest.raises(MeshError, match="at least 4"):
        generate_bar(cells=(3, 1, 1), element="mixed")


@pytest.mark.parametrize("element", ELEMENTS2)
def test_bar_2d(element):
    m = generate_bar(SIZE2, CELLS2, element)
    assert m.dim == 2
    n = np.prod(CELLS2)
    expected = {"quad": n, "triangle": 2 * n, "triangle6": 2 * n, "mixed": 3 * CELLS2[1] + 2 * 3 * CELLS2[1]}
    assert m.n_cells == expected[element]
    assert orientation_ok(m)
    assert total_volume(m) == pytest.approx(np.prod(SIZE2), rel=1e-12)
    check_mesh(m)
    assert len(boundary_faces(m)) == 2 * sum(CELLS2)


def test_generate_bar_rejects_bad_input():
    for kwargs in (dict(element="hexahedron20"), dict(cells=(0, 1, 1)), dict(size=(1, 1), cells=(1, 1, 1)),
                   dict(size=(1, 1), cells=(2, 2), element="tetra")):
        with pytest.raises(MeshError):
            generate_bar(**kwargs)


# ---------------------------------------------------------------- reference cells and faces

@pytest.mark.parametrize("cell_type", sorted(SOLID_TYPES_3D + SOLID_TYPES_2D))
def test_reference_cell_is_valid_and_faces_point_outward(cell_type):
    corners = np.array(REF[cell_type], float)
    if cell_type == "tetra10":
        e = [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]
        corners = np.vstack([corners, [(corners[a] + corners[b]) / 2 for a, b in e]])
    if cell_type == "triangle6":
        corners = np.vstack([corners, [(corners[a] + corners[b]) / 2 for a, b in [(0, 1), (1, 2), (2, 0)]]])
    m = single_cell(cell_type, corners)
    check_mesh(m)
    centre = corners[:len(REF[cell_type])].mean(axis=0)
    faces = boundary_faces(m)
    for _, _, f in faces:
        x = corners[list(f)]
        if m.dim == 3:
            n = np.cross(x[1] - x[0], x[2] - x[0])
        else:
            d = x[1] - x[0]
            n = np.array([d[1], -d[0]])
        assert np.dot(n, x[:len(f)].mean(axis=0) - centre) > 0
    if cell_type == "tetra10":
        assert all(len(f) == 6 for _, _, f in faces)


# ---------------------------------------------------------------- check_mesh failures

def test_inverted_cell_is_named():
    m = generate_bar(element="tetra")
    m.blocks[0].cells[17, [1, 2]] = m.blocks[0].cells[17, [2, 1]]
    with pytest.raises(MeshError, match=r"inverted.*\[17\]"):
        check_mesh(m)


def test_inverted_hex_in_mixed_mesh_uses_global_ids():
    m = generate_bar(element="mixed")
    offset = len(m.blocks[0]) + len(m.blocks[1])
    c = m.blocks[2].cells
    c[3] = c[3][[0, 3, 2, 1, 4]]
    with pytest.raises(MeshError, match=rf"inverted.*\[{offset + 3}\]"):
        check_mesh(m)


def test_orient_cells_repairs_mirrored_cells():
    for element in ("tetra", "tetra10", "mixed"):
        m = generate_bar(element=element)
        for b in m.blocks:
            mirror = {"tetra": [0, 2, 1, 3], "tetra10": [0, 2, 1, 3, 6, 5, 4, 7, 9, 8],
                      "hexahedron": [3, 2, 1, 0, 7, 6, 5, 4], "wedge": [0, 2, 1, 3, 5, 4],
                      "pyramid": [1, 0, 3, 2, 4]}[b.type]
            b.cells[::3] = b.cells[::3][:, mirror]
        with pytest.raises(MeshError, match="inverted"):
            check_mesh(m)
        fixed = orient_cells(m)
        check_mesh(fixed)
        assert orientation_ok(fixed)


def test_degenerate_cells():
    tet = single_cell("tetra", [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0.3, 0.3, 0.0)])
    with pytest.raises(MeshError, match=r"degenerate.*\[0\]"):
        check_mesh(tet)
    hexa = np.array(REF["hexahedron"], float)
    hexa[6] = hexa[7]                                   # collapse a node onto another
    with pytest.raises(MeshError, match="degenerate"):
        check_mesh(single_cell("hexahedron", hexa))
    m = generate_bar(element="hexahedron")
    m.blocks[0].cells[5, 1] = m.blocks[0].cells[5, 0]   # collapsed by index
    with pytest.raises(MeshError, match=r"repeated node.*\[5\]"):
        check_mesh(m)


def test_nan_coordinate_and_out_of_range_index_and_empty_mesh():
    m = generate_bar(element="wedge")
    m.points[7, 1] = np.nan
    with pytest.raises(MeshError, match=r"NaN.*\[7\]"):
        check_mesh(m)
    m = generate_bar(element="wedge")
    m.blocks[0].cells[11, 2] = m.n_points
    with pytest.raises(MeshError, match=r"out of range.*\[11\]"):
        check_mesh(m)
    with pytest.raises(MeshError, match="no cells"):
        check_mesh(Mesh(np.zeros((3, 3)), []))


def test_unused_points_are_allowed():
    m = generate_bar(element="hexahedron")
    m.points = np.vstack([m.points, [[5.0, 5.0, 5.0]]])
    check_mesh(m)


def _hanging_node_mesh():
    """Hex 0 = [0,1]^3; hexes 1, 2 split [1,2]x[0,1]x[0,1] in y, with hanging nodes at y=0.5."""
    ids = {}

    def node(x, y, z):
        return ids.setdefault((x, y, z), len(ids))

    def hexa(x0, x1, y0, y1):
        return [node(x0, y0, 0), node(x1, y0, 0), node(x1, y1, 0), node(x0, y1, 0),
                node(x0, y0, 1), node(x1, y0, 1), node(x1, y1, 1), node(x0, y1, 1)]

    cells = [hexa(0, 1, 0, 1), hexa(1, 2, 0, 0.5), hexa(1, 2, 0.5, 1)]
    return Mesh(np.array(list(ids), float), [CellBlock("hexahedron", np.array(cells))])


def test_hanging_node_names_both_sides():
    m = _hanging_node_mesh()
    assert orientation_ok(m)
    with pytest.raises(MeshError, match=r"non-conforming.*cells 0 and 1, 0 and 2") as err:
        check_mesh(m)
    assert "2 pairs" in str(err.value)


def test_hanging_node_2d():
    pts = [(0, 0), (1, 0), (1, 1), (0, 1), (2, 0), (2, 0.5), (1, 0.5), (2, 1)]
    quads = [(0, 1, 2, 3), (1, 4, 5, 6), (6, 5, 7, 2)]
    m = Mesh(np.array(pts, float), [CellBlock("quad", np.array(quads))])
    with pytest.raises(MeshError, match=r"non-conforming.*cells 0 and 1, 0 and 2"):
        check_mesh(m)


def _hex_next_to_tets():
    h = generate_bar((2, 1, 1), (2, 1, 1), "hexahedron")
    t = generate_bar((2, 1, 1), (2, 1, 1), "tetra")
    assert np.array_equal(h.points, t.points)
    return h, t


def test_quad_face_against_two_triangles():
    h, t = _hex_next_to_tets()
    m = Mesh(h.points, [CellBlock("hexahedron", h.blocks[0].cells[:1]), CellBlock("tetra", t.blocks[0].cells[6:])])
    with pytest.raises(MeshError, match=r"quad face split into triangles.*cells 0 and \d, 0 and \d"):
        check_mesh(m)


def test_mismatched_diagonals_between_tets():
    _, t = _hex_next_to_tets()
    cells = t.blocks[0].cells.copy()
    # rotate the second hex's tets by 90 degrees about the x axis: same hex,
    # still positive tets, but the diagonal on the shared face x=1 flips
    p = t.points
    lookup = {tuple(np.round(x, 9)): i for i, x in enumerate(p)}
    rot = {i: lookup[(p[i, 0], 1 - p[i, 2], p[i, 1])] for i in np.unique(cells[6:])}
    cells[6:] = np.vectorize(rot.get)(cells[6:])
    m = Mesh(p, [CellBlock("tetra", cells)])
    assert orientation_ok(m)
    with pytest.raises(MeshError, match=r"non-conforming interface.*cells \d and \d+"):
        check_mesh(m)


def test_unmerged_duplicate_nodes_and_overlaps():
    h = generate_bar((2, 1, 1), (2, 1, 1), "hexahedron")
    pts = np.vstack([h.points, h.points])
    cells = h.blocks[0].cells.copy()
    cells[1] += h.n_points                               # second hex uses copies of the nodes
    with pytest.raises(MeshError, match=r"non-conforming.*cells 0 and 1"):
        check_mesh(Mesh(pts, [CellBlock("hexahedron", cells)]))
    with pytest.raises(MeshError, match=r"duplicated cells.*hexahedron cells 0 and 1"):
        check_mesh(Mesh(h.points, [CellBlock("hexahedron", h.blocks[0].cells[[0, 0, 1]])]))
    dup = h.blocks[0].cells[[1, 1]]
    dup[1] = dup[1, [1, 2, 3, 0, 5, 6, 7, 4]]             # the same cell, numbered from another corner
    with pytest.raises(MeshError, match=r"duplicated cells.*hexahedron cells 0 and 1"):
        check_mesh(Mesh(h.points, [CellBlock("hexahedron", dup)]))


def test_quadratic_cells_must_share_midside_nodes():
    m = generate_bar(element="tetra10")
    c = m.blocks[0].cells
    m.points = np.vstack([m.points, m.points[c[0, 4]]])
    c[0, 4] = m.n_points - 1                             # a private copy of a shared midside node
    with pytest.raises(MeshError, match="midside"):
        check_mesh(m)


def test_wrong_cell_shape_and_type():
    with pytest.raises(MeshError, match="shape"):
        CellBlock("tetra", np.zeros((3, 5), int))
    with pytest.raises(MeshError, match="hexahedron27"):
        CellBlock("hexahedron27", np.zeros((1, 27), int))
    with pytest.raises(MeshError, match="do not fit"):
        check_mesh(Mesh(np.eye(3), [CellBlock("triangle", [[0, 1, 2]])]))


def test_check_mesh_on_100k_cells_finds_the_one_inverted_cell():
    # the chunked, vectorised checks at scale (their time is reported by the benchmarks' set-up
    # times, not asserted here: no timed unit tests)
    m = generate_bar((1, 1, 1), (30, 24, 24), "tetra")
    assert m.n_cells > 100_000
    check_mesh(m)
    cells = m.blocks[0].cells
    cells[77_777, [0, 1]] = cells[77_777, [1, 0]]          # mirror one cell deep inside the mesh
    with pytest.raises(MeshError, match="77777"):
        check_mesh(m)


# ---------------------------------------------------------------- reading and writing

def _same_mesh(a, b):
    assert np.allclose(a.points, b.points)
    assert [bl.type for bl in a.blocks] == [bl.type for bl in b.blocks]
    for x, y in zip(a.blocks, b.blocks):
        assert np.array_equal(x.cells, y.cells)


@pytest.mark.parametrize("element", ["tetra", "tetra10", "mixed"])
def test_vtu_round_trip(tmp_path, element):
    m = generate_bar(element=element)
    path = tmp_path / "bar.vtu"
    to_meshio(m).write(path)
    back = read_mesh(path)
    _same_mesh(m, back)
    check_mesh(back)


def test_vtu_round_trip_2d_drops_z(tmp_path):
    m = generate_bar(SIZE2, CELLS2, "mixed")
    path = tmp_path / "plate.vtu"
    to_meshio(m, pad_to_3d=True).write(path)
    back = read_mesh(path)
    assert back.dim == 2
    _same_mesh(m, back)


def test_tags_split_blocks(tmp_path):
    m = generate_bar(element="tetra")
    n = m.n_cells
    tags = np.where(np.arange(n) < n // 2, 7, 3)
    m.blocks[0].tags = tags
    path = tmp_path / "tagged.vtu"
    to_meshio(m).write(path)
    back = read_mesh(path)
    assert [(b.type, int(b.tags[0]), len(b)) for b in back.blocks] == [("tetra", 7, n // 2), ("tetra", 3, n - n // 2)]
    assert np.array_equal(np.vstack([b.cells for b in back.blocks]), m.blocks[0].cells)


def test_gmsh22_round_trip_keeps_boundary_cells_as_groups(tmp_path):
    m = generate_bar(element="mixed")
    quads = [f for b, _, f in boundary_faces(m) if len(f) == 4]
    # a .msh file holds gmsh's node order: its prism winds the base the other way (GMSH_TO_VTK)
    gmsh_order = [b.cells[:, GMSH_TO_VTK[b.type]] if b.type in GMSH_TO_VTK else b.cells for b in m.blocks]
    cells = [(b.type, c) for b, c in zip(m.blocks, gmsh_order)] + [
        ("quad", np.array(quads)), ("line", np.array([[0, 1]])), ("vertex", np.array([[0]]))]
    phys = [np.full(len(c), 10 + i) for i, (_, c) in enumerate(cells)]
    mm = meshio.Mesh(m.points, cells, cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys})
    path = tmp_path / "bar.msh"
    mm.write(path, file_format="gmsh22", binary=False)
    back = read_mesh(path)
    assert back.dim == 3
    assert sorted(back.cell_types()) == sorted(m.cell_types())
    assert sum(len(b) for b in back.blocks) == m.n_cells
    by_type = {b.type: b for b in back.blocks}
    for i, b in enumerate(m.blocks):
        assert np.array_equal(by_type[b.type].cells, b.cells)
        assert np.all(by_type[b.type].tags == 10 + i)
    check_mesh(back)
    # the boundary cells are kept as groups of their dimension (no names in this file: ids only)
    groups = {g.id: g for g in back.groups}
    assert sorted(groups) == [10, 11, 12, 13, 14, 15, 16]
    assert [groups[i].dim for i in range(10, 17)] == [3, 3, 3, 3, 2, 1, 0]
    assert np.array_equal(groups[14].cells["quad"], np.array(quads))
    assert groups[15].cells["line"].tolist() == [[0, 1]] and groups[16].cells["vertex"].tolist() == [[0]]
    assert groups[11].cell_ids.size == len(m.blocks[1]) and groups[14].cell_ids.size == 0


def test_read_errors(tmp_path):
    with pytest.raises(MeshError, match="not found"):
        read_mesh(tmp_path / "missing.vtu")
    for name in ("garbage.vtu", "garbage.msh", "garbage.qqq"):
        p = tmp_path / name
        p.write_bytes(b"this is not a mesh \x00\x01\x02\n" * 5)
        with pytest.raises(MeshError, match="could not read"):
            read_mesh(p)


def test_read_rejects_unsupported_solid_types(tmp_path):
    pts = np.array(REF["hexahedron"] * 1, float)
    pts20 = np.vstack([pts, (pts[[0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3]] + pts[[1, 2, 3, 0, 5, 6, 7, 4, 4, 5, 6, 7]]) / 2])
    path = tmp_path / "h20.vtu"
    meshio.Mesh(pts20, [("hexahedron20", np.arange(20)[None])]).write(path)
    with pytest.raises(MeshError, match="hexahedron20"):
        read_mesh(path)


def test_read_surface_only_mesh_in_3d_is_rejected(tmp_path):
    path = tmp_path / "surf.vtu"
    meshio.Mesh(np.array([(0, 0, 0), (1, 0, 0), (0, 1, 1.0)]), [("triangle", np.array([[0, 1, 2]]))]).write(path)
    with pytest.raises(MeshError, match="nonzero z"):
        read_mesh(path)


def test_type_lists():
    assert set(SOLID_TYPES_3D) | set(SOLID_TYPES_2D) | {"shell"} == set(NODES_PER_CELL)
