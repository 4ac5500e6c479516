"""examples/organ/ (#12): a gmsh-made organ whose scene selects everything by the mesh's physical
groups; it reads, passes the mesh checks and runs, and its region loads, constraints and probes are
what the groups say."""
import re
from pathlib import Path

import numpy as np
import pytest

from tensormass.runtime.assembly.loads import body_force, measure_weights, shape_table
from tensormass.runtime.mesh.checks import check_mesh
from tensormass.runtime.mesh.io import read_mesh
from tensormass.runtime.model.model import Model
from tensormass.runtime.mesh.regions import region_faces, region_nodes
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.run.simulation import Simulation

ORGAN = Path(__file__).resolve().parents[3] / "examples" / "organ"
GETTING_STARTED = Path(__file__).resolve().parents[3] / "docs" / "getting-started.md"
A, B, C = 0.040, 0.030, 0.030


def test_the_organ_mesh_and_its_groups():
    assert (ORGAN / "organ.msh").stat().st_size < 300_000
    mesh = read_mesh(ORGAN / "organ.msh")
    check_mesh(mesh)                                 # tetra10 from gmsh: positive, conforming, groups on the surface
    assert mesh.cell_types() == ["tetra10"] and 300 <= mesh.n_cells <= 2000
    groups = {g.name: (g.id, g.dim) for g in mesh.groups}
    assert groups == {"organ": (1, 3), "attached": (2, 2), "loaded": (3, 2)}
    assert np.allclose(mesh.points.min(axis=0), [-A, -B, 0.0], atol=1e-3)
    assert np.allclose(mesh.points.max(axis=0), [A, B, C], atol=1e-3)
    attached = region_nodes(mesh, "attached")
    assert np.all(mesh.points[attached, 2] == 0.0)
    assert attached.size == np.count_nonzero(mesh.points[:, 2] == 0.0)
    loaded = region_nodes(mesh, "loaded")
    r = np.hypot(mesh.points[loaded, 0], mesh.points[loaded, 1])
    assert np.all(r <= 0.012 + 1e-5) and np.all(mesh.points[loaded, 2] > 0.8 * C)


def _area(mesh, region) -> float:
    """Flat-facet area of a region's faces (corners)."""
    (rows,) = region_faces(mesh, region).values()
    x = mesh.points[rows[:, :3]]
    return 0.5 * float(np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1).sum())


def _curved_area(mesh, region) -> float:
    """Area of a region's curved triangle6 faces: the face Jacobian at the shape table's points."""
    (rows,) = region_faces(mesh, region).values()
    return float(measure_weights(mesh.points[rows], shape_table("triangle6")).sum())


def test_the_organ_scene_loads_and_constraints_follow_the_groups():
    scene = Scene.from_toml(ORGAN / "scene.toml")
    model = Model.from_scene(scene)
    mesh = model.mesh
    fixed_nodes = np.unique(model.fixed_dofs // 3)
    assert fixed_nodes.tolist() == region_nodes(mesh, "attached").tolist()
    f = model.f_ext.reshape(-1, 3)
    loaded = region_nodes(mesh, "loaded")
    # consistent gravity: int N rho g dV over the organ's cells (runtime.assembly.loads, checked in test_loads)
    (cells,) = [b.cells for b in mesh.blocks]
    gravity = body_force(mesh.points, {"tetra10": cells}, {"tetra10": 1050.0}, (0.0, 0.0, -9.81))
    weight = model.mass.reshape(-1, 3)[:, 2].sum() * -9.81
    assert gravity[:, 2].sum() == pytest.approx(weight, rel=1e-12)
    area = _curved_area(mesh, "loaded")
    # 19 coarse curved faces: their flat facets (corners only) miss ~8 % of the cap's area
    assert _area(mesh, "loaded") < area < 1.1 * _area(mesh, "loaded")
    assert f[:, 2].sum() == pytest.approx(weight - 400.0 * area, rel=1e-12)
    assert np.allclose(f[:, :2], 0.0)
    extra = f[:, 2] - gravity[:, 2]                  # the traction alone: on the loaded nodes only
    assert np.allclose(np.delete(extra, loaded), 0.0, atol=1e-15)       # (curved triangle6 corners take ~0, either sign)
    assert extra[loaded].sum() == pytest.approx(-400.0 * area, rel=1e-12)
    assert model.probes["loaded"].nodes.tolist() == loaded.tolist()


def test_the_organ_scene_runs():
    scene = Scene.from_toml(ORGAN / "scene.toml")
    sim = Simulation(scene, output=False)
    summary = sim.run()
    assert summary.status == "ok"
    u = sim.displacement
    loaded = region_nodes(sim.model.mesh, "loaded")
    assert summary.probes["loaded"] == pytest.approx(u[loaded].mean(axis=0).tolist())
    assert summary.probes["loaded"][2] < -1e-4 and summary.probes["pole"][2] < summary.probes["loaded"][2] * 0.5
    assert np.abs(u[region_nodes(sim.model.mesh, "attached")]).max() == 0.0
    # the number the getting-started page states is this run's
    stated = re.search(r"examples/organ/scene.toml .*the pole sinks ([0-9.]+) mm", GETTING_STARTED.read_text())
    assert stated and float(stated.group(1)) == pytest.approx(-1e3 * summary.probes["pole"][2], abs=0.005)


def test_make_organ_makes_the_shipped_mesh(tmp_path):
    pytest.importorskip("gmsh")
    import importlib.util
    spec = importlib.util.spec_from_file_location("make_organ", ORGAN / "make_organ.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    new, old = read_mesh(module.make(tmp_path / "organ.msh")), read_mesh(ORGAN / "organ.msh")
    assert [(b.type, len(b)) for b in new.blocks] == [(b.type, len(b)) for b in old.blocks]
    assert [(g.name, g.id, g.dim, g.n_cells()) for g in new.groups] == [(g.name, g.id, g.dim, g.n_cells()) for g in old.groups]
    assert np.allclose(new.points, old.points)


def test_the_tool_scene_moves_the_cap_along_its_path():
    # examples/organ/tool.toml: the "loaded" cap follows the press/slide tables (first 3 steps here)
    scene = Scene.from_toml(ORGAN / "tool.toml")
    scene.solver.steps = 3
    sim = Simulation(scene, output=False)
    summary = sim.run()
    assert summary.status == "ok"
    cap = region_nodes(sim.model.mesh, "loaded")
    t = 3 * scene.solver.dt                           # press: 0 -> 1 over 0.3 s, slide still 0
    assert np.allclose(sim.displacement.reshape(-1, 3)[cap], [0.0, 0.0, -0.006 * t / 0.3], atol=1e-15)
