"""The fetal head (B24) in a quick form: the committed two-zone shell mesh, its regions selecting the
materials, the clamp and the pressure bands; three damped steps already shorten SOBD and lengthen MaVD
with the enclosed volume kept. A region the mesh lacks is refused naming the known ones."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import tensormass as tm
from tensormass.apps import fetal_head
from tensormass.runtime.base.errors import SceneError, TensormassError

MESH = Path(__file__).resolve().parents[2] / "examples" / "birth" / "fetal_head.msh"
SCENE = MESH.with_suffix(".toml")          # the checkout's (an installed package has no examples)


def test_zones_cover_the_head_and_sutures_cross_the_bands():
    import meshio
    m = meshio.read(MESH)
    tags = m.cell_data["gmsh:physical"][0]
    assert {k: int(v[0]) for k, v in m.field_data.items()} == fetal_head.ZONES
    assert all((tags == i).sum() > 100 for i in fetal_head.ZONES.values())
    z = m.points[m.cells[0].data].mean(axis=1)[:, 2]
    assert np.any((tags == fetal_head.ZONES["suture"]) & (z > -0.030) & (z < 0.0))
    assert np.array_equal(fetal_head.zones(m.points, m.cells[0].data), tags)
    pairs = fetal_head.landmarks(m.points)
    d = fetal_head.diameters(m.points, pairs)
    for name, (diameter, _) in fetal_head.TABLE_8_2.items():
        assert abs(1e3 * d[name] - diameter) < 0.5


def test_pressure_bands_shorten_sobd_and_lengthen_mavd_at_constant_volume():
    row = fetal_head.run_head(MESH, steps=3, scene=SCENE)
    assert row["status"] == "ok" and row["triangles"] == 9334
    assert row["change_mm"]["MaVD"] > 0.01 and row["change_mm"]["SOBD"] < -0.01
    assert abs(row["volume_change"]) < 1e-9


def test_without_the_scene_file_the_report_says_so(tmp_path):
    with pytest.raises(TensormassError, match="scene .* is not there"):
        fetal_head.run_head(MESH, steps=1, scene=tmp_path / "none.toml")


def test_a_region_the_shell_mesh_lacks_is_refused():
    text = SCENE.read_text().replace('file = "fetal_head.msh"', f'file = "{MESH.as_posix()}"')
    with pytest.raises((SceneError, TensormassError), match=r"unknown region 'band50'; the mesh's regions: 'suture' \(id 1, surface\), 'band45'.*'neck' \(id 6, surface\)$"):
        tm.Simulation(tm.Scene.from_string(text.replace('region = "band45"', 'region = "band50"')), output=False)
