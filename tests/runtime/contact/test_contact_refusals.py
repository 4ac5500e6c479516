"""Scenes with contact that cannot run are refused before anything runs, each with a message that
names the key or obstacle and what to do (SceneError from the parser, TensormassError from the model)."""
from __future__ import annotations

import re

import meshio
import numpy as np
import pytest

from tensormass.apps.cli import main
from tensormass.runtime.base.errors import SceneError, TensormassError

from contact_scenes import bar, model_of

PLATE = {"name": "plate", "shape": "plane", "point": [0.05, 0.05, 0.105], "normal": [0, 0, -1]}
# a closed tetrahedral surface (4 triangles wound outward) above the bar's top face
TETRA_V = np.array([[0.0, 0.0, 0.2], [0.1, 0.0, 0.2], [0.0, 0.1, 0.2], [0.0, 0.0, 0.3]])
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def _refused(data, error=TensormassError) -> str:
    with pytest.raises(error) as info:
        model_of(data)
    return str(info.value)


@pytest.mark.parametrize("dhat", [0.0, -1e-3])
def test_dhat_not_positive(dhat):
    assert _refused(bar([PLATE], contact={"dhat": dhat}), SceneError) == f"contact.dhat: must be > 0 (got {dhat:g})"


def test_negative_friction():
    assert _refused(bar([PLATE], contact={"mu": -0.1}), SceneError) == "contact.mu: must be >= 0 (got -0.1)"


def test_unknown_keys():
    message = _refused(bar([PLATE], contact={"dhatt": 0.1}), SceneError)
    assert message.startswith("contact.dhatt: unknown key; allowed keys in [contact]: method, dhat,")
    message = _refused(bar([dict(PLATE, colour=1.0)]), SceneError)
    assert message.startswith("obstacle[0].colour: unknown key; allowed keys in [obstacle]: name, shape,")
    # a key of another shape: named with the keys this shape takes
    assert _refused(bar([dict(PLATE, radius=1.0)]), SceneError) == (
        "obstacle[0].radius: not a key of a plane obstacle (it takes point, normal, and name, translation, "
        "rotation, amplitude)")


def test_unknown_or_missing_shape():
    assert _refused(bar([dict(PLATE, shape="cone")]), SceneError) == (
        "obstacle[0].shape: unknown value 'cone'; allowed: plane, sphere, capsule, box, mesh")
    assert _refused(bar([{"name": "x", "point": [0, 0, 1]}]), SceneError) == (
        "obstacle[0].shape: missing (plane, sphere, capsule, box, mesh)")


@pytest.mark.parametrize("table, missing, needs", [
    ({"shape": "plane", "point": [0, 0, 1]}, "normal", "point, normal"),
    ({"shape": "sphere", "center": [0, 0, 1]}, "radius", "center, radius"),
    ({"shape": "capsule", "a": [0, 0, 1], "radius": 0.1}, "b", "a, b, radius"),
    ({"shape": "box"}, "box", "box"),
    ({"shape": "mesh"}, "file", "file"),
])
def test_missing_keys_of_each_shape(table, missing, needs):
    assert _refused(bar([table]), SceneError) == (
        f"obstacle[0].{missing}: missing (a {table['shape']} obstacle needs {needs})")


def test_penalty_refuses_a_mesh_obstacle_and_self_contact(tmp_path):
    path = tmp_path / "tool.obj"
    meshio.write(str(path), meshio.Mesh(TETRA_V, [("triangle", TETRA_F)]))
    tool = {"name": "tool", "shape": "mesh", "file": str(path)}
    assert model_of(bar([tool])).contact.method == "ipc"           # the same obstacle: IPC takes it
    assert _refused(bar([tool], contact={"method": "penalty"})) == (
        "obstacle 'tool': contact.method = \"penalty\" takes plane, sphere, capsule and box obstacles (a mesh "
        "obstacle has no exact distance); use contact.method = \"ipc\"")
    message = _refused(bar([PLATE], contact={"method": "penalty", "self": True}), SceneError)
    assert message.startswith("contact.self: an IPC setting; penalty contact")


@pytest.mark.parametrize("kind, dt", [("explicit", 1e-5), ("generalized_alpha", 1e-3), ("implicit_euler", 1e-3)])
def test_ipc_refused_by_integrators_without_a_newton_solve(kind, dt):
    solver = {"kind": kind, "steps": 1, "dt": dt}
    assert _refused(bar([PLATE], solver=solver)) == (
        f"contact.method = 'ipc' does not work with solver.kind = '{kind}' (it takes 'penalty'); 'ipc' runs "
        "with static, backward_euler")
    assert model_of(bar([PLATE], contact={"method": "penalty"}, solver=solver)).contact.method == "penalty"


@pytest.mark.parametrize("faces, open_edges, many", [(TETRA_F[:3], 3, 0), (np.vstack([TETRA_F, TETRA_F[3:]]), 0, 3)])
def test_open_or_non_manifold_obstacle_mesh(tmp_path, faces, open_edges, many):
    path = tmp_path / "tool.obj"
    meshio.write(str(path), meshio.Mesh(TETRA_V, [("triangle", faces)]))
    assert _refused(bar([{"name": "tool", "shape": "mesh", "file": str(path)}]), SceneError) == (
        f"obstacle 'tool' ({path}): the surface must be closed and manifold (every edge in exactly two "
        f"triangles); {open_edges} open edge(s), {many} edge(s) in more than two")


@pytest.mark.parametrize("method", ["ipc", "penalty"])
def test_obstacle_intersecting_the_body_at_rest(method):
    """Named with the surface nodes inside it (the bar's top face: z = 0.1)."""
    sunk = dict(PLATE, point=[0.05, 0.05, 0.08])
    message = _refused(bar([sunk], contact={"method": method}))
    nodes = re.search(r"nodes ([\d, ]+) \.\.\. are inside it", message)
    assert message.startswith("obstacle 'plate' intersects the body at rest; nodes ") and nodes
    model = model_of(bar())
    top = [int(n) for n in nodes.group(1).split(", ")]
    assert len(top) == 5 and np.allclose(np.asarray(model.mesh.points)[top, 2], 0.1)
    ball = {"name": "ball", "shape": "sphere", "center": [0.1, 0.1, 0.1], "radius": 0.02}
    corner = int(np.argmin(np.linalg.norm(np.asarray(model.mesh.points) - 0.1, axis=1)))
    assert f"obstacle 'ball' intersects the body at rest; nodes {corner} are inside it" in _refused(
        bar([ball], contact={"method": method}))


def test_obstacle_crossing_the_body_with_no_node_inside_is_refused_too(tmp_path):
    """A thin slab through the bar between node layers (IPC's triangle test), and a mesh obstacle
    holding a corner (its winding number)."""
    slab = {"name": "slab", "shape": "box", "box": [[-0.1, -0.1, 0.06], [0.2, 0.2, 0.07]]}
    assert _refused(bar([slab])) == ("obstacle 'slab' intersects the body at rest: move it clear of the body "
                                     "(contact cannot start from an intersecting state)")
    path = tmp_path / "tool.obj"
    meshio.write(str(path), meshio.Mesh(TETRA_V - [0.02, 0.02, 0.15], [("triangle", TETRA_F)]))
    message = _refused(bar([{"name": "tool", "shape": "mesh", "file": str(path)}]))
    assert message.startswith("obstacle 'tool' intersects the body at rest; nodes ")


def test_contact_with_a_cut():
    cut = [{"step": 1, "plane": [[0.05, 0, 0], [1.0, 0, 0]]}]
    assert _refused(bar([PLATE], cut=cut), SceneError) == (
        "contact: cannot be combined with [[cut]] (a contact surface that changes during the run is not supported)")


SCENE = """name = "sunk"
[mesh]
generate = "bar"
size = [0.1, 0.1, 0.1]
cells = [2, 2, 2]
element = "tetra"
[[material]]
law = "hooke"
quadrature = "gauss1"
E = 1e5
nu = 0.3
[[fixed]]
box = [[-1, -1, -1e-9], [1, 1, 1e-9]]
[[obstacle]]
name = "plate"
shape = "plane"
point = [0.05, 0.05, 0.08]
normal = [0, 0, -1]
[solver]
kind = "static"
steps = 1
"""


def test_cli_refuses_an_intersecting_obstacle_with_exit_2_and_writes_nothing(tmp_path, capsys):
    scene = tmp_path / "sunk.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == 2
    assert "obstacle 'plate' intersects the body at rest" in capsys.readouterr().err
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["sunk.toml"]
    # the same scene with the plate clear of the body runs
    scene.write_text(SCENE.replace("0.08]", "0.105]"))
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == 0 and out.is_dir()
