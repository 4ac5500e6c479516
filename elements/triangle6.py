"""Quadratic triangle (VTK_QUADRATIC_TRIANGLE): corners, then the midsides of edges 01, 12, 20."""
import math

from ._base import SIMPLEX, ElementType, Face, midpoints

_CORNERS = ((0, 0), (1, 0), (0, 1))
_MIDSIDE_EDGES = ((0, 1), (1, 2), (2, 0))

ELEMENT = ElementType(
    name="triangle6", dim=2, domain=SIMPLEX, order=2, linear="triangle",
    nodes=_CORNERS + tuple(midpoints(_CORNERS, _MIDSIDE_EDGES)),
    n_corners=3,
    midside_edges=_MIDSIDE_EDGES,
    edges=((0, 1), (1, 2), (2, 0)),
    faces=(Face("line3", (0, 1, 3)), Face("line3", (1, 2, 4)), Face("line3", (2, 0, 5))),
    regular_measure=math.sqrt(3) / 4,
    flip=(0, 2, 1, 5, 4, 3),
)
