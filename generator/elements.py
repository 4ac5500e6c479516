"""Reference finite elements with symbolic shape functions.

The element types themselves (VTK-ordered nodes, reference domain, order) are
described once in `elements/` (tensormass.elements); this module derives their
shape functions: a Lagrange basis on the domain's polynomial space, and the
standard rational basis on the pyramid domain.  Node order follows VTK (and
therefore meshio), so that a positively oriented cell read by meshio maps from
these reference coordinates with det J > 0.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import sympy as sp

from .. import elements as _types
from ..elements import PYRAMID, ElementType, monomial_exponents

XI = sp.symbols("xi eta zeta", real=True)  # reference coordinates; 2D uses XI[:2]

@dataclass(frozen=True)
class ReferenceElement:
    name: str  # meshio cell type name
    dim: int   # topological dimension
    nodes: tuple  # reference coordinates of each node (exact), VTK order
    shape_functions: tuple  # sympy expressions in XI[:dim]
    simplex: bool
    polynomial: bool  # False for the pyramid (rational basis)
    order: int
    type: ElementType | None = None  # the table entry it was derived from

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
        return sp.Rational(self.type.reference_measure)


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


def _as_nodes(points):
    return tuple(tuple(sp.sympify(c) for c in p) for p in points)


def _pyramid_shapes(t: ElementType) -> tuple:
    """No polynomial basis is conforming with both the quad base and the
    triangular faces, so use the standard rational basis; it reduces to
    bilinear on the base and linear on the triangular faces."""
    if t.n_nodes != 5:
        raise ValueError(f"{t.name}: only the 5-node pyramid has a basis on the pyramid domain")
    x, y, z = XI
    shapes = [(1 + a * x - z) * (1 + b * y - z) / (4 * (1 - z)) for a, b, _ in _as_nodes(t.nodes[:4])]
    shapes.append(z)
    return tuple(shapes)


def reference(t: ElementType) -> ReferenceElement:
    """The ReferenceElement of a table entry: shape functions from its nodes and domain."""
    nodes = _as_nodes(t.nodes)
    xi = XI[: t.dim]
    if t.domain == PYRAMID:
        shapes, polynomial = _pyramid_shapes(t), False
    else:
        basis = [sp.Mul(*[x**e for x, e in zip(xi, exps)])
                 for exps in monomial_exponents(t.domain, t.dim, t.order)]
        shapes, polynomial = _lagrange(nodes, basis, xi), True
    return ReferenceElement(t.name, t.dim, nodes, shapes, t.simplex, polynomial, t.order, t)


def _build() -> dict:
    els = [reference(_types.get(name)) for name in _types.builtin()]
    return {e.name: e for e in sorted(els, key=lambda e: e.name)}


# The catalogue's elements: the built-in types (element types registered later,
# e.g. by tests, are derived on demand by element()).
ELEMENTS: dict[str, ReferenceElement] = _build()


@functools.cache
def _derived(t: ElementType) -> ReferenceElement:
    return reference(t)


def element(name: str) -> ReferenceElement:
    try:
        return ELEMENTS[name]
    except KeyError:
        pass
    try:
        return _derived(_types.get(name))
    except ValueError:
        raise ValueError(
            f"unknown element {name!r}; known: {', '.join(ELEMENTS)}"
        ) from None
