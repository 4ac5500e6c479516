"""Element formulations a material can choose (`[[material]] formulation = "..."`).

- "displacement": the law's energy integrated at the quadrature points (every kernel as generated).
  Linear elements lock when the material is nearly incompressible.
- "mean_dilatation": the volumetric part of the law is evaluated once per element, at the element's
  mean volume measure (Nagtegaal, Parks & Rice 1974; Simo, Taylor & Pister 1985: Q1-P0 with the
  pressure condensed per element).  For quadratic simplices it is the P2-P0 mixed element.
- "nodal_pressure": the volumetric part evaluated at the nodes, from volumes averaged over the cells
  around each node (the average nodal pressure tetrahedron, Bonet & Burton 1998; the triangle and
  the wedge likewise): the locking-free choice for linear tetrahedra, triangles and wedges.

- "edge_smoothed": nodal pressure for the volumetric part, and the rest of the law integrated with
  strains smoothed over the edges (ES-FEM; with the node-based volume, the selective ES/NS-FEM of
  Nguyen-Thoi et al. 2009): linear triangles only.  It also removes most of their stiffness in
  bending, so it is the choice for triangles (Cook's membrane, one-diagonal 32 x 32 at nu = 0.4999:
  -3.3 % from P2-P0 where nodal pressure is -5.6 %; runtime.assembly.volumetric).

- "mixed": the pressure as an unknown beside the displacements (runtime.assembly.mixed), for exact
  incompressibility (nu = 0.5) and up to it: P2-P1 (Taylor-Hood) on tetra10, P1-P1 stabilised by
  MINI's condensed bubble on tetra, Q1-P0 on hexahedra.  Newton solves the symmetric indefinite
  (u, p) system (runtime.physics.saddle).

Wedges take both averaged formulations, but only nodal pressure cures their locking in prism
layers: under a field in the layers' plane a linear prism's dilatation is already constant over
the cell (it is the dilatation of its triangle), so the cell mean is the pointwise value and
mean dilatation keeps P1/P0 triangles' one volume constraint per cell (a thick cylinder in plane
strain at nu = 0.499: -44 % / -29 % / -9 % from Lame on three gmsh prism meshes with either, -4.0 %
/ -1.1 % / -0.26 % with nodal pressure; apps/reports/cylinder.py).  LOCKING_FREE names the choice.

Each is an energy, so forces and Jacobians follow from the same generated kernels
(runtime.assembly.volumetric assembles them; generator.volumetric splits each law).
"""
from __future__ import annotations

__all__ = ["FORMULATIONS", "DEFAULT_FORMULATION", "LINEAR_ELEMENTS", "LOCKING_FREE", "supports",
           "locking_free_choice", "formulation_names"]

DEFAULT_FORMULATION = "displacement"

# name -> element types it supports (None: every element)
FORMULATIONS = {
    "displacement": None,
    "mean_dilatation": ("hexahedron", "quad", "tetra10", "triangle6", "wedge"),
    "nodal_pressure": ("tetra", "triangle", "wedge"),
    "edge_smoothed": ("triangle",),
    "mixed": ("tetra", "tetra10", "hexahedron"),
}

# element -> the formulation that cures its locking (elements not here have none)
LOCKING_FREE = {"hexahedron": "mean_dilatation", "quad": "mean_dilatation", "tetra10": "mean_dilatation",
                "triangle6": "mean_dilatation", "tetra": "nodal_pressure", "triangle": "edge_smoothed",
                "wedge": "nodal_pressure"}

# elements with linear shape functions: those that lock under a displacement formulation
LINEAR_ELEMENTS = ("hexahedron", "pyramid", "quad", "tetra", "triangle", "wedge")


def formulation_names() -> list:
    return list(FORMULATIONS)


def supports(formulation: str, element: str) -> bool:
    allowed = FORMULATIONS[formulation]
    return allowed is None or element in allowed


def locking_free_choice(element: str) -> str | None:
    """The formulation to suggest for a nearly incompressible material on this element (None: none)."""
    return LOCKING_FREE.get(element)
