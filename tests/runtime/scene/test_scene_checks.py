"""Scene checks that used to pass silently or with a misleading message (issue 10, items 5 and 9)."""
from __future__ import annotations

import copy
import math

import meshio
import numpy as np
import pytest

from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.mesh.container import MeshError
from tensormass.runtime.mesh.checks import check_coordinates, check_mesh
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.mesh.io import to_meshio
from tensormass.runtime.scene.parser import MAX_STEPS
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.base.errors import SceneError

BASE = {
    "mesh": {"generate": "bar", "size": [1.0, 0.2, 0.2], "cells": [4, 1, 1], "element": "hexahedron"},
    "material": [{"region": "all", "law": "stvk", "E": 1e6, "nu": 0.3}],
    "fixed": [{"box": [[-1e-9, -1, -1], [1e-9, 1, 1]]}],
    "solver": {"kind": "static", "steps": 1},
}


def scene(**changes):
    data = copy.deepcopy(BASE)
    data.update(copy.deepcopy(changes))
    return Scene.from_dict(data)


def file_scene(tmp_path, points_change):
    """A scene reading a 4-hex bar from a VTU file whose points were changed."""
    mesh = generate_bar((1.0, 0.2, 0.2), (4, 1, 1))
    points_change(mesh.points)
    path = tmp_path / "bar.vtu"
    meshio.write(path, to_meshio(mesh))
    data = copy.deepcopy(BASE)
    data["mesh"] = {"file": str(path)}
    return data


# ------------------------------------------------------------------------------ solver.steps


def test_steps_as_a_toml_float_says_what_is_wrong():
    text = ('[mesh]\ngenerate = "bar"\n[[material]]\nE = 1e6\nnu = 0.3\n[[fixed]]\n'
            'box = [[0, 0, 0], [0, 1, 1]]\n[solver]\nsteps = 1e12\n')
    with pytest.raises(SceneError) as info:
        Scene.from_string(text)
    message = str(info.value)
    assert message.startswith("solver.steps: expected an integer, got float 1e+12")
    assert "TOML reads numbers with an exponent" in message and "above the limit of 100,000,000" in message
    with pytest.raises(SceneError, match=r"got float 2 \(TOML reads .* as floats: write 2\)"):
        Scene.from_string(text.replace("1e12", "2.0"))


def test_absurd_step_counts_are_refused():
    with pytest.raises(SceneError, match=r"^solver\.steps: must be <= 100,000,000 \(got 1,000,000,000,000\): "):
        scene(solver={"kind": "static", "steps": 10 ** 12})
    assert scene(solver={"kind": "static", "steps": MAX_STEPS}).solver.steps == MAX_STEPS


# ------------------------------------------------------------------------------ coordinates


def test_nan_coordinate_in_a_mesh_file_names_the_node(tmp_path):
    def poison(points):
        points[3, 1] = math.nan
    with pytest.raises(SceneError) as info:
        Scene.from_dict(file_scene(tmp_path, poison))
    message = str(info.value)
    assert message.startswith("mesh.file: non-finite (NaN/Inf) coordinates at nodes [3] (1 node): node 3")
    assert "no mesh node inside" not in message


def test_huge_coordinates_are_called_too_large_not_degenerate(tmp_path):
    def blow_up(points):
        points *= 1e200
    with pytest.raises(SceneError, match=r"^mesh\.file: coordinates too large: node \d+ is at \(1e\+200"):
        Scene.from_dict(file_scene(tmp_path, blow_up))
    with pytest.raises(SceneError, match=r"^mesh\.size\[0\]: coordinates too large"):
        scene(mesh={"generate": "bar", "size": [1e200, 0.2, 0.2], "cells": [4, 1, 1]})
    with pytest.raises(SceneError, match=r"^mesh\.origin\[2\]: coordinates too large"):
        scene(mesh={"generate": "bar", "origin": [0.0, 0.0, 1e300], "cells": [4, 1, 1]})


def test_check_mesh_and_tiny_meshes():
    mesh = generate_bar()
    mesh.points[5] = [math.inf, 0.0, 0.0]
    with pytest.raises(MeshError, match=r"NaN/Inf.*\[5\].*node 5 is at \(inf, 0, 0\)"):
        check_mesh(mesh)
    with pytest.raises(MeshError, match="mesh too small"):
        check_coordinates(generate_bar().points * 1e-60)
    check_coordinates(generate_bar().points * 1e-30)            # small, but fine


# ------------------------------------------------------------------------------ probes


def test_probe_far_outside_the_body_is_refused():
    with pytest.raises(SceneError) as info:
        scene(probe=[{"name": "tip", "point": [101.0, 0.1, 0.1]}])
    message = str(info.value)
    assert message.startswith("probe[0].point: probe 'tip' at [101, 0.1, 0.1] is not on the body: it is 100 m "
                              "outside it (from the nearest boundary face; nearest node")
    assert "within 10% of the nearest cell's size" in message


def test_probes_on_or_near_the_body_are_accepted_and_beyond_the_tolerance_refused():
    # cells 0.25 x 0.2 x 0.2 m: the tolerance is 10 % of their diagonal, 0.0377 m
    ok = scene(probe=[{"name": "tip", "point": [1.0, 0.1, 0.1]}, {"name": "near", "point": [1.03, 0.1, 0.1]}])
    assert [p.name for p in ok.probes] == ["tip", "near"]
    with pytest.raises(SceneError, match=r"^probe\[1\]\.point: probe 'off' at \[1\.05, 0\.1, 0\.1\] is not on the "
                                         r"body: it is 0\.05 m outside"):
        scene(probe=[{"name": "tip", "point": [1.0, 0.1, 0.1]}, {"name": "off", "point": [1.05, 0.1, 0.1]}])
    # the centre of a single big cell is far from every node, but on the body
    one = scene(mesh={"generate": "bar", "size": [1.0, 1.0, 1.0], "cells": [1, 1, 1]},
                probe=[{"name": "centre", "point": [0.5, 0.5, 0.5]}])
    assert one.probes[0].name == "centre"


# ------------------------------------------------------------------------------ [[fixed]]


def test_conflicting_fixed_entries_are_refused_naming_both():
    clamp = {"box": [[-1e-9, -1, -1], [0.3, 1, 1]]}
    pull = {"box": [[0.2, -1, -1], [0.3, 1, 1]], "displacement": [0.01, 0.0, 0.0]}
    with pytest.raises(SceneError) as info:
        scene(fixed=[clamp, pull])
    message = str(info.value)
    assert message.startswith("fixed[1]: prescribes component 0 = 0.01 at node")
    assert "where fixed[0] prescribes 0" in message


def test_compatible_fixed_entries_are_accepted():
    clamp = {"box": [[-1e-9, -1, -1], [1e-9, 1, 1]]}
    same = {"box": [[-1e-9, -1, -1], [0.3, 1, 1]], "displacement": [0.0, 0.0, 0.0]}
    other = {"box": [[-1e-9, -1, -1], [0.3, 1, 1]], "displacement": [0.0, 0.0, 0.0]}
    assert len(scene(fixed=[clamp, same, other]).fixed) == 3
    x_only = {"box": [[0.2, -1, -1], [1.0, 1, 1]], "displacement": [0.01, 0.0, 0.0], "components": [0]}
    z_only = {"box": [[0.2, -1, -1], [1.0, 1, 1]], "displacement": [0.0, 0.0, -0.02], "components": [2]}
    assert len(scene(fixed=[clamp, x_only, z_only]).fixed) == 3


def test_model_refuses_conflicting_constraints_too():
    from tensormass.runtime.model.model import Model
    from tensormass.runtime.scene.types import Fixed, Material
    mesh = generate_bar((1.0, 0.2, 0.2), (4, 1, 1))
    fixed = [Fixed(box=((-1, -1, -1), (0.3, 1, 1))),
             Fixed(box=((0.2, -1, -1), (0.3, 1, 1)), displacement=(0.0, 0.0, 0.5), components=(2,))]
    with pytest.raises(TensormassError, match=r"fixed\[1\]: prescribes component 2 = 0.5 .* where fixed\[0\]"):
        Model(mesh, [Material(E=1e6, nu=0.3)], fixed=fixed)


# ------------------------------------------------------------------------------ materials


def test_material_shadowed_by_an_earlier_one_is_refused():
    soft = {"region": "all", "law": "stvk", "E": 1e6, "nu": 0.3}
    stiff = {"region": "all", "box": [[0.5, -1, -1], [2, 1, 1]], "law": "stvk", "E": 1e8, "nu": 0.3}
    with pytest.raises(SceneError, match=r"^material\[1\]: no cell uses it: every cell it matches is taken by "
                                         r"material\[0\] \(first match wins\)"):
        scene(material=[soft, stiff])
    assert len(scene(material=[stiff, soft]).materials) == 2         # the other order uses both


def test_material_matching_no_cell_is_refused():
    wrong_type = {"region": "tetra", "law": "stvk", "E": 1e8, "nu": 0.3}
    rest = {"region": "all", "law": "stvk", "E": 1e6, "nu": 0.3}
    with pytest.raises(SceneError, match=r"^material\[0\]: no cell uses it: no cell matches its region 'tetra' "
                                         r"\(the mesh has hexahedron cells, no tags\)"):
        scene(material=[wrong_type, rest])
    outside = dict(rest, box=[[5, 5, 5], [6, 6, 6]])
    with pytest.raises(SceneError, match=r"^material\[0\]: no cell uses it: no cell matches its region 'all' and box"):
        scene(material=[outside, rest])


def test_every_example_uses_every_material():
    """The checks above must not refuse the shipped examples (they load their meshes here)."""
    from pathlib import Path
    for path in sorted((Path(__file__).resolve().parents[3] / "examples").glob("*.toml")):
        scene_ = Scene.from_toml(path)
        used = {int(i) for w in scene_.assign_materials() for i in np.unique(w)}
        assert used == set(range(len(scene_.materials))), path.name
