"""Element formulations a material can choose (`[[material]] formulation = "..."`).

- "displacement": the law's energy integrated at the quadrature points (every kernel as generated).
  Linear elements lock when the material is nearly incompressible.
- "mean_dilatation": the volumetric part of the law is evaluated once per element, at the element's
  mean volume measure (Nagtegaal, Parks & Rice 1974; Simo, Taylor & Pister 1985: Q1-P0 with the
  pressure condensed per element).  For quadratic simplices it is the P2-P0 mixed element.
- "nodal_pressure": the volumetric part evaluated at the nodes, from volumes averaged over the cells
  around each node (the average nodal pressure tetrahedron, Bonet & Burton 1998; the triangle
  likewise): the locking-free choice for linear tetrahedra and triangles.

Each is an energy, so forces and Jacobians follow from the same generated kernels
(runtime.volumetric assembles them; generator.volumetric splits each law).
"""
from __future__ import annotations

__all__ = ["FORMULATIONS", "DEFAULT_FORMULATION", "LINEAR_ELEMENTS", "supports", "locking_free_choice",
           "formulation_names"]

DEFAULT_FORMULATION = "displacement"

# name -> element types it supports (None: every element)
FORMULATIONS = {
    "displacement": None,
    "mean_dilatation": ("hexahedron", "quad", "tetra10", "triangle6", "wedge"),
    "nodal_pressure": ("tetra", "triangle"),
}

# elements with linear shape functions: those that lock under a displacement formulation
LINEAR_ELEMENTS = ("hexahedron", "pyramid", "quad", "tetra", "triangle", "wedge")


def formulation_names() -> list:
    return list(FORMULATIONS)


def supports(formulation: str, element: str) -> bool:
    allowed = FORMULATIONS[formulation]
    return allowed is None or element in allowed


def locking_free_choice(element: str) -> str | None:
    """The formulation to suggest for a nearly incompressible material on this element (None: none)."""
    for name, allowed in FORMULATIONS.items():
        if allowed is not None and element in allowed:
            return name
    return None
