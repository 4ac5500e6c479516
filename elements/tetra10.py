"""Quadratic tetrahedron (VTK_QUADRATIC_TETRA): corners, then midsides of edges 01 12 20 03 13 23."""
import math

from ._base import SIMPLEX, ElementType, Face, midpoints

_CORNERS = ((0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1))
_MIDSIDE_EDGES = ((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3))

ELEMENT = ElementType(
    name="tetra10", dim=3, domain=SIMPLEX, order=2, linear="tetra",
    nodes=_CORNERS + tuple(midpoints(_CORNERS, _MIDSIDE_EDGES)),
    n_corners=4,
    midside_edges=_MIDSIDE_EDGES,
    edges=_MIDSIDE_EDGES,
    faces=(Face("triangle6", (0, 2, 1, 6, 5, 4)), Face("triangle6", (0, 1, 3, 4, 8, 7)),
           Face("triangle6", (0, 3, 2, 7, 9, 6)), Face("triangle6", (1, 2, 3, 5, 9, 8))),
    regular_measure=1 / (6 * math.sqrt(2)),
    flip=(0, 2, 1, 3, 6, 5, 4, 7, 9, 8),
)
