"""Linear wedge (VTK_WEDGE) on the unit triangle x [-1, 1].

The base triangle (0, 1, 2) winds so that its right-hand normal points away
from (3, 4, 5); hence (0, 1) before (1, 0) in (xi, eta).
"""
import math

from ._base import PRISM, ElementType, Face

_BASE = ((0, 0), (0, 1), (1, 0))

ELEMENT = ElementType(
    name="wedge", dim=3, domain=PRISM, order=1,
    nodes=tuple(p + (-1,) for p in _BASE) + tuple(p + (1,) for p in _BASE),
    n_corners=6,
    edges=((0, 1), (1, 2), (2, 0), (3, 4), (4, 5), (5, 3), (0, 3), (1, 4), (2, 5)),
    faces=(Face("triangle", (0, 1, 2)), Face("triangle", (3, 5, 4)), Face("quad", (0, 3, 4, 1)),
           Face("quad", (0, 2, 5, 3)), Face("quad", (1, 4, 5, 2))),
    regular_measure=math.sqrt(3) / 4,           # equilateral triangle x unit height
    flip=(3, 4, 5, 0, 1, 2),
)
