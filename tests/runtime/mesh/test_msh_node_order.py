"""Node order of gmsh .msh files (#12): every cell type tensormass supports, read from a file gmsh
itself wrote (MSH 4.1 and 2.2, ascii and binary), passes the inversion check with positive volume.

The fixtures in data/msh/ were made by data/msh/make_fixtures.py (gmsh 4.15); the last test makes
them again with gmsh when it is installed and compares what tensormass reads."""
from pathlib import Path

import meshio
import numpy as np
import pytest

from tensormass import elements
from tensormass.runtime.mesh.io import GMSH_TO_VTK, read_mesh
from tensormass.runtime.mesh.container import CellBlock, Mesh, MeshError
from tensormass.runtime.mesh.faces import sample_dets, boundary_faces
from tensormass.runtime.mesh.checks import check_mesh
from tensormass.runtime.mesh.regions import region_nodes

DATA = Path(__file__).parents[1] / "data" / "msh"
FILES = sorted(DATA.glob("*.msh"))
# the fixtures are boxes [0, 1] x [0, 0.6] x [0, 0.4] (3D) and rectangles [0, 1] x [0, 0.6] (2D)
VOLUME = {3: 1.0 * 0.6 * 0.4, 2: 1.0 * 0.6}


def _load_builder():
    import importlib.util
    spec = importlib.util.spec_from_file_location("make_fixtures", DATA / "make_fixtures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def enclosed_volume(mesh) -> float:
    """Volume (area in 2D) enclosed by the outward boundary faces (divergence theorem, corners only):
    positive only when the faces, and so the cells, are oriented the right way round."""
    total = 0.0
    for _, _, nodes in boundary_faces(mesh):
        x = mesh.points[list(nodes)]
        if mesh.dim == 2:
            total += 0.5 * (x[0, 0] * x[1, 1] - x[0, 1] * x[1, 0])
        elif len(nodes) in (4, 8, 9):           # a quad: two triangles (planar faces of a box)
            total += (np.dot(x[0], np.cross(x[1], x[2])) + np.dot(x[0], np.cross(x[2], x[3]))) / 6
        else:
            total += np.dot(x[0], np.cross(x[1], x[2])) / 6
    return total


def test_every_supported_cell_type_has_a_fixture():
    seen = set()
    for path in FILES:
        seen.update(read_mesh(path).cell_types())
    solids = {n for n in elements.builtin() if elements.get(n).solid}      # a shell is a file's triangle
    assert solids <= seen, f"no gmsh fixture for {solids - seen}"


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_cells_read_from_gmsh_pass_the_inversion_check_with_positive_volume(path):
    mesh = read_mesh(path)
    check_mesh(mesh)                                  # det J > 0 at corners and centroid, conforming
    for blk in mesh.blocks:
        assert sample_dets(mesh.points, blk).min() > 0, blk.type
    assert enclosed_volume(mesh) == pytest.approx(VOLUME[mesh.dim], rel=1e-12)
    # physical groups: the volume "body" holds every cell, "side" the x = 0 boundary
    groups = {g.name: g for g in mesh.groups}
    assert groups["body"].id == 1 and groups["body"].dim == mesh.dim
    assert groups["body"].cell_ids.tolist() == list(range(mesh.n_cells))
    assert groups["side"].id == 2 and groups["side"].dim == mesh.dim - 1
    side = region_nodes(mesh, "side")
    assert side.size and np.all(mesh.points[side, 0] == 0.0)
    assert side.size == np.count_nonzero(mesh.points[np.unique(np.concatenate([b.cells.ravel() for b in mesh.blocks])), 0] == 0.0)


def test_gmsh_prisms_are_mirrored_without_the_conversion():
    """meshio keeps gmsh's prism order: read raw, every wedge is inverted, and the message says why."""
    for path in (DATA / "wedge_v41.msh", DATA / "hex_wedge_v22b.msh"):
        raw = meshio.read(path)
        blocks = [CellBlock(cb.type, cb.data) for cb in raw.cells if cb.type in ("wedge", "hexahedron")]
        wedges = next(b for b in blocks if b.type == "wedge")
        assert np.all(sample_dets(raw.points, wedges).max(axis=1) < 0)
        with pytest.raises(MeshError, match=r"inverted cells .*every wedge cell is inverted: the file's node order"):
            check_mesh(Mesh(raw.points, blocks))
        converted = CellBlock("wedge", wedges.cells[:, GMSH_TO_VTK["wedge"]])
        assert np.all(sample_dets(raw.points, converted).min(axis=1) > 0)


def test_no_node_order_hint_when_only_some_cells_are_inverted():
    mesh = read_mesh(DATA / "tetra_v41.msh")
    cells = mesh.blocks[0].cells.copy()
    cells[0, [0, 1]] = cells[0, [1, 0]]
    with pytest.raises(MeshError, match=r"inverted cells") as info:
        check_mesh(Mesh(mesh.points, [CellBlock("tetra", cells)]))
    assert "node order" not in str(info.value)


def test_the_fixtures_are_what_gmsh_makes(tmp_path):
    pytest.importorskip("gmsh")
    builder = _load_builder()
    made = builder.make(tmp_path)
    assert sorted(p.name for p in made) == [p.name for p in FILES]
    for path in made:
        new, old = read_mesh(path), read_mesh(DATA / path.name)
        check_mesh(new)
        assert [(b.type, len(b)) for b in new.blocks] == [(b.type, len(b)) for b in old.blocks]
        assert [(g.name, g.id, g.dim, g.n_cells()) for g in new.groups] == \
            [(g.name, g.id, g.dim, g.n_cells()) for g in old.groups]
        assert np.allclose(new.points, old.points)
        body = {t for b in new.blocks for t in [b.type]}
        assert body == builder.FIXTURES[path.name.rsplit("_v", 1)[0]][1]
