"""Scene checks of `[[material]] formulation = "..."` (runtime.physics.formulations has the table).

    formulation_name(value, "material[0].formulation")                 # the name, or SceneError
    check_element("material[0].formulation", "mean_dilatation", "tetra")  # SceneError: not for tetra
    check_adapt(materials, rules)                                      # no law switching with one

Called by the scene parser (runtime.scene.scene: the name; the element when region names an element
type; the [[adapt]] rules) and again per cell type of the mesh (runtime.scene.mesh_source.check_against_mesh).
"""
from __future__ import annotations

from ..base.errors import SceneError
from ..physics.formulations import (DEFAULT_FORMULATION, FORMULATIONS, LINEAR_ELEMENTS, locking_free_choice,
    supports)
from ..mesh.regions import reachable_laws, switch_applies

__all__ = ["formulation_name", "check_element", "check_adapt"]

_SIMPLICES = ("tetra", "triangle")      # one integration point is exact for their constant strain


def formulation_name(value, key: str) -> str:
    """A known formulation name (runtime.physics.formulations.FORMULATIONS), else SceneError naming the key."""
    known = ", ".join(FORMULATIONS)
    if not isinstance(value, str):
        raise SceneError(f"{key}: expected a string (one of {known}), got {type(value).__name__} {value!r}")
    if value not in FORMULATIONS:
        raise SceneError(f"{key}: unknown formulation {value!r}; known: {known}")
    return value


def _why_not(formulation: str, element: str) -> str:
    if formulation == "mean_dilatation" and element in _SIMPLICES:
        return "one integration point already has one volume per element"
    if formulation == "edge_smoothed":
        return "it smooths strains over the edges of linear triangles only"
    if formulation == "nodal_pressure":
        return "it averages volumes at the nodes of linear tetrahedra, triangles and wedges only"
    if formulation == "mixed":
        return "its pressure spaces are made for tetra (P1-P1 stabilised), tetra10 (P2-P1) and hexahedron (Q1-P0)"
    return f"it is made for {', '.join(FORMULATIONS[formulation])}"


def check_element(key: str, formulation: str, element: str) -> None:
    """SceneError unless the formulation applies to the element type (naming what the element supports)."""
    if formulation not in FORMULATIONS or supports(formulation, element):
        return
    choice = locking_free_choice(element)
    allowed = [name for name in FORMULATIONS if supports(name, element)]
    if choice is not None:
        fix = f"use {choice}"
    elif element in LINEAR_ELEMENTS:
        fix = f"{element} supports only {', '.join(allowed)}: refine the mesh or use quadratic elements"
    else:
        fix = f"{element} supports {', '.join(allowed)}"
    raise SceneError(f"{key}: {element}: {formulation} does not apply ({_why_not(formulation, element)}); {fix}")


def check_adapt(materials, rules) -> None:
    """Law switching ([[adapt]] switch_law) is refused for materials with a non-displacement formulation."""
    for i, material in enumerate(materials):
        formulation = getattr(material, "formulation", DEFAULT_FORMULATION)
        if formulation == DEFAULT_FORMULATION:
            continue
        reach = reachable_laws(material.law, rules)
        for r, rule in enumerate(rules):
            if any(switch_applies(rule, law) for law in reach):
                raise SceneError(f"adapt[{r}].law: law switching is not supported with formulations yet: it reaches "
                                 f"material[{i}], which uses formulation = \"{formulation}\"; use formulation = "
                                 f"\"displacement\" there, or limit the rule with from = \"<law>\" to other materials")
