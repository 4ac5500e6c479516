"""Face-only element types: the faces of the element table that are not element types themselves.

Edges of 2D elements (line, line3) are described here like any element type (VTK order, the
unit simplex [0, 1] as reference domain) so that the generator derives their shape functions
the same way (generator/shape_tables.py: consistent tractions and pressure).  They are NOT
registered: no kernels, no meshes of them, not in `elements.names()`.
"""
from fractions import Fraction

from ._base import SIMPLEX, ElementType

LINE = ElementType(
    name="line", dim=1, domain=SIMPLEX, order=1,
    nodes=((0,), (1,)), n_corners=2, edges=((0, 1),), faces=(),
    regular_measure=1.0, flip=(1, 0), space_dims=(2, 3),
)

LINE3 = ElementType(
    name="line3", dim=1, domain=SIMPLEX, order=2, linear="line",
    nodes=((0,), (1,), (Fraction(1, 2),)), n_corners=2, midside_edges=((0, 1),), edges=((0, 1),), faces=(),
    regular_measure=1.0, flip=(1, 0, 2), space_dims=(2, 3),
)

FACE_ONLY = {t.name: t for t in (LINE, LINE3)}
