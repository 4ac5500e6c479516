"""Flat shell triangle (CST membrane + DKT plate bending, thesis chapter 6) on the unit triangle.

Three corner nodes in 3D space, six unknowns each: the displacement (u, v, w) and the rotation
vector (theta_x, theta_y, theta_z), world components.  Meshes store it as VTK triangles (a
surface mesh in 3D: `[mesh] element = "shell"`); its kernels are generated from laws/cst_dkt.py.
"""
import math

from ._base import SIMPLEX, ElementType, Face

ELEMENT = ElementType(
    name="shell", dim=2, domain=SIMPLEX, order=1,
    nodes=((0, 0), (1, 0), (0, 1)),
    n_corners=3,
    edges=((0, 1), (1, 2), (2, 0)),
    faces=(Face("line", (0, 1)), Face("line", (1, 2)), Face("line", (2, 0))),
    regular_measure=math.sqrt(3) / 4,           # equilateral, unit edges
    flip=(0, 2, 1),
    dofs_per_node=6,
    space_dims=(3,),
    file_type="triangle",
    description="flat CST-DKT shell triangle: 3 nodes x (3 displacements, 3 rotations) in 3D",
)
