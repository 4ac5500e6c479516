"""Quadrature rules on the reference domains of the element types (tensormass.elements).

Rules are chosen by the element's reference *domain* (simplex, box, prism,
pyramid) and topological dimension, never by its name.

Values are sympy numbers: exact where a closed form is short (rationals and
square roots), otherwise sp.Float with 30 significant digits, so that the
symbolic pipeline never loses accuracy before code generation.
"""
from __future__ import annotations

import functools
import re
from dataclasses import dataclass

import sympy as sp
from sympy.integrals.quadrature import gauss_jacobi
from sympy.utilities.iterables import multiset_permutations

from ..elements import BOX, PRISM, PYRAMID, SIMPLEX, names as _type_names
from .elements import element as _element

DIGITS = 30
GAUSS_RULES = ("gauss1", "gauss2", "gauss3")  # offered by every element
MAX_N = 20  # largest N accepted in "gaussN" / "collapsedN"

_R = sp.Rational
# simplex rules by topological dimension
_SIMPLEX_DOMAIN = {1: "line", 2: "triangle", 3: "tetra"}


@dataclass(frozen=True)
class QuadratureRule:
    name: str
    element: str
    points: tuple  # one tuple of `dim` coordinates per point
    weights: tuple
    # Simplices, prism, pyramid: total polynomial degree integrated exactly.
    # box (quad/hexahedron): per-direction degree 2N-1.
    degree: int

    @property
    def n_points(self) -> int:
        return len(self.points)


def _num(x):
    """Keep exact numbers exact; round anything touched by a Float to DIGITS."""
    x = sp.sympify(x)
    return sp.Float(x.evalf(DIGITS), DIGITS) if x.has(sp.Float) else x


def _f(s: str) -> sp.Float:
    return sp.Float(s, DIGITS)


# ---------------------------------------------------------------- 1D rules
@functools.cache
def gauss_line(n: int, alpha: int = 0):
    """n-point Gauss rule on [0, 1] for the weight (1 - t)**alpha.

    alpha > 0 absorbs the Jacobian of the collapsed (Duffy) maps below."""
    if alpha == 0 and n <= 3:  # short closed forms of Gauss-Legendre
        r, w = {1: ([0], [2]),
                2: ([-1 / sp.sqrt(3), 1 / sp.sqrt(3)], [1, 1]),
                3: ([-sp.sqrt(_R(3, 5)), 0, sp.sqrt(_R(3, 5))],
                    [_R(5, 9), _R(8, 9), _R(5, 9)])}[n]
    else:
        # sympy solves for the Jacobi roots to the requested precision.
        r, w = gauss_jacobi(n, alpha, 0, DIGITS + 5)
    # x in [-1, 1] -> t = (1 + x)/2; (1 - x)^alpha dx = 2^(alpha+1) (1 - t)^alpha dt
    scale = _R(1, 2 ** (alpha + 1))
    return tuple(_num((1 + x) / 2) for x in r), tuple(_num(scale * v) for v in w)


def _gauss_legendre(n: int):
    """n-point Gauss-Legendre rule on [-1, 1]."""
    t, w = gauss_line(n)
    return tuple(_num(2 * x - 1) for x in t), tuple(_num(2 * v) for v in w)


# ------------------------------------------------- symmetric simplex rules
def _orbit(bary, weight):
    """All distinct permutations of barycentric coordinates; the reference
    coordinates are the barycentrics of vertices 1..d (vertex 0 is the origin)."""
    return [(tuple(p[1:]), weight) for p in multiset_permutations(list(bary))]


def _s21(a, w):
    return _orbit((a, a, 1 - 2 * a), w)


def _s31(a, w):
    return _orbit((a, a, a, 1 - 3 * a), w)


def _s22(a, w):
    return _orbit((a, a, _R(1, 2) - a, _R(1, 2) - a), w)


# The Float constants below solve the symmetric moment equations (done with
# mpmath at 50 digits); tests re-check every moment to ~1e-25.
def _triangle_symmetric():
    """(degree, points-with-weights) for the unit triangle, cheapest first."""
    r15 = sp.sqrt(15)
    return [
        (1, [((_R(1, 3), _R(1, 3)), _R(1, 2))]),
        (2, _s21(_R(1, 6), _R(1, 6))),
        # Dunavant's 6-point degree-4 rule (also covers degree 3).
        (4, _s21(_f("0.445948490915964886318329253883052"),
                 _f("0.111690794839005732847503504216561"))
         + _s21(_f("0.0915762135097707434595714634022015"),
                _f("0.0549758718276609338191631624501053"))),
        # Radon's 7-point degree-5 rule (closed form).
        (5, [((_R(1, 3), _R(1, 3)), _R(9, 80))]
         + _s21((6 - r15) / 21, (155 - r15) / 2400)
         + _s21((6 + r15) / 21, (155 + r15) / 2400)),
    ]


def _tetra_symmetric():
    """(degree, points-with-weights) for the unit tetrahedron, cheapest first."""
    return [
        (1, [((_R(1, 4),) * 3, _R(1, 6))]),
        (2, _s31((5 - sp.sqrt(5)) / 20, _R(1, 24))),
        # Two 4-point orbits with equal weights: positive degree-3 rule
        # (the classic 5-point degree-3 rule has a negative weight).
        (3, _s31(_f("0.112956794512511028695146988892604"), _R(1, 48))
         + _s31(_f("0.328861649930202910400319367826022"), _R(1, 48))),
        # Keast/Walkington 14-point positive degree-5 rule.
        (5, _s31(_f("0.0927352503108912264023239137370306"),
                 _f("0.0122488405193936582572850342477213"))
         + _s31(_f("0.310885919263300609797345733763458"),
                _f("0.0187813209530026417998642753888811"))
         + _s22(_f("0.0455037041256496494918805262793394"),
                _f("0.00709100346284691107301157135337624"))),
    ]


# ------------------------------------------------------ collapsed rules
def _collapsed_triangle(n):
    # (u, v) in [0,1]^2 -> (u (1 - v), v); Jacobian (1 - v) goes into the v weight.
    (tu, wu), (tv, wv) = gauss_line(n), gauss_line(n, 1)
    return [((u * (1 - v), v), a * b) for u, a in zip(tu, wu) for v, b in zip(tv, wv)]


def _collapsed_tetra(n):
    # (u, v, w) -> (u (1-v)(1-w), v (1-w), w); Jacobian (1-v)(1-w)^2.
    (tu, wu), (tv, wv), (tw, ww) = gauss_line(n), gauss_line(n, 1), gauss_line(n, 2)
    return [((u * (1 - v) * (1 - w), v * (1 - w), w), a * b * c)
            for u, a in zip(tu, wu) for v, b in zip(tv, wv) for w, c in zip(tw, ww)]


def _simplex_gauss(domain, n):
    """Cheapest rule of total degree >= n: a symmetric one if available,
    else the collapsed rule with n//2 + 1 points per direction."""
    if domain == "line":
        return _collapsed(domain, n // 2 + 1)
    table = _triangle_symmetric() if domain == "triangle" else _tetra_symmetric()
    for degree, pw in table:
        if degree >= n:
            return degree, pw
    return _collapsed(domain, n // 2 + 1)


def _collapsed(domain, m):
    if domain == "line":  # [0, 1]: plain Gauss-Legendre
        pw = [((t,), w) for t, w in zip(*gauss_line(m))]
    else:
        pw = _collapsed_triangle(m) if domain == "triangle" else _collapsed_tetra(m)
    return 2 * m - 1, pw


# ----------------------------------------------------------- public API
def _make(name, element_name, degree, pw) -> QuadratureRule:
    points = tuple(tuple(_num(c) for c in p) for p, _ in pw)
    weights = tuple(_num(w) for _, w in pw)
    return QuadratureRule(name, element_name, points, weights, degree)


def _simplex_domain(ref):
    """'line' / 'triangle' / 'tetra' for simplex elements, else None."""
    t = ref.type
    return _SIMPLEX_DOMAIN.get(t.dim) if t.domain == SIMPLEX else None


def _valid_names(ref):
    names = f"gaussN (N = 1..{MAX_N})"
    if _simplex_domain(ref) is not None:
        names += f", collapsedN (N = 1..{MAX_N})"
    return names


@functools.cache
def rule(element_name: str, name: str) -> QuadratureRule:
    """Quadrature rule `name` ("gaussN") on the reference domain of `element_name`.

    box (quad/hexahedron): N-point Gauss-Legendre per direction.
    simplex (triangle/tetra + quadratic variants): exact for total degree N.
    prism (wedge): triangle gaussN x N-point Gauss-Legendre in zeta.
    pyramid: N x N Gauss-Legendre x N-point Gauss-Jacobi collapsed to the apex.
    Simplices also accept "collapsedN" (N points per collapsed direction)."""
    try:
        ref = _element(element_name)
    except ValueError:
        raise ValueError(f"unknown element {element_name!r}; known: {', '.join(_type_names())}") from None
    m = re.fullmatch(r"(gauss|collapsed)([1-9][0-9]*)", name)
    n = int(m.group(2)) if m else 0
    domain = _simplex_domain(ref)
    if not m or n > MAX_N or (m.group(1) == "collapsed" and domain is None):
        raise ValueError(f"unknown rule {name!r} for {element_name}; valid: "
                         f"{_valid_names(ref)}")

    if domain is not None:
        degree, pw = (_simplex_gauss(domain, n) if m.group(1) == "gauss"
                      else _collapsed(domain, n))
        return _make(name, element_name, degree, pw)

    x, w = _gauss_legendre(n)
    line = list(zip(x, w))
    kind, dim = ref.type.domain, ref.dim
    if kind == BOX and dim == 1:
        pw = [((a,), wa) for a, wa in line]
        degree = 2 * n - 1
    elif kind == BOX and dim == 2:
        pw = [((a, b), wa * wb) for b, wb in line for a, wa in line]
        degree = 2 * n - 1
    elif kind == BOX and dim == 3:
        pw = [((a, b, c), wa * wb * wc) for c, wc in line for b, wb in line for a, wa in line]
        degree = 2 * n - 1
    elif kind == PRISM and dim == 3:
        tri_degree, tri = _simplex_gauss("triangle", n)
        pw = [((p[0], p[1], c), wp * wc) for p, wp in tri for c, wc in line]
        degree = min(tri_degree, 2 * n - 1)
    elif kind == PYRAMID and dim == 3:
        # x = a (1 - z), y = b (1 - z): the Jacobian (1 - z)^2 is the Jacobi
        # weight, and the rational shape functions become polynomials in (a, b, z).
        tz, wz = gauss_line(n, 2)
        pw = [((a * (1 - z), b * (1 - z), z), wa * wb * wzz)
              for z, wzz in zip(tz, wz) for b, wb in line for a, wa in line]
        degree = 2 * n - 1
    else:
        raise ValueError(f"no quadrature rule on the {dim}D {kind.name} domain of {element_name}")
    return _make(name, element_name, degree, pw)


def rule_for_degree(element_name: str, degree: int) -> QuadratureRule:
    """Cheapest rule of this module exact for total degree >= `degree`
    (simplex domains only: triangle, triangle6, tetra, tetra10, ...)."""
    try:
        ref = _element(element_name)
    except ValueError:
        ref = None
    if ref is None or _simplex_domain(ref) is None:
        simplices = [t for t in _type_names() if _simplex_domain(_element(t)) is not None]
        raise ValueError(f"rule_for_degree supports simplices only "
                         f"({', '.join(simplices)}), not {element_name!r}")
    d = max(int(degree), 1)
    if d > 2 * MAX_N - 1:
        raise ValueError(f"degree {degree} exceeds the supported maximum {2 * MAX_N - 1}")
    candidates = [rule(element_name, f"gauss{d}"), rule(element_name, f"collapsed{d // 2 + 1}")]
    return min(candidates, key=lambda r: r.n_points)  # ties keep the symmetric rule
