"""Linear triangle (VTK_TRIANGLE) on the unit triangle."""
import math

from ._base import SIMPLEX, ElementType, Face

ELEMENT = ElementType(
    name="triangle", dim=2, domain=SIMPLEX, order=1,
    nodes=((0, 0), (1, 0), (0, 1)),
    n_corners=3,
    edges=((0, 1), (1, 2), (2, 0)),
    faces=(Face("line", (0, 1)), Face("line", (1, 2)), Face("line", (2, 0))),
    regular_measure=math.sqrt(3) / 4,           # equilateral, unit edges
    flip=(0, 2, 1),
    refinement="bisection",
)
