"""Trilinear hexahedron (VTK_HEXAHEDRON) on [-1, 1]^3: bottom quad (zeta = -1), then top."""
from ._base import BOX, ElementType, Face

_SQUARE = ((-1, -1), (1, -1), (1, 1), (-1, 1))

ELEMENT = ElementType(
    name="hexahedron", dim=3, domain=BOX, order=1,
    nodes=tuple(p + (-1,) for p in _SQUARE) + tuple(p + (1,) for p in _SQUARE),
    n_corners=8,
    edges=((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4),
           (0, 4), (1, 5), (2, 6), (3, 7)),
    faces=(Face("quad", (0, 3, 2, 1)), Face("quad", (4, 5, 6, 7)), Face("quad", (0, 1, 5, 4)),
           Face("quad", (1, 2, 6, 5)), Face("quad", (2, 3, 7, 6)), Face("quad", (3, 0, 4, 7))),
    regular_measure=1.0,                        # unit cube
    flip=(4, 5, 6, 7, 0, 1, 2, 3),
)
