"""Setup advice naming the body size: a mesh in millimetres with SI values (runtime.scene.advice)."""
from __future__ import annotations

from tensormass.runtime.scene import advice as adv
from tensormass.runtime.scene.scene import Scene


# -- body size: a mesh in millimetres with SI values ------------------------------------------------

def _sized_scene(size, E=3000.0, density=1000.0, gravity=-9.81):
    return Scene.from_string(f"""
name = "sized"
[mesh]
generate = "bar"
size = [{size[0]}, {size[1]}, {size[2]}]
cells = [2, 1, 1]
element = "tetra"
[[material]]
law = "neohookean"
E = {E}
nu = 0.45
density = {density}
[[fixed]]
box = [[-1e-9, -1e9, -1e9], [1e-9, 1e9, 1e9]]
[loads]
gravity = [0.0, 0.0, {gravity}]
""")


def test_a_body_150_m_across_with_tissue_values_is_named_by_its_size():
    scene = _sized_scene((150.0, 100.0, 80.0))
    lines = [a for a in adv.scene_advice(scene) if "across" in a]
    assert len(lines) == 1
    assert lines[0].startswith("the body is 150 m across (bounding box 150 x 100 x 80 m)")
    assert "rho g L^2 / E = 7.36e+04 m" in lines[0] and "millimetres" in lines[0]


def test_a_tissue_body_under_a_millimetre_is_named_without_gravity():
    scene = _sized_scene((0.0005, 0.0002, 0.0002), gravity=0.0)
    lines = [a for a in adv.scene_advice(scene) if "across" in a]
    assert len(lines) == 1 and lines[0].startswith("the body is 0.0005 m across")
    assert "tissue-like material[0] (E = 3e+03 Pa" in lines[0]


def test_an_organ_sized_body_gets_no_size_advice():
    assert adv.body_size_advice(_sized_scene((0.15, 0.1, 0.08)), _sized_scene((0.15, 0.1, 0.08)).load_mesh()) is None
    steel = _sized_scene((150.0, 10.0, 10.0), E=2.1e11, density=7800.0)     # a bridge girder: consistent
    assert adv.body_size_advice(steel, steel.load_mesh()) is None
