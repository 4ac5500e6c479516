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
