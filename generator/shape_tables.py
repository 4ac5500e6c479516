"""Shape-function tables for consistent loads and masses: one generated data file for the runtime.

For every element type of the table (tensormass.elements) and every face type its faces use
(line, line3, triangle, triangle6, quad, ...), the shape functions N (q, k) and their reference
gradients dN/dxi (q, k, r) at the points of a quadrature rule, with the weights (q,):

    tensormass generate            writes <out>/shape_tables.json next to the kernels
    tensormass generate --check    regenerates it and compares byte for byte with generated/

The shape functions are the generator's own (generator.elements: sympy, from the element table),
evaluated exactly and rounded once to float64, so the runtime (runtime/assembly/loads.py, runtime/assembly/mass.py)
needs numpy only.  The rule of each type is exact for the consistent-mass integrand N_a N_b det J
of an isoparametric element of that type (so also for the load integrand N_a det J, and for the
face integrand N_a (t1 x t2) of flat or curved faces); see `rule_for`.
"""
from __future__ import annotations

import json
from pathlib import Path

import sympy as sp

from .. import elements as _types
from ..elements import BOX, SIMPLEX
from ..elements._faces import FACE_ONLY
from .elements import reference
from .quadrature import QuadratureRule, gauss_line, rule, rule_for_degree
from ..runtime.base.files import write_atomic

FILE = "shape_tables.json"
FORMAT = 1


def face_types() -> list:
    """Names of the face types the built-in element types use, sorted."""
    return sorted({f.type for name in _solid() for f in _types.get(name).faces})


def _solid() -> list:
    """The built-in solid element types (shells have no shape table: their kernels are structural)."""
    return [n for n in _types.builtin() if _types.get(n).solid]


def type_of(name: str):
    """The ElementType of an element or face-only type."""
    return FACE_ONLY[name] if name in FACE_ONLY else _types.get(name)


def rule_for(t):
    """The QuadratureRule exact for N_a N_b det J on an isoparametric element of type t.

    Simplices of order p in r dimensions: N_a N_b has degree 2p, det J degree r (p - 1).
    Boxes, prisms, pyramids: Gauss with p + 1 points per direction in 1D/2D (det J of a
    bilinear quad is linear per direction), p + 2 in 3D (det J of a trilinear map is
    quadratic per direction); the pyramid's collapsed rule integrates its rational basis
    as polynomials (generator.quadrature).
    """
    if t.domain == SIMPLEX:
        degree = 2 * t.order + t.dim * (t.order - 1)
        if t.name in FACE_ONLY:        # not registered: the Gauss rule on [0, 1] directly
            x, w = gauss_line(degree // 2 + 1)
            return QuadratureRule(f"gauss{degree}", t.name, tuple((p,) for p in x), w, 2 * len(x) - 1)
        return rule_for_degree(t.name, degree)
    n = t.order + 1 if (t.domain == BOX and t.dim <= 2) else t.order + 2
    return rule(t.name, f"gauss{n}")


def _num(x) -> float:
    return float(sp.N(x, 40))


def table(name: str) -> dict:
    """The table of one type: rule, points, weights, N, dN (plain lists of floats)."""
    t = type_of(name)
    ref = reference(t)
    r = rule_for(t)
    rule_name, degree, points, weights = r.name, r.degree, r.points, r.weights
    xi = ref.xi
    grads = [[sp.diff(n, x) for x in xi] for n in ref.shape_functions]
    N, dN = [], []
    for p in points:
        at = dict(zip(xi, p))
        N.append([_num(n.subs(at)) for n in ref.shape_functions])
        dN.append([[_num(g.subs(at)) for g in row] for row in grads])
    return {"dim": t.dim, "nodes": t.n_nodes, "order": t.order, "domain": t.domain.name,
            "reference_measure": float(t.reference_measure), "rule": rule_name, "degree": degree,
            "points": [[_num(c) for c in p] for p in points], "weights": [_num(w) for w in weights],
            "N": N, "dN": dN}


def build() -> dict:
    """Every element type of the table and every face type they use."""
    names = sorted(set(_solid()) | set(face_types()))
    return {"format": FORMAT, "faces": {e: sorted({f.type for f in _types.get(e).faces}) for e in sorted(_solid())},
            "types": {n: table(n) for n in names}}


def render() -> str:
    """The file's text: sorted keys, float64 written by repr (round-trips exactly): deterministic."""
    return json.dumps(build(), sort_keys=True, separators=(",", ":"), indent=None) + "\n"


def write(out) -> Path:
    """Write <out>/shape_tables.json atomically; returns its path."""
    path = Path(out) / FILE
    write_atomic(path, render())
    return path
