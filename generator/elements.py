"""Reference finite elements with symbolic shape functions.

Node order follows VTK (and therefore meshio), so that a positively oriented
cell read by meshio maps from these reference coordinates with det J > 0.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from itertools import product

import sympy as sp

XI = sp.symbols("xi eta zeta", real=True)  # reference coordinates; 2D uses XI[:2]

_R = sp.Rational


@dataclass(frozen=True)
class ReferenceElement:
    name: str  # meshio cell type name
    dim: int
    nodes: tuple  # reference coordinates of each node (exact), VTK order
    shape_functions: tuple  # sympy expressions in XI[:dim]
    simplex: bool
    polynomial: bool  # False for the pyramid (rational basis)
    order: int

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def xi(self) -> tuple:
        return XI[: self.dim]

    def gradients(self) -> sp.Matrix:
        """(n_nodes, dim) matrix of dN_i/dxi_k."""
        return _gradients(self)

    def volume(self):
        """Exact measure of the reference domain."""
        return _VOLUME[self.name]


@functools.cache  # simplification is slow-ish and the elements are immutable
def _gradients(el: ReferenceElement) -> sp.Matrix:
    return sp.Matrix(
        [[sp.simplify(sp.diff(n, x)) for x in el.xi] for n in el.shape_functions]
    )


def _lagrange(nodes, basis, xi) -> tuple:
    """Shape functions spanning `basis` with N_i(node_j) = delta_ij.

    Solving the Vandermonde system V c = I keeps every element on the same
    code path instead of hand-written formulas."""
    V = sp.Matrix([[b.subs(dict(zip(xi, p))) for b in basis] for p in nodes])
    C = V.inv()  # column i holds the coefficients of N_i
    B = sp.Matrix([basis])
    return tuple(sp.expand((B * C[:, i])[0]) for i in range(len(nodes)))


def _midpoints(vertices, edges):
    return [tuple((a + b) / 2 for a, b in zip(vertices[i], vertices[j])) for i, j in edges]


def _monomials(xi, max_degree):
    """All monomials of total degree <= max_degree."""
    out = []
    for exps in product(range(max_degree + 1), repeat=len(xi)):
        if sum(exps) <= max_degree:
            out.append(sp.Mul(*[x**e for x, e in zip(xi, exps)]))
    return out


def _as_nodes(points):
    return tuple(tuple(sp.sympify(c) for c in p) for p in points)


def _build() -> dict:
    x, y, z = XI
    one = sp.Integer(1)
    els = []

    def add(name, dim, nodes, basis, simplex, order):
        nodes = _as_nodes(nodes)
        shapes = _lagrange(nodes, basis, XI[:dim])
        els.append(ReferenceElement(name, dim, nodes, shapes, simplex, True, order))

    tri = [(0, 0), (1, 0), (0, 1)]
    add("triangle", 2, tri, [one, x, y], True, 1)
    add("triangle6", 2, tri + _midpoints(_as_nodes(tri), [(0, 1), (1, 2), (2, 0)]),
        _monomials((x, y), 2), True, 2)

    add("quad", 2, [(-1, -1), (1, -1), (1, 1), (-1, 1)], [one, x, y, x * y], False, 1)

    tet = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
    add("tetra", 3, tet, [one, x, y, z], True, 1)
    tet_edges = [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]  # VTK quadratic tetra
    add("tetra10", 3, tet + _midpoints(_as_nodes(tet), tet_edges),
        _monomials((x, y, z), 2), True, 2)

    square = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    hexa = [p + (-1,) for p in square] + [p + (1,) for p in square]
    add("hexahedron", 3, hexa,
        [one, x, y, z, x * y, y * z, x * z, x * y * z], False, 1)

    # vtkWedge: the base triangle (0,1,2) winds so that its right-hand normal
    # points away from (3,4,5); hence (0,1) before (1,0) in (xi, eta).
    base = [(0, 0), (0, 1), (1, 0)]
    wedge = [p + (-1,) for p in base] + [p + (1,) for p in base]
    add("wedge", 3, wedge, [one, x, y, z, x * z, y * z], False, 1)

    # Pyramid: no polynomial basis is conforming with both the quad base and
    # the triangular faces, so use the standard rational basis; it reduces to
    # bilinear on the base and linear on the triangular faces.
    pyr = [p + (0,) for p in square] + [(0, 0, 1)]
    shapes = [(1 + a * x - z) * (1 + b * y - z) / (4 * (1 - z)) for a, b in square]
    shapes.append(z)
    els.append(ReferenceElement("pyramid", 3, _as_nodes(pyr), tuple(shapes),
                                False, False, 1))
    return {e.name: e for e in sorted(els, key=lambda e: e.name)}


# Measures of the reference domains: unit simplices, [-1,1]^d boxes, the
# unit triangle times [-1,1] (wedge) and the pyramid of base 4 and height 1.
_VOLUME = {
    "triangle": _R(1, 2), "triangle6": _R(1, 2), "quad": sp.Integer(4),
    "tetra": _R(1, 6), "tetra10": _R(1, 6), "hexahedron": sp.Integer(8),
    "wedge": sp.Integer(1), "pyramid": _R(4, 3),
}

ELEMENTS: dict[str, ReferenceElement] = _build()


def element(name: str) -> ReferenceElement:
    try:
        return ELEMENTS[name]
    except KeyError:
        raise ValueError(
            f"unknown element {name!r}; known: {', '.join(ELEMENTS)}"
        ) from None
