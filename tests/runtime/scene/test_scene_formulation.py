"""`[[material]] formulation = "..."`: parsed, checked against runtime.physics.formulations and the element types
each material models, and refused with [[adapt]] law switching (runtime.scene.formulation_check)."""
from __future__ import annotations

import re

import pytest

from tensormass.runtime.physics.formulations import FORMULATIONS
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.base.errors import SceneError

SCENE = """
[mesh]
generate = "bar"
size = [1.0, 0.2, 0.2]
cells = [4, 1, 1]
element = "{element}"
{materials}
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
{extra}
"""
MATERIAL = """
[[material]]
region = "{region}"
law = "hooke"
quadrature = "{quadrature}"
E = 1.0e6
nu = 0.3
{formulation}
"""


def scene(element="tetra", formulation=None, region="all", quadrature="gauss1", extra="", more=""):
    line = "" if formulation is None else f"formulation = {formulation}"
    materials = MATERIAL.format(region=region, quadrature=quadrature, formulation=line) + more
    return Scene.from_string(SCENE.format(element=element, materials=materials, extra=extra))


def test_default_and_given_formulations_are_stored():
    assert scene().materials[0].formulation == "displacement"
    assert scene(formulation='"nodal_pressure"').materials[0].formulation == "nodal_pressure"
    assert scene("hexahedron", '"mean_dilatation"', quadrature="gauss2").materials[0].formulation == "mean_dilatation"


@pytest.mark.parametrize("value, message", [
    ('"fbar"', "material[0].formulation: unknown formulation 'fbar'; known: " + ", ".join(FORMULATIONS)),
    ("3", "material[0].formulation: expected a string (one of displacement, mean_dilatation, nodal_pressure, "
          "edge_smoothed, mixed)"),
])
def test_unknown_formulations_are_refused_with_the_known_names(value, message):
    with pytest.raises(SceneError, match="^" + re.escape(message)):
        scene(formulation=value)


def test_element_named_by_region_is_checked_while_parsing():
    with pytest.raises(SceneError) as err:
        Scene.from_string(SCENE.format(element="tetra", extra="", materials=MATERIAL.format(
            region="tetra", quadrature="gauss1", formulation='formulation = "mean_dilatation"')), load_mesh=False)
    assert str(err.value) == ("material[0].formulation: tetra: mean_dilatation does not apply (one integration "
                              "point already has one volume per element); use nodal_pressure")


@pytest.mark.parametrize("element, quadrature, formulation, message", [
    ("tetra", "gauss1", "mean_dilatation", "tetra: mean_dilatation does not apply (one integration point already "
                                           "has one volume per element); use nodal_pressure"),
    ("hexahedron", "gauss2", "nodal_pressure", "hexahedron: nodal_pressure does not apply (it averages volumes at "
                                               "the nodes of linear tetrahedra, triangles and wedges only); use mean_dilatation"),
    ("pyramid", "gauss2", "mean_dilatation", "pyramid: mean_dilatation does not apply (it is made for hexahedron, "
                                             "quad, tetra10, triangle6, wedge); pyramid supports only displacement: "
                                             "refine the mesh or use quadratic elements"),
])
def test_the_mesh_cell_types_are_checked(element, quadrature, formulation, message):
    """region = "all": the element is known only from the mesh (validate(), per cell type)."""
    with pytest.raises(SceneError) as err:
        scene(element, f'"{formulation}"', quadrature=quadrature)
    assert str(err.value) == f"material[0].formulation: {message}"


def test_mixed_mesh_each_material_is_checked_on_the_cells_it_models():
    tets = MATERIAL.format(region="all", quadrature="gauss2", formulation='formulation = "nodal_pressure"')
    ok = scene("mixed", '"mean_dilatation"', region="hexahedron", quadrature="gauss2",
               more=MATERIAL.format(region="pyramid", quadrature="gauss2", formulation="") + tets.replace(
                   '"all"', '"tetra"') + MATERIAL.format(region="all", quadrature="gauss2", formulation=""))
    assert [m.formulation for m in ok.materials] == ["mean_dilatation", "displacement", "nodal_pressure",
                                                     "displacement"]
    with pytest.raises(SceneError, match=r"^material\[0\]\.formulation: hexahedron: nodal_pressure does not apply"):
        scene("mixed", '"nodal_pressure"', quadrature="gauss2")


def test_law_switching_reaching_a_formulation_is_refused():
    rule = '[[adapt]]\ncriterion = "R_L"\nthreshold = 0.1\nlaw = "stvk"'
    with pytest.raises(SceneError) as err:
        scene(formulation='"nodal_pressure"', extra=rule)
    assert str(err.value).startswith("adapt[0].law: law switching is not supported with formulations yet: it "
                                     "reaches material[0], which uses formulation = \"nodal_pressure\"")
    assert scene(extra=rule).adapt[0].law == "stvk"                       # displacement: allowed
    # a rule limited to another law does not reach the material
    assert len(scene(formulation='"nodal_pressure"', extra=rule + '\nfrom = "neohookean"').adapt) == 1
