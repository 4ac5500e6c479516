"""Messages name mesh groups by their names: cells without a material are named by the volume group
that holds them ('tumour'), not by the number of its cell tag."""
from __future__ import annotations

import contextlib
import io

import meshio
import numpy as np
import pytest

from tensormass.runtime.base.errors import SceneError
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.scene.scene import Scene


def _write_organ(path, names=True):
    """A 1 x 0.2 x 0.2 tetra bar as gmsh 2.2 with volume groups "healthy" (id 1, x < 0.5) and
    "tumour" (id 2, x > 0.5)."""
    m = generate_bar((1.0, 0.2, 0.2), (4, 1, 1), "tetra")
    (blk,) = m.blocks
    tag = np.where(m.points[blk.cells].mean(axis=1)[:, 0] < 0.5, 1, 2)
    field = {"healthy": np.array([1, 3]), "tumour": np.array([2, 3])} if names else {}
    mesh = meshio.Mesh(m.points, [("tetra", blk.cells)], cell_data={"gmsh:physical": [tag],
                       "gmsh:geometrical": [tag]}, field_data=field)
    with contextlib.redirect_stdout(io.StringIO()):
        mesh.write(path, file_format="gmsh22", binary=False)


def _scene(tmp_path, names=True):
    _write_organ(tmp_path / "organ.msh", names)
    return Scene.from_dict({"mesh": {"file": "organ.msh"},
                            "material": [{"region": "healthy" if names else 1, "E": 3e3, "nu": 0.45,
                                          "law": "neohookean"}],
                            "fixed": [{"box": [[-1, -1, -1], [1e-9, 1, 1]]}]}, base_dir=tmp_path)


def test_cells_without_a_material_are_named_by_their_group(tmp_path):
    with pytest.raises(SceneError) as err:
        _scene(tmp_path)
    text = str(err.value)
    assert "in group 'tumour' (id 2, volume) match no [[material]]" in text
    assert 'give a [[material]] region = "tumour", or add a last' in text
    assert "tag 2" not in text


def test_unnamed_groups_are_named_by_their_id(tmp_path):
    with pytest.raises(SceneError, match=r"in group id 2 \(volume\) match no \[\[material\]\].*region = 2, or"):
        _scene(tmp_path, names=False)


def _removal_scene(tmp_path, remove):
    _write_organ(tmp_path / "organ.msh")
    import tensormass as tm
    return tm.Scene.from_dict({
        "mesh": {"file": "organ.msh"},
        "material": [{"region": "all", "E": 3e3, "nu": 0.3, "law": "stvk"}],
        "fixed": [{"box": [[-1, -1, -1], [1e-9, 1, 1]]}],
        "solver": {"kind": "static", "steps": 2, "backend": "c"},
        "probe": [{"name": "lump", "point": [0.9, 0.1, 0.1]}],
        "remove": [{"name": "resection", "step": 1, **remove}]}, base_dir=tmp_path)


@pytest.mark.parametrize("remove, named", [
    ({"region": "tumour"}, "move the probe or narrow the removal's region 'tumour'"),
    ({"box": [[0.5, -1, -1], [2, 1, 1]]}, "move the probe or narrow the removal's box"),
    ({"region": "tumour", "box": [[0.5, -1, -1], [2, 1, 1]]},
     "move the probe or narrow the removal's region 'tumour' and its box"),
])
def test_a_removal_taking_a_probe_names_what_selected_its_cells(tmp_path, remove, named):
    import tensormass as tm
    with pytest.raises(tm.TensormassError) as err:
        tm.Simulation(_removal_scene(tmp_path, remove), output=False)
    text = str(err.value)
    assert text.startswith("remove 'resection': the cells it removes hold probe 'lump'")
    assert text.endswith(named)


def test_a_cut_refused_for_the_model_says_its_kind_once(tmp_path):
    import tensormass as tm
    scene = tm.Scene.from_dict({
        "mesh": {"generate": "plate", "size": [1.0, 1.0], "cells": [2, 2]},
        "material": [{"law": "cst_dkt", "E": 1e7, "nu": 0.3, "thickness": 0.01, "density": 1000.0}],
        "fixed": [{"box": [[-1, -1, -1], [1e-9, 2, 1]]}],
        "solver": {"kind": "static", "steps": 2, "backend": "c"},
        "cut": [{"step": 1, "plane": [[0.5, 0, 0], [1, 0, 0]]}]})
    with pytest.raises(tm.TensormassError) as err:
        tm.Simulation(scene, output=False)
    text = str(err.value)
    assert text.startswith("cut: only solid meshes can change topology here")
    assert "cut/remove" not in text and text.count("cut:") == 1
