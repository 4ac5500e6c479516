"""Pyramid (VTK_PYRAMID): base [-1, 1]^2 at zeta = 0, apex (0, 0, 1).

No polynomial basis is conforming with both the quad base and the triangular
faces: the generator and the mesh checks special-case the pyramid domain with
the standard rational basis.
"""
import math

from ._base import PYRAMID, ElementType, Face

ELEMENT = ElementType(
    name="pyramid", dim=3, domain=PYRAMID, order=1,
    nodes=((-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0), (0, 0, 1)),
    n_corners=5,
    edges=((0, 1), (1, 2), (2, 3), (3, 0), (0, 4), (1, 4), (2, 4), (3, 4)),
    faces=(Face("quad", (0, 3, 2, 1)), Face("triangle", (0, 1, 4)), Face("triangle", (1, 2, 4)),
           Face("triangle", (2, 3, 4)), Face("triangle", (3, 0, 4))),
    regular_measure=math.sqrt(2) / 6,           # square base, unit edges (half an octahedron)
    flip=(0, 3, 2, 1, 4),
)
