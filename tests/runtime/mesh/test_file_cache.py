"""Mesh files read and checked once (runtime.mesh.file_cache): the second load of the same bytes comes
from the user cache with the same mesh and the same run, other bytes miss, a damaged entry is read
again, a mesh that fails its checks is never kept, and a cache that cannot be written changes nothing."""
import shutil
from pathlib import Path

import meshio
import numpy as np
import pytest

from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.mesh import file_cache
from tensormass.runtime.run.simulation import Simulation
from tensormass.runtime.scene.mesh_source import scene_mesh
from tensormass.runtime.scene.scene import Scene

FIXTURE = Path(__file__).parents[1] / "data" / "msh" / "hex_wedge_v41.msh"     # groups "body" and "side"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """The mesh cache in a folder of its own (the kernels stay in the usual cache)."""
    where = tmp_path / "meshes"
    monkeypatch.setattr(file_cache, "folder", lambda: where)
    return where


def _scene(path) -> Scene:
    return Scene.from_dict({"mesh": {"file": str(path)},
                            "material": [{"region": "body", "law": "hooke", "quadrature": "gauss2", "E": 1e5, "nu": 0.3}],
                            "fixed": [{"region": "side"}], "loads": {"gravity": [0.0, 0.0, -9.81]},
                            "output": {"fields": []}})


def _same(a, b):
    assert np.array_equal(a.points, b.points)
    assert [(x.type, x.cells.tolist(), None if x.tags is None else x.tags.tolist()) for x in a.blocks] == \
        [(y.type, y.cells.tolist(), None if y.tags is None else y.tags.tolist()) for y in b.blocks]
    assert [(g.name, g.id, g.dim, g.cell_ids.tolist(), {t: c.tolist() for t, c in g.cells.items()}) for g in a.groups] == \
        [(g.name, g.id, g.dim, g.cell_ids.tolist(), {t: c.tolist() for t, c in g.cells.items()}) for g in b.groups]


def test_the_second_load_of_the_same_bytes_comes_from_the_cache_and_runs_alike(tmp_path, cache):
    path = tmp_path / "mesh.msh"
    shutil.copy(FIXTURE, path)
    read = scene_mesh(_scene(path))
    assert not getattr(read, "checked", False) and len(list(cache.glob("*.npz"))) == 1
    loaded = scene_mesh(_scene(path))
    assert loaded.checked is True and loaded.groups and len(loaded.blocks) == 2
    _same(read, loaded)
    runs = []
    for _ in range(2):
        sim = Simulation(_scene(path), output=False)
        assert sim.run().status == "ok"
        runs.append(sim.ctx.u.copy())
    assert np.array_equal(runs[0], runs[1])


def test_other_bytes_miss_and_a_damaged_entry_is_read_again(tmp_path, cache):
    path = tmp_path / "mesh.msh"
    shutil.copy(FIXTURE, path)
    scene_mesh(_scene(path))
    text = path.read_text()
    path.write_text(text.replace("\n2 0.5 0 0 0 \n", "\n2 0.5 0 0 0  \n", 1))      # one byte more, same mesh
    assert path.read_text() != text
    assert file_cache.load(path) is None
    scene_mesh(_scene(path))
    entries = sorted(cache.glob("*.npz"))
    assert len(entries) == 2
    for entry in entries:
        entry.write_bytes(b"not an npz file")
    assert file_cache.load(path) is None                 # damaged: removed, and the file is read again
    assert len(list(cache.glob("*.npz"))) == 1
    assert not getattr(scene_mesh(_scene(path)), "checked", False) and file_cache.load(path).checked


def test_a_mesh_that_fails_its_checks_is_never_kept(tmp_path, cache):
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    path = tmp_path / "inverted.vtu"
    meshio.write(str(path), meshio.Mesh(points, [("tetra", np.array([[0, 2, 1, 3]]))]))
    data = {"mesh": {"file": str(path)}, "material": [{"law": "hooke", "E": 1e5, "nu": 0.3}],
            "fixed": [{"box": [[-1, -1, -1e-9], [2, 2, 1e-9]]}]}
    for _ in range(2):
        with pytest.raises(TensormassError, match="inverted cells"):
            scene_mesh(Scene.from_dict(data))
    assert not cache.exists() or not list(cache.glob("*.npz"))


def test_a_cache_that_cannot_be_written_only_means_reading_again(tmp_path, monkeypatch):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    monkeypatch.setattr(file_cache, "folder", lambda: blocker / "meshes")
    path = tmp_path / "mesh.msh"
    shutil.copy(FIXTURE, path)
    for _ in range(2):
        assert not getattr(scene_mesh(_scene(path)), "checked", False)


def test_only_the_mesh_as_read_is_kept(tmp_path, cache):
    """A caller that changes the mesh it read, or puts another in its place (report accuracy refines a
    file's mesh and raises it to tetra10), before the checks: that mesh is checked, not kept under the
    file's bytes; the next load reads the file again and gives the mesh as read."""
    path = tmp_path / "mesh.msh"
    shutil.copy(FIXTURE, path)
    scene = _scene(path)
    scene.load_mesh().points[:] *= 2.0                  # changed in place after reading
    scene_mesh(scene)
    other = _scene(path)
    original = other.load_mesh()
    other._mesh = type(original)(original.points * 3.0, original.blocks, original.groups, original.midpoints)
    scene_mesh(other)
    assert not cache.exists() or not list(cache.glob("*.npz"))
    kept = scene_mesh(_scene(path))                      # as read: kept now, and equal to the file's
    assert len(list(cache.glob("*.npz"))) == 1
    _same(kept, file_cache.load(path))
    _same(kept, Scene.from_dict({"mesh": {"file": str(path)}, "material": [{"law": "hooke", "E": 1, "nu": 0.3}],
                                 "fixed": [{"region": "side"}]}).load_mesh())
