"""Linear tetrahedron (VTK_TETRA) on the unit tetrahedron."""
import math

from ._base import SIMPLEX, ElementType, Face

ELEMENT = ElementType(
    name="tetra", dim=3, domain=SIMPLEX, order=1,
    nodes=((0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)),
    n_corners=4,
    edges=((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)),
    faces=(Face("triangle", (0, 2, 1)), Face("triangle", (0, 1, 3)),
           Face("triangle", (0, 3, 2)), Face("triangle", (1, 2, 3))),
    regular_measure=1 / (6 * math.sqrt(2)),     # regular tetrahedron, unit edges
    flip=(0, 2, 1, 3),
    refinement="bisection",
)
