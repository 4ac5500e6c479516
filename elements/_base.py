"""The description of one element type, and the reference domains it lives on.

An element type is data only (no sympy, no numpy): the generator derives shape
functions and quadrature from it, the runtime its mesh checks, faces, criteria
and refinement.  Coordinates are exact (int or Fraction) so that the generator's
symbolic pipeline stays exact.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction
from itertools import product
from math import factorial

__all__ = ["Domain", "SIMPLEX", "BOX", "PRISM", "PYRAMID", "DOMAINS", "Face", "ElementType",
           "midpoints", "monomial_exponents"]


@dataclass(frozen=True)
class Domain:
    """A family of reference domains; `measure(dim)` is the exact measure of the one of dimension dim.

    simplex: the unit simplex {xi_k >= 0, sum xi_k <= 1} ([0, 1] in 1D);
    box:     [-1, 1]^dim;
    prism:   the unit triangle x [-1, 1] (3D only);
    pyramid: base [-1, 1]^2 at zeta = 0, apex (0, 0, 1) (3D only).
    """
    name: str

    def measure(self, dim: int) -> Fraction:
        if self.name == "simplex":
            return Fraction(1, factorial(dim))
        if self.name == "box":
            return Fraction(2 ** dim)
        if (self.name, dim) == ("prism", 3):
            return Fraction(1)
        if (self.name, dim) == ("pyramid", 3):
            return Fraction(4, 3)
        raise ValueError(f"no {dim}D {self.name} domain")


SIMPLEX, BOX, PRISM, PYRAMID = Domain("simplex"), Domain("box"), Domain("prism"), Domain("pyramid")
DOMAINS = {d.name: d for d in (SIMPLEX, BOX, PRISM, PYRAMID)}


@dataclass(frozen=True)
class Face:
    """A face (an edge of a 2D element, a vertex of a 1D one) as local nodes of its element.

    `nodes` are in the face type's own node order (corners first, then midsides),
    oriented outward: the right-hand normal (3D), or the edge direction with the
    element on its left (2D), points out of a positively oriented element.
    """
    type: str
    nodes: tuple

    @property
    def corners(self) -> tuple:
        return self.nodes[:_FACE_CORNERS.get(self.type, len(self.nodes))]


# corner counts of face types that are not element types themselves
_FACE_CORNERS = {"vertex": 1, "line": 2, "line3": 2, "triangle": 3, "triangle6": 3, "quad": 4,
                 "quad8": 4, "quad9": 4}


@dataclass(frozen=True)
class ElementType:
    """One element type (a meshio / VTK cell type name) and everything known about it.

    nodes           reference coordinates of every node, VTK order (exact numbers)
    n_corners       the first n_corners nodes are the corners, then the edge midside nodes, then any
                    face / interior nodes (hexahedron27)
    edges           corner edges (pairs of local corner ids)
    faces           Face per face, outward (see Face)
    midside_edges   for quadratic elements: node n_corners + m is the midpoint of midside_edges[m]
    linear          the linear counterpart (its own name for linear elements)
    domain          reference domain (Domain)
    dim             topological dimension (may be below the space dimension: bars, shells)
    order           polynomial order of the shape functions
    dofs_per_node   None: the space dimension (solids); otherwise a fixed count (shells, rotations)
    space_dims      space dimensions a mesh of this type may have; None: (dim,) (solids)
    regular_measure measure of the regular element of this shape with unit edges (adaptation R_M, R_HM)
    flip            node permutation that mirrors the reference element onto itself (orientation fix)
    refinement      refinement pattern ("bisection": longest-edge bisection), None where not defined
    file_type       the meshio / VTK cell type its cells are stored as (None: its own name; the
                    shell: "triangle")
    """
    name: str
    nodes: tuple
    n_corners: int
    edges: tuple
    faces: tuple
    domain: Domain
    dim: int
    regular_measure: float
    flip: tuple
    order: int = 1
    midside_edges: tuple = ()
    linear: str | None = None
    dofs_per_node: int | None = None
    space_dims: tuple | None = None
    refinement: str | None = None
    file_type: str | None = None
    description: str = field(default="", compare=False)

    def __post_init__(self):
        if self.linear is None:
            object.__setattr__(self, "linear", self.name)
        if self.space_dims is None:
            object.__setattr__(self, "space_dims", (self.dim,))
        if self.file_type is None:
            object.__setattr__(self, "file_type", self.name)
        if min(self.space_dims) < self.dim:
            raise ValueError(f"{self.name}: space dimension below the topological dimension {self.dim}")
        if any(len(p) != self.dim for p in self.nodes):
            raise ValueError(f"{self.name}: reference nodes need {self.dim} coordinates each")
        if len(self.nodes) < self.n_corners + len(self.midside_edges):
            raise ValueError(f"{self.name}: {len(self.nodes)} nodes but {self.n_corners} corners and "
                             f"{len(self.midside_edges)} midside edges")
        if sorted(self.flip) != list(range(len(self.nodes))):
            raise ValueError(f"{self.name}: flip must be a permutation of the nodes")

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def solid(self) -> bool:
        """A continuum element: its nodes carry the displacement only (dofs per node = space dimension)."""
        return self.dofs_per_node is None

    @property
    def simplex(self) -> bool:
        return self.domain is SIMPLEX or self.domain == SIMPLEX

    @property
    def quadratic(self) -> bool:
        return bool(self.midside_edges)

    @property
    def corner_nodes(self) -> tuple:
        """Reference coordinates of the corners."""
        return self.nodes[: self.n_corners]

    @property
    def reference_measure(self) -> Fraction:
        return self.domain.measure(self.dim)

    def midside(self, a: int, b: int) -> int:
        """Local index of the midside node of corner edge (a, b)."""
        for m, e in enumerate(self.midside_edges):
            if set(e) == {a, b}:
                return self.n_corners + m
        raise KeyError((self.name, a, b))

    def n_dofs(self, space_dim: int) -> int:
        """Unknowns per element in a space of dimension space_dim."""
        return self.n_nodes * (space_dim if self.dofs_per_node is None else self.dofs_per_node)


def midpoints(vertices, edges) -> list:
    """Exact midpoints of the given corner edges."""
    return [tuple(Fraction(a + b, 2) for a, b in zip(vertices[i], vertices[j])) for i, j in edges]


def monomial_exponents(domain: Domain, dim: int, order: int) -> list:
    """Exponent tuples of the polynomial space of a Lagrange element on `domain`.

    simplex: total degree <= order; box: degree <= order per direction; prism:
    (triangle, total degree <= order) x (zeta, degree <= order).  The pyramid has
    no polynomial basis (its rational basis is special-cased by the users).
    """
    if domain == SIMPLEX:
        return [e for e in product(range(order + 1), repeat=dim) if sum(e) <= order]
    if domain == BOX:
        return list(product(range(order + 1), repeat=dim))
    if domain == PRISM and dim == 3:
        return [e for e in product(range(order + 1), repeat=3) if e[0] + e[1] <= order]
    raise ValueError(f"no polynomial Lagrange basis on the {dim}D {domain.name} domain")
