"""Shell triangles from files: windings made consistent (runtime.mesh.surfaces.orient_triangles) or
refused (check_mesh), duplicated cells refused."""
import numpy as np
import pytest

from tensormass.runtime.mesh import surfaces
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.mesh.container import CellBlock, Mesh, MeshError
from tensormass.runtime.mesh.checks import check_mesh
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.run.simulation import Simulation


def _every_third_turned(T):
    return np.where((np.arange(len(T)) % 3 == 0)[:, None], T[:, ::-1], T)


def test_a_closed_surface_is_wound_outward_whatever_its_file_says():
    P, T = surfaces.icosphere(1.0, 2)
    mixed = np.where((np.random.default_rng(0).random(len(T)) < 0.3)[:, None], T[:, ::-1], T)
    for given in (mixed, T[:, ::-1]):                         # scattered, and all inside out
        out, notes = surfaces.orient_triangles(P, given)
        assert np.array_equal(out, T)
        assert len(notes) == 1 and "outward (closed surface)" in notes[0]
    out, notes = surfaces.orient_triangles(P, T)
    assert np.array_equal(out, T) and notes == []


def test_an_open_surface_keeps_the_majority_and_pieces_are_oriented_apart():
    P, T = surfaces.plate(1.0, 1.0, 4, 4)
    out, notes = surfaces.orient_triangles(P, _every_third_turned(T))
    assert np.array_equal(out, T) and "majority" in notes[0] and "11 of 32" in notes[0]
    # two plates, one wound down, one mixed: each keeps its own majority
    Q = P + [2.0, 0.0, 0.0]
    both = np.vstack([T[:, ::-1], _every_third_turned(T) + len(P)])
    out, notes = surfaces.orient_triangles(np.vstack([P, Q]), both)
    assert np.array_equal(out[:len(T)], T[:, ::-1]) and np.array_equal(out[len(T):], T + len(P))
    assert len(notes) == 1 and "piece 2 of 2" in notes[0]


def test_a_moebius_strip_is_refused():
    n = 12
    pts = []
    for a in np.linspace(0, 2 * np.pi, n, endpoint=False):
        for s in (-0.2, 0.2):
            pts.append([(1 + s * np.cos(a / 2)) * np.cos(a), (1 + s * np.cos(a / 2)) * np.sin(a), s * np.sin(a / 2)])
    tri = []
    for i in range(n):
        j = (i + 1) % n
        b0, b1 = (2 * j, 2 * j + 1) if j else (1, 0)         # the half twist
        tri += [[2 * i, b0, b1], [2 * i, b1, 2 * i + 1]]
    with pytest.raises(ValueError, match="no consistent winding"):
        surfaces.orient_triangles(np.array(pts), np.array(tri))


def test_check_mesh_refuses_disagreeing_windings_and_duplicated_cells():
    P, T = surfaces.plate(1.0, 1.0, 2, 2)
    check_mesh(Mesh(P, [CellBlock("shell", T)]))
    with pytest.raises(MeshError, match=r"wound against their neighbours.*cell pairs 0-1"):
        check_mesh(Mesh(P, [CellBlock("shell", _every_third_turned(T))]))
    with pytest.raises(MeshError, match=r"duplicated cells.*shell cells 2 and 8"):
        check_mesh(Mesh(P, [CellBlock("shell", np.vstack([T, T[2:3, [1, 2, 0]]]))]))
    bar = generate_bar((1.0, 0.2, 0.2), (2, 1, 1), "tetra")
    twice = np.vstack([bar.blocks[0].cells, bar.blocks[0].cells[3:4]])
    with pytest.raises(MeshError, match=r"duplicated cells.*tetra cells 3 and 12"):
        check_mesh(Mesh(bar.points, [CellBlock("tetra", twice)]))


PLATE = """
[mesh]
file = "{path}"
element = "shell"
[[material]]
law = "cst_dkt"
E = 1.0e7
nu = 0.3
thickness = 0.01
corotational = 0
density = 1000.0
[[fixed]]
box = [[-1, -1, -1], [1e-9, 2, 1]]
[[fixed]]
box = [[0.999999, -1, -1], [2, 2, 1]]
[[fixed]]
box = [[-1, -1, -1], [2, 1e-9, 1]]
[[fixed]]
box = [[-1, 0.999999, -1], [2, 2, 1]]
[[loads.pressure]]
box = [[-1, -1, -1], [2, 2, 1]]
value = 1.0
[solver]
kind = "static"
steps = 1
[[probe]]
name = "centre"
point = [0.5, 0.5, 0.0]
"""


def _plate_file(folder, name, T):
    import meshio
    P, _ = surfaces.plate(1.0, 1.0, 6, 6)
    path = folder / name
    meshio.write(path, meshio.Mesh(P, [("triangle", T)]))
    return path


def _run(path):
    try:
        summary = Simulation(Scene.from_string(PLATE.format(path=path)), output=False).run()
    except TensormassError as exc:
        return exc
    assert summary.status == "ok", summary.message
    return summary


def test_a_plate_file_with_mixed_windings_deflects_like_a_consistent_one(tmp_path):
    """A plate file with every third triangle turned deflected upward at a ninth of the right
    deflection; its triangles are turned to agree when read, and the advice says so."""
    _, T = surfaces.plate(1.0, 1.0, 6, 6)
    right = _run(_plate_file(tmp_path, "plate.vtu", T))
    assert right.probes["centre"][2] < 0 and right.advice == []      # pushed against the +z normal
    mixed = _run(_plate_file(tmp_path, "mixed.vtu", _every_third_turned(T)))
    assert mixed.probes["centre"][2] == pytest.approx(right.probes["centre"][2], rel=1e-9)
    assert any("mesh.file:" in a and "24 of 72 triangles turned" in a for a in mixed.advice)
    duplicated = _run(_plate_file(tmp_path, "twice.vtu", np.vstack([T, T[5:6]])))
    assert isinstance(duplicated, TensormassError) and "duplicated triangles" in str(duplicated)


def test_a_surface_file_is_read_with_its_windings_made_to_agree_and_duplicates_refused(tmp_path):
    """surfaces.read_shell_triangles, the reader for element = "shell" files."""
    _, T = surfaces.plate(1.0, 1.0, 6, 6)
    points, triangles, notes = surfaces.read_shell_triangles(_plate_file(tmp_path, "mixed.vtu", _every_third_turned(T)))
    assert np.array_equal(triangles, T) and len(notes) == 1 and "24 of 72 triangles turned" in notes[0]
    check_mesh(Mesh(points, [CellBlock("shell", triangles)]))
    with pytest.raises(MeshError, match=r"duplicated triangles.*triangles 5 and 72"):
        surfaces.read_shell_triangles(_plate_file(tmp_path, "twice.vtu", np.vstack([T, T[5:6, [2, 0, 1]]])))
