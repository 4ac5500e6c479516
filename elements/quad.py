"""Bilinear quadrilateral (VTK_QUAD) on [-1, 1]^2."""
from ._base import BOX, ElementType, Face

ELEMENT = ElementType(
    name="quad", dim=2, domain=BOX, order=1,
    nodes=((-1, -1), (1, -1), (1, 1), (-1, 1)),
    n_corners=4,
    edges=((0, 1), (1, 2), (2, 3), (3, 0)),
    faces=(Face("line", (0, 1)), Face("line", (1, 2)), Face("line", (2, 3)), Face("line", (3, 0))),
    regular_measure=1.0,                        # unit square
    flip=(0, 3, 2, 1),
)
