"""Regions from the mesh (#12): groups read from files (gmsh physical groups, cell sets, tags of every
dimension), selected by name or id for materials, [[fixed]], loads and probes, alone or with a box;
boundary groups checked to lie on the surface; unknown regions listed."""
import contextlib
import io

import meshio
import numpy as np
import pytest

from tensormass.runtime.base.errors import SceneError, TensormassError
from tensormass.runtime.mesh.container import MeshError
from tensormass.runtime.mesh.checks import check_mesh
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.mesh.io import read_mesh
from tensormass.runtime.mesh.mesh_groups import Group, read_groups
from tensormass.runtime.model.model import Model
from tensormass.runtime.mesh.regions import (assign_materials, find_group, known_regions, region_faces,
    region_nodes)
from tensormass.runtime.scene.types import Fixed, Material, NodalLoad, Probe, Loads
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.run.simulation import Simulation

L, W = 1.0, 0.2


def _node(points, x):
    return int(np.flatnonzero(np.all(np.isclose(points, x), axis=1))[0])


def _faces_on(mesh, axis, value):
    from tensormass.runtime.mesh.faces import boundary_faces
    return [f for _, _, f in boundary_faces(mesh) if np.allclose(mesh.points[list(f), axis], value)]


def write_bar(path, element="tetra", extra=(), names=True):
    """A 1 x 0.2 x 0.2 bar of 4 x 1 x 1 hexes (tetra: Kuhn-split) as gmsh 2.2, with groups:
    volumes "left" (id 1, x < 0.5) and "right" (id 2); surfaces "clamp" (id 1, x = 0) and "tip" (id 3,
    x = 1); the curve "edge" (id 4, x = 1, z = 0) and the point "corner" (id 5, at (1, 0.2, 0.2)).
    Surface id 1 = volume id 1 on purpose (gmsh numbers groups per dimension)."""
    m = generate_bar((L, W, W), (4, 1, 1), element)
    (blk,) = m.blocks
    cx = m.points[blk.cells].mean(axis=1)[:, 0]
    vol_tag = np.where(cx < 0.5, 1, 2)
    clamp = np.array(_faces_on(m, 0, 0.0))
    tip = np.array(_faces_on(m, 0, L))
    ftype = {3: "triangle", 4: "quad", 6: "triangle6"}[clamp.shape[1]]
    a, b = _node(m.points, (L, 0, 0)), _node(m.points, (L, W, 0))
    cells = [(element, blk.cells), (ftype, clamp), (ftype, tip), ("line", np.array([[a, b]])),
             ("vertex", np.array([[_node(m.points, (L, W, W))]]))] + list(extra)
    phys = [vol_tag, np.full(len(clamp), 1), np.full(len(tip), 3), np.array([4]), np.array([5])] + \
        [np.full(len(c), 9) for _, c in extra]
    field = {"left": np.array([1, 3]), "right": np.array([2, 3]), "clamp": np.array([1, 2]),
             "tip": np.array([3, 2]), "edge": np.array([4, 1]), "corner": np.array([5, 0])} if names else {}
    if extra and names:
        field["inner"] = np.array([9, 2])
    mm = meshio.Mesh(m.points, cells, cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
                     field_data=field)
    with contextlib.redirect_stdout(io.StringIO()):
        mm.write(path, file_format="gmsh22", binary=False)
    return path


@pytest.fixture(scope="module")
def bar_file(tmp_path_factory):
    return write_bar(tmp_path_factory.mktemp("regions") / "bar.msh")


@pytest.fixture(scope="module")
def bar(bar_file):
    mesh = read_mesh(bar_file)
    check_mesh(mesh)
    return mesh


def test_groups_of_every_dimension_are_read_with_names_and_ids(bar):
    got = {g.name: (g.id, g.dim) for g in bar.groups}
    assert got == {"left": (1, 3), "right": (2, 3), "clamp": (1, 2), "tip": (3, 2), "edge": (4, 1), "corner": (5, 0)}
    groups = {g.name: g for g in bar.groups}
    assert groups["left"].cell_ids.size + groups["right"].cell_ids.size == bar.n_cells
    assert len(groups["clamp"].cells["triangle"]) == 2 and len(groups["tip"].cells["triangle"]) == 2
    assert known_regions(bar) == ("'left' (id 1, volume), 'right' (id 2, volume), 'clamp' (id 1, surface), "
                                  "'tip' (id 3, surface), 'edge' (id 4, curve), 'corner' (id 5, point)")


def test_materials_by_name_and_by_id(bar):
    centre_x = np.vstack([bar.points[b.cells].mean(axis=1) for b in bar.blocks])[:, 0]
    for left, right in (("left", "right"), (1, 2), ("left", 2), ("1", "right")):
        which = np.concatenate(assign_materials(bar, [Material(region=left, E=1.0, nu=0.3),
                                                      Material(region=right, E=2.0, nu=0.3)]))
        assert which.tolist() == np.where(centre_x < 0.5, 0, 1).tolist()
    # region and box: the intersection
    which = np.concatenate(assign_materials(bar, [Material(region="right", box=((0.75, -1, -1), (2, 1, 1))),
                                                  Material()]))
    assert which.tolist() == np.where(centre_x > 0.75, 0, 1).tolist()


def test_material_regions_must_be_volume_groups(bar):
    with pytest.raises(SceneError, match=r"^material\[0\]\.region: region 'tip' \(id 3, surface\) is not a volume "
                                         r"group, which a material \(it selects cells\) needs; the mesh's volume "
                                         r"groups: 'left' \(id 1, volume\), 'right' \(id 2, volume\)"):
        assign_materials(bar, [Material(region="tip")])
    with pytest.raises(SceneError, match=r"^material\[1\]\.region: unknown region 'liver'; the mesh's regions: "
                                         r"'left' \(id 1, volume\), .*'corner' \(id 5, point\)"):
        assign_materials(bar, [Material(region="left"), Material(region="liver")])


def test_fixed_by_name_id_and_box(bar):
    x0 = np.flatnonzero(bar.points[:, 0] == 0.0)
    assert region_nodes(bar, "clamp").tolist() == x0.tolist()
    assert region_nodes(bar, 3).tolist() == np.flatnonzero(bar.points[:, 0] == L).tolist()   # id 3: one group
    low = ((-1, -1, -1), (2, 0.1, 1))
    assert region_nodes(bar, "clamp", box=low).tolist() == x0[bar.points[x0, 1] <= 0.1].tolist()
    assert region_nodes(bar, "edge").tolist() == sorted([_node(bar.points, (L, 0, 0)), _node(bar.points, (L, W, 0))])
    assert region_nodes(bar, "corner").tolist() == [_node(bar.points, (L, W, W))]
    assert region_nodes(bar, "left").size == np.count_nonzero(bar.points[:, 0] <= 0.5)
    with pytest.raises(SceneError, match=r"^fixed\[0\]\.region: id 1 names groups of several dimensions "
                                         r"\('left' \(id 1, volume\), 'clamp' \(id 1, surface\)\); use the group's name"):
        find_group(bar, 1, key="fixed[0].region")
    model = _model(bar, fixed=[Fixed(box=None, region="clamp"), Fixed(box=((-1, -1, -1), (2, 2, 2)), region=3,
                                                                    displacement=(0.0, 0.0, -0.01), components=(2,))])
    assert sorted(set(model.fixed_dofs // 3)) == sorted(set(x0) | set(np.flatnonzero(bar.points[:, 0] == L)))
    tip = np.flatnonzero(bar.points[:, 0] == L)
    assert np.allclose(model.prescribed[np.isin(model.fixed_dofs, tip * 3 + 2)], -0.01)


def _model(mesh, fixed=(), loads=None, probes=()):
    return Model(mesh, [Material(law="hooke", E=1e6, nu=0.3)], fixed=fixed or [Fixed(box=None, region="clamp")],
                 loads=loads, probes=probes)


def test_loads_on_regions_force_and_traction(bar):
    tip = np.flatnonzero(bar.points[:, 0] == L)
    model = _model(bar, loads=Loads(nodal=[NodalLoad(box=None, force=(0.0, 0.0, -8.0), region="tip")]))
    f = model.f_ext.reshape(-1, 3)
    assert np.allclose(f[tip], [0, 0, -8.0 / tip.size]) and np.allclose(np.delete(f, tip, axis=0), 0.0)
    model = _model(bar, loads=Loads(nodal=[NodalLoad(box=None, force=(0.0, 100.0, 0.0), kind="traction",
                                                     region=3)]))
    f = model.f_ext.reshape(-1, 3)
    assert f[:, 1].sum() == pytest.approx(100.0 * W * W) and np.allclose(np.delete(f, tip, axis=0), 0.0)
    # region and box: only the tip faces with every node at y <= 0.1 ... none (each spans y = 0 .. 0.2)
    with pytest.raises(SceneError, match=r"has no boundary face inside its box"):
        Scene.from_dict(_scene_dict(loads={"traction": [{"region": "tip", "box": [[0, -1, -1], [2, 0.1, 1]],
                                                         "value": [0, 0, 1.0]}]}), load_mesh=True)
    with pytest.raises(SceneError, match=r"^loads\.traction\[0\]\.region: region 'edge' \(id 4, curve\) holds no "
                                         r"faces; a traction needs a surface group"):
        Scene.from_dict(_scene_dict(loads={"traction": [{"region": "edge", "value": [0, 0, 1.0]}]}))
    with pytest.raises(SceneError, match=r"^loads\.force\[0\]\.region: unknown region 'lid'; the mesh's regions: "
                                         r"'left' \(id 1, volume\)"):
        Scene.from_dict(_scene_dict(loads={"force": [{"region": "lid", "value": [0, 0, 1.0]}]}))


def test_probes_on_regions_report_the_mean_displacement(bar):
    probes = [Probe("tip", None, region="tip"), Probe("corner", None, region="corner"),
              Probe("low_tip", None, region="tip", box=((0, -1, -1), (2, 0.1, 1))),
              Probe("node", (L, W, W))]
    model = _model(bar, probes=probes)
    u = np.arange(bar.n_points * 3, dtype=float) / 7.0
    U = u.reshape(-1, 3)
    values = model.probe_values(u)
    tip = np.flatnonzero(bar.points[:, 0] == L)
    assert values["tip"] == pytest.approx(U[tip].mean(axis=0).tolist())
    assert values["corner"] == pytest.approx(U[_node(bar.points, (L, W, W))].tolist()) == values["node"]
    low = tip[bar.points[tip, 1] <= 0.1]
    assert values["low_tip"] == pytest.approx(U[low].mean(axis=0).tolist())


def _scene_dict(file="bar.msh", **extra):
    d = {"mesh": {"file": file}, "material": [{"region": "left", "E": 1e6, "nu": 0.3, "law": "hooke"},
                                             {"region": 2, "E": 2e6, "nu": 0.3, "law": "hooke"}],
         "fixed": [{"region": "clamp"}]}
    d.update(extra)
    return d


@pytest.fixture(autouse=True)
def _in_bar_folder(bar_file, monkeypatch):
    monkeypatch.chdir(bar_file.parent)


def test_scene_keys_and_their_errors(bar_file):
    scene = Scene.from_dict(_scene_dict(probe=[{"name": "tip", "region": "tip"}],
                                        loads={"traction": [{"region": "tip", "value": [0, 0, -1.0]}]}),
                            base_dir=bar_file.parent)
    assert scene.fixed[0].region == "clamp" and scene.fixed[0].box is None
    assert scene.probes[0].region == "tip" and scene.probes[0].point is None
    cases = [
        ({"fixed": [{"displacement": [0, 0, 0]}]}, r"^fixed\[0\]\.box: missing .*region"),
        ({"fixed": [{"region": True}]}, r"^fixed\[0\]\.region: expected a region name"),
        ({"fixed": [{"region": ""}]}, r"^fixed\[0\]\.region: expected a region name"),
        ({"fixed": [{"region": "lid"}]}, r"^fixed\[0\]\.region: unknown region 'lid'; the mesh's regions: 'left'"),
        ({"fixed": [{"region": "clamp", "box": [[5, 5, 5], [6, 6, 6]]}]},
         r"^fixed\[0\]: region 'clamp' has no node inside its box"),
        ({"probe": [{"name": "p", "point": [1, 0, 0], "region": "tip"}]}, r"^probe\[0\]\.region: give either point"),
        ({"probe": [{"name": "p"}]}, r"^probe\[0\]\.point: missing \(or give region"),
        ({"probe": [{"name": "p", "region": "lid"}]}, r"^probe\[0\]\.region: unknown region 'lid'"),
        ({"loads": {"force": [{"value": [0, 0, 1.0]}]}}, r"^loads\.force\[0\]\.box: missing \(or give region"),
    ]
    for extra, pattern in cases:
        with pytest.raises(SceneError, match=pattern):
            Scene.from_dict(_scene_dict(**extra), base_dir=bar_file.parent)
    # a generated mesh has no named regions: refused while parsing
    with pytest.raises(SceneError, match=r"^material\[0\]\.region: unknown region 'left'; a generated mesh"):
        Scene.from_dict({"mesh": {"generate": "bar"}, "material": [{"region": "left", "E": 1.0, "nu": 0.3}],
                         "fixed": [{"box": [[0, 0, 0], [0, 1, 1]]}]})


def test_region_faces_are_outward_with_the_element_table_node_order(tmp_path):
    for element, ftype, k in (("tetra", "triangle", 3), ("tetra10", "triangle6", 6), ("hexahedron", "quad", 4)):
        mesh = read_mesh(write_bar(tmp_path / f"{element}.msh", element))
        check_mesh(mesh)
        for name, normal in (("tip", (1, 0, 0)), ("clamp", (-1, 0, 0))):
            faces = region_faces(mesh, name)
            assert list(faces) == [ftype] and faces[ftype].shape[1] == k
            x = mesh.points[faces[ftype]]
            n = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
            assert np.allclose(n / np.linalg.norm(n, axis=1)[:, None], normal)
            if k == 6:                              # midside nodes in the middle of the face's edges
                for m, (a, b) in enumerate(((0, 1), (1, 2), (2, 0))):
                    assert np.allclose(x[:, 3 + m], (x[:, a] + x[:, b]) / 2)
            plane = L if name == "tip" else 0.0         # every node on the face's plane, midsides too
            assert region_nodes(mesh, name).tolist() == np.flatnonzero(mesh.points[:, 0] == plane).tolist()
        area = 0.0
        for rows in region_faces(mesh, "left").values():     # a volume group: its part of the body's surface
            x = mesh.points[rows]
            cr = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
            area += np.linalg.norm(cr, axis=1).sum() * (1.0 if rows.shape[1] == 4 else 0.5)
        assert area == pytest.approx(W * W + 4 * 0.5 * W)
        everything = sum(len(r) for r in region_faces(mesh).values())
        assert everything == sum(len(r) for r in region_faces(mesh, box=((-1, -1, -1), (2, 2, 2))).values())


def test_boundary_groups_off_the_surface_are_refused(tmp_path):
    m = generate_bar((L, W, W), (4, 1, 1), "tetra")
    # a triangle between two tets inside the body: a face of two cells
    from tensormass.runtime.mesh.faces import face_table
    ft = face_table(m)
    inner = ft.nodes[np.flatnonzero(ft.count[ft.group] == 2)[0], :3]
    path = write_bar(tmp_path / "inner.msh", extra=[("triangle", inner[None])])
    mesh = read_mesh(path)
    with pytest.raises(MeshError, match=r"^region 'inner' \(id 9, surface\): 1 of its 1 triangle cell\(s\) are not "
                                        r"on the body's surface"):
        check_mesh(mesh)
    with pytest.raises(TensormassError, match=r"region 'inner'"):
        Model.from_scene(Scene.from_dict(_scene_dict(file=str(path))))
    # an edge through the body, and a node inside a (refined) body: also refused
    for extra, what in ((("line", np.array([[_node(m.points, (0, 0, 0)), _node(m.points, (0.25, W, W))]])), "line"),):
        with pytest.raises(MeshError, match=rf"1 of its 1 {what} cell\(s\) are not on the body's surface"):
            check_mesh(read_mesh(write_bar(tmp_path / "edge.msh", extra=[extra])))


def test_cell_sets_and_unnamed_tags():
    """meshio cell_sets (gmsh 4.1 lists every group an entity is in there) and tags without names."""
    m = generate_bar((L, W, W), (2, 1, 1), "tetra")
    cells = m.blocks[0].cells
    tip = np.array(_faces_on(m, 0, L))
    mm = meshio.Mesh(m.points, [("triangle", tip), ("tetra", cells)],
                     cell_data={"gmsh:physical": [np.full(len(tip), 7), np.full(len(cells), 3)]},
                     field_data={"hard": np.array([3, 3])},
                     cell_sets={"stiff_end": [np.zeros(0, int), np.arange(len(cells) // 2)],
                                "gmsh:bounding_entities": [np.zeros(0, int), np.zeros(0, int)]})
    solid = [None, np.arange(len(cells))]
    groups = read_groups(mm, [np.full(len(tip), 7), np.full(len(cells), 3)], solid, [tip, None])
    got = {(g.name, g.id, g.dim): g for g in groups}
    assert set(got) == {(None, 7, 2), ("hard", 3, 3), ("stiff_end", None, 3)}
    assert got[("stiff_end", None, 3)].cell_ids.tolist() == list(range(len(cells) // 2))
    assert got[("hard", 3, 3)].cell_ids.size == len(cells)
    assert got[(None, 7, 2)].cells["triangle"].tolist() == tip.tolist()
    assert Group(None, 7, 2).label == "id 7 (surface)"


@pytest.mark.parametrize("share", [1.0, 0.4])
def test_groups_follow_refinement(bar, share):
    from tensormass.runtime.mesh.refine import refine
    rng = np.random.default_rng(3)
    marked = rng.random(bar.n_cells) < share
    mesh = bar
    for _ in range(2):
        mesh = refine(mesh, np.flatnonzero(marked[:mesh.n_cells]) if share < 1 else np.ones(mesh.n_cells, bool),
                      propagate=True).mesh
    check_mesh(mesh)                                          # the refined groups lie on the surface
    assert mesh.n_cells > bar.n_cells
    groups = {g.name: g for g in mesh.groups}
    x = mesh.points
    for name, plane in (("clamp", 0.0), ("tip", L)):
        nodes = region_nodes(mesh, name)
        assert nodes.tolist() == np.flatnonzero(x[:, 0] == plane).tolist()
        (rows,) = region_faces(mesh, name).values()
        tri = x[rows]
        assert 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum() == \
            pytest.approx(W * W)
    edge = region_nodes(mesh, "edge")
    assert edge.tolist() == np.flatnonzero((x[:, 0] == L) & (x[:, 2] == 0.0)).tolist()
    assert len(groups["edge"].cells["line"]) == edge.size - 1
    centre_x = np.vstack([x[b.cells].mean(axis=1) for b in mesh.blocks])[:, 0]
    assert groups["left"].cell_ids.tolist() == np.flatnonzero(centre_x < 0.5).tolist()
    assert groups["corner"].cells["vertex"].tolist() == [[_node(x, (L, W, W))]]


def test_groups_follow_refinement_in_2d():
    from tensormass.runtime.mesh.refine import refine
    from pathlib import Path
    mesh = read_mesh(Path(__file__).parents[1] / "data" / "msh" / "triangle_v41.msh")
    fine = refine(mesh, np.ones(mesh.n_cells, bool)).mesh
    check_mesh(fine)
    side = region_nodes(fine, "side")
    assert side.tolist() == np.flatnonzero(fine.points[:, 0] == 0.0).tolist() and side.size > region_nodes(mesh, "side").size
    (edges,) = region_faces(fine, "side").values()
    assert np.abs(fine.points[edges[:, 1], 1] - fine.points[edges[:, 0], 1]).sum() == pytest.approx(0.6)


def test_msh2_cells_listed_once_per_group_are_one_cell(tmp_path):
    """MSH 2 writes a cell that is in two physical groups twice (one physical tag per line)."""
    m = generate_bar((L, W, W), (2, 1, 1), "tetra")
    cells = m.blocks[0].cells
    for tags, ok in (((1, 2), True), ((1, 1), False)):
        mm = meshio.Mesh(m.points, [("tetra", cells), ("tetra", cells)],
                         cell_data={"gmsh:physical": [np.full(len(cells), t) for t in tags],
                                    "gmsh:geometrical": [np.full(len(cells), 1)] * 2},
                         field_data={"body": np.array([1, 3]), "soft": np.array([2, 3])})
        path = tmp_path / f"twice{tags[1]}.msh"
        with contextlib.redirect_stdout(io.StringIO()):
            mm.write(path, file_format="gmsh22", binary=False)
        mesh = read_mesh(path)
        if not ok:                                # the same cell twice in one group: overlapping cells
            with pytest.raises(MeshError, match="overlapping"):
                check_mesh(mesh)
            continue
        check_mesh(mesh)
        assert [(b.type, len(b)) for b in mesh.blocks] == [("tetra", len(cells))]
        groups = {g.name: g for g in mesh.groups}
        assert groups["body"].cell_ids.tolist() == groups["soft"].cell_ids.tolist() == list(range(len(cells)))
        which = assign_materials(mesh, [Material(region="soft"), Material(region="body")])
        assert np.concatenate(which).tolist() == [0] * len(cells)
        which = assign_materials(mesh, [Material(region=2), Material(region="body")])
        assert np.concatenate(which).tolist() == [0] * len(cells)


def test_2d_curve_groups_carry_tractions():
    from pathlib import Path
    data = Path(__file__).parents[1] / "data" / "msh"
    for name, ftype in (("triangle6_v41.msh", "line3"), ("quad_v22b.msh", "line"), ("triangle_v41.msh", "line")):
        mesh = read_mesh(data / name)
        faces = region_faces(mesh, "side")
        assert list(faces) == [ftype]
        x = mesh.points[faces[ftype]]
        assert np.all(x[:, :, 0] == 0.0) and np.all(x[:, 1, 1] < x[:, 0, 1])   # x = 0, body on the left: downwards
        model = Model(mesh, [Material(law="hooke", E=1e6, nu=0.3)],
                      fixed=[Fixed(box=((1.0, -1.0), (1.0, 1.0)))],
                      loads=Loads(gravity=(0.0, 0.0), nodal=[NodalLoad(box=None, force=(-3.0, 2.0), kind="traction",
                                                                      region="side")]))
        f = model.f_ext.reshape(-1, 2)
        assert f.sum(axis=0) == pytest.approx([-3.0 * 0.6, 2.0 * 0.6])
        assert np.allclose(np.delete(f, region_nodes(mesh, "side"), axis=0), 0.0)


# every documented way to place a load: box alone, region alone, region and box (issue: a pressure on a
# region without a box crashed in the scene check)
_TIP_BOX = [[L - 1e-9, -1, -1], [L + 1e-9, 1, 1]]
_LOW_TIP_BOX = [[L - 1e-9, -1, -1], [L + 1e-9, 1, 0.1]]       # the tip's faces reaching z <= 0.1 only: none whole


@pytest.mark.parametrize("kind, value", [("force", [0.0, 0.0, -1.0]), ("traction", [0.0, 0.0, -1.0]),
                                         ("pressure", 10.0)])
@pytest.mark.parametrize("where", ["box", "region", "region and box"])
def test_every_load_kind_by_box_region_or_both(bar_file, kind, value, where):
    load = {"value": value}
    if "box" in where:
        load["box"] = _TIP_BOX
    if "region" in where:
        load["region"] = "tip"
    scene = Scene.from_dict(_scene_dict(loads={kind: [load]}), base_dir=bar_file.parent)
    summary = Simulation(scene).run()
    assert summary.status == "ok", summary.message
    model = Model.from_scene(scene)
    if kind == "pressure":
        loaded = np.unique(np.concatenate([faces.ravel() for faces, _ in model.pressure.groups.values()]))
    else:
        loaded = np.flatnonzero(np.abs(model.f_ext.reshape(-1, 3)).sum(axis=1))
    assert loaded.size and np.allclose(model.mesh.points[loaded, 0], L)      # the tip's nodes only


@pytest.mark.parametrize("kind, value", [("traction", [0.0, 0.0, -1.0]), ("pressure", 10.0)])
def test_a_face_load_whose_region_has_no_face_in_its_box_is_refused(bar_file, kind, value):
    load = {"value": value, "region": "tip", "box": _LOW_TIP_BOX}
    with pytest.raises(SceneError, match=rf"^loads\.{kind}\[0\]: region 'tip' has no boundary face inside its box"):
        Scene.from_dict(_scene_dict(loads={kind: [load]}), base_dir=bar_file.parent)

