"""Reference elements (shape functions, VTK orientation) and quadrature rules."""
from math import factorial
from itertools import product

import mpmath
import pytest
import sympy as sp

from tensormass.generator.elements import ELEMENTS, XI, element
from tensormass.generator import quadrature
from tensormass.generator.quadrature import GAUSS_RULES, rule, rule_for_degree

NAMES = ["hexahedron", "pyramid", "quad", "tetra", "tetra10", "triangle", "triangle6", "wedge"]
SIMPLICES = ["triangle", "triangle6", "tetra", "tetra10"]
TOL = mpmath.mpf("1e-25")  # rules carry 30 significant digits


# ------------------------------------------------------------- helpers
def at(expr, xi, point):
    """Value at a point; substituting the last coordinate after cancelling
    resolves the pyramid's 0/0 at its apex (its limit is well defined)."""
    expr = sp.cancel(expr.subs(dict(zip(xi[:-1], point[:-1]))))
    return sp.simplify(expr.subs(xi[-1], point[-1]))


def line(k):
    """Integral of t^k over [-1, 1]."""
    return sp.Rational(2, k + 1) if k % 2 == 0 else sp.Integer(0)


def exact_monomial(name, e):
    """Closed-form integral of xi^a eta^b (zeta^c) over the reference domain."""
    f = factorial
    if name in ("triangle", "triangle6"):
        return sp.Rational(f(e[0]) * f(e[1]), f(sum(e) + 2))
    if name in ("tetra", "tetra10"):
        return sp.Rational(f(e[0]) * f(e[1]) * f(e[2]), f(sum(e) + 3))
    if name in ("quad", "hexahedron"):
        return sp.Mul(*[line(k) for k in e])
    if name == "wedge":
        return exact_monomial("triangle", e[:2]) * line(e[2])
    if name == "pyramid":  # |x|,|y| <= 1 - z: a Beta integral in z
        a, b, c = e
        return line(a) * line(b) * sp.Rational(f(c) * f(a + b + 2), f(a + b + c + 3))
    raise KeyError(name)


def integrate_exact(name, expr):
    """sympy integration over the reference domain (slow; used sparingly)."""
    x, y, z = XI
    if name == "pyramid":
        # collapsed coordinates x = (1 - z) s, y = (1 - z) t, dx dy = (1 - z)^2 ds dt: the rational pyramid
        # functions become polynomials over [-1, 1]^2 x [0, 1], integrated term by term in closed form
        s, t = sp.symbols("s t")
        num, den = sp.fraction(sp.cancel(expr.subs({x: (1 - z) * s, y: (1 - z) * t}, simultaneous=True)
                                         * (1 - z) ** 2))
        if not den.free_symbols:
            terms = sp.Poly(num, s, t, z).terms()
            return sum((c * line(a) * line(b) * sp.Rational(1, k + 1) for (a, b, k), c in terms),
                       sp.Integer(0)) / den
    limits = {
        "triangle": [(y, 0, 1 - x), (x, 0, 1)],
        "quad": [(x, -1, 1), (y, -1, 1)],
        "tetra": [(z, 0, 1 - x - y), (y, 0, 1 - x), (x, 0, 1)],
        "hexahedron": [(x, -1, 1), (y, -1, 1), (z, -1, 1)],
        "wedge": [(y, 0, 1 - x), (x, 0, 1), (z, -1, 1)],
        "pyramid": [(x, z - 1, 1 - z), (y, z - 1, 1 - z), (z, 0, 1)],
    }
    limits["triangle6"], limits["tetra10"] = limits["triangle"], limits["tetra"]
    return sp.integrate(expr, *limits[name])


def mp_rule(r):
    """Points and weights as 40-digit mpmath numbers for fast, accurate sums."""
    with mpmath.workdps(40):
        pts = [[mpmath.mpf(str(sp.N(c, 40))) for c in p] for p in r.points]
        ws = [mpmath.mpf(str(sp.N(w, 40))) for w in r.weights]
    return pts, ws


def monomial_errors(r, exponents):
    """{exponent tuple: |quadrature - exact|}, with power tables per point."""
    pts, ws = mp_rule(r)
    top = max(max(e) for e in exponents)
    out = {}
    with mpmath.workdps(40):
        powers = [[[c**k for k in range(top + 1)] for c in p] for p in pts]
        for e in exponents:
            q = mpmath.fsum(w * mpmath.fprod(pw[d][k] for d, k in enumerate(e))
                            for w, pw in zip(ws, powers))
            exact = exact_monomial(r.element, e)
            out[e] = abs(q - mpmath.mpf(exact.p) / exact.q)
    return out


def total_degree(dim, degree):
    return [e for e in product(range(degree + 1), repeat=dim) if sum(e) == degree]


def up_to(dim, degree):
    return [e for d in range(degree + 1) for e in total_degree(dim, d)]


# ------------------------------------------------------------ elements
def test_catalogue():
    # the solids, and the shell triangle (6 dofs per node: generator/shell.py, no solid kernels)
    assert [n for n in ELEMENTS if n != "shell"] == NAMES and "shell" in ELEMENTS
    for name in NAMES:
        el = element(name)
        assert el.name == name and el.n_nodes == len(el.shape_functions) == len(el.nodes)
        assert el.xi == XI[: el.dim]
        assert el.gradients().shape == (el.n_nodes, el.dim)
    assert (element("pyramid").polynomial, element("tetra10").order) == (False, 2)
    with pytest.raises(ValueError, match="tetra10"):
        element("prism")


@pytest.mark.parametrize("name", NAMES)
def test_kronecker_delta(name):
    el = element(name)
    for i, n in enumerate(el.shape_functions):
        for j, p in enumerate(el.nodes):
            assert at(n, el.xi, p) == (1 if i == j else 0), (i, j)


@pytest.mark.parametrize("name", NAMES)
def test_partition_of_unity_and_linear_completeness(name):
    el = element(name)
    assert sp.cancel(sum(el.shape_functions) - 1) == 0
    for k, x in enumerate(el.xi):
        interp = sum(n * p[k] for n, p in zip(el.shape_functions, el.nodes))
        assert sp.cancel(interp - x) == 0
    G = el.gradients()
    for k, x in enumerate(el.xi):
        assert sp.cancel(sum(G[:, k])) == 0
        for i, n in enumerate(el.shape_functions):
            assert sp.cancel(G[i, k] - sp.diff(n, x)) == 0


@pytest.mark.parametrize("name", NAMES)
def test_identity_map_has_unit_jacobian(name):
    el = element(name)
    point = [sp.Rational(1, 5), sp.Rational(1, 7), sp.Rational(1, 3)][: el.dim]  # interior
    G = el.gradients().subs(dict(zip(el.xi, point)))
    X = sp.Matrix(el.nodes)  # reference nodes used as physical nodes
    J = X.T * G  # dx_a/dxi_k
    assert sp.simplify(J.det()) == 1


def _vertices(el):
    return [sp.Matrix(p) for p in el.nodes]


def test_vtk_orientation_conventions():
    # 2D: counter-clockwise vertices.
    for name in ("triangle", "triangle6", "quad"):
        v = _vertices(element(name))
        assert (v[1] - v[0]).row_join(v[2] - v[0]).det() > 0
    # 3D: right-hand normal of the face (0,1,2) points towards node 3 / 4 / the
    # apex (vtkTetra, vtkHexahedron, vtkPyramid) but away from (3,4,5) for vtkWedge.
    for name, other, sign in [("tetra", 3, 1), ("tetra10", 3, 1), ("hexahedron", 4, 1),
                              ("pyramid", 4, 1), ("wedge", 3, -1)]:
        v = _vertices(element(name))
        normal = (v[1] - v[0]).cross(v[2] - v[0])
        assert sign * normal.dot(v[other] - v[0]) > 0, name


def test_quadratic_midside_nodes_follow_vtk():
    for name, edges in [("triangle6", [(0, 1), (1, 2), (2, 0)]),
                        ("tetra10", [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)])]:
        el = element(name)
        nv = el.n_nodes - len(edges)
        for k, (i, j) in enumerate(edges):
            mid = tuple((a + b) / 2 for a, b in zip(el.nodes[i], el.nodes[j]))
            assert el.nodes[nv + k] == mid


@pytest.mark.parametrize("name", NAMES)
def test_volume_and_closed_forms(name):
    el = element(name)
    assert integrate_exact(name, sp.Integer(1)) == el.volume()
    x = XI
    mono = x[0] ** 2 * x[1] * (x[2] ** 2 if el.dim == 3 else 1)
    e = (2, 1, 2)[: el.dim]
    assert integrate_exact(name, mono) == exact_monomial(name, e)
    even = (2, 2, 2)[: el.dim]
    assert integrate_exact(name, sp.Mul(*[c**2 for c in el.xi])) == exact_monomial(name, even)


# ---------------------------------------------------------- quadrature
def _inside(name, p):
    p = [float(c) for c in p]
    if name in ("triangle", "triangle6"):
        return p[0] > 0 and p[1] > 0 and p[0] + p[1] < 1
    if name in ("tetra", "tetra10"):
        return min(p) > 0 and sum(p) < 1
    if name in ("quad", "hexahedron"):
        return max(abs(c) for c in p) < 1
    if name == "wedge":
        return p[0] > 0 and p[1] > 0 and p[0] + p[1] < 1 and abs(p[2]) < 1
    if name == "pyramid":
        return 0 < p[2] < 1 and abs(p[0]) < 1 - p[2] and abs(p[1]) < 1 - p[2]
    raise KeyError(name)


ALL_RULES = [(e, f"gauss{n}") for e in NAMES for n in range(1, 7)] + [
    (e, f"collapsed{n}") for e in ("triangle", "tetra") for n in range(1, 5)]


@pytest.mark.parametrize("name,rule_name", ALL_RULES)
def test_rule_basics(name, rule_name):
    r = rule(name, rule_name)
    el = element(name)
    assert (r.name, r.element) == (rule_name, name)
    assert r.n_points == len(r.weights) > 0
    assert all(len(p) == el.dim for p in r.points)
    assert all(_inside(name, p) for p in r.points)
    assert all(w > 0 for w in r.weights)
    assert abs(sp.N(sum(r.weights) - el.volume(), 40)) < 1e-25
    assert len(set(r.points)) == r.n_points


@pytest.mark.parametrize("name,rule_name", ALL_RULES)
def test_rule_exactness(name, rule_name):
    r = rule(name, rule_name)
    dim = element(name).dim
    if name in ("quad", "hexahedron"):  # per direction, degree 2N-1
        exact = list(product(range(r.degree + 1), repeat=dim))
        if len(exact) > 1000:  # keep it fast: total degree plus the top corner
            exact = up_to(dim, r.degree) + [(r.degree,) * dim]
        beyond = [(r.degree + 1,) + (0,) * (dim - 1)]
    else:
        exact = up_to(dim, r.degree)
        beyond = total_degree(dim, r.degree + 1)
    errors = monomial_errors(r, exact)
    assert max(errors.values()) < TOL, max(errors, key=errors.get)
    # The claimed degree is tight: some monomial of degree + 1 is missed.
    assert max(monomial_errors(r, beyond).values()) > 1e-8


def test_wedge_is_triangle_times_line():
    # gauss3: 6-point degree-4 triangle rule times 3 Gauss points (degree 5).
    r = rule("wedge", "gauss3")
    assert r.n_points == 18
    exps = [(a, b, c) for a, b in up_to(2, 4) for c in range(6)]
    assert max(monomial_errors(r, exps).values()) < TOL


def test_simplex_rule_choices():
    assert [rule("triangle", g).n_points for g in GAUSS_RULES] == [1, 3, 6]
    assert [rule("tetra", g).n_points for g in GAUSS_RULES] == [1, 4, 8]
    assert rule("tetra", "gauss4").n_points == 14
    assert rule("triangle", "gauss5").n_points == 7
    # Short closed forms stay exact.
    assert all(isinstance(w, sp.Rational) for w in rule("triangle", "gauss2").weights)
    assert not any(c.has(sp.Float) for p in rule("tetra", "gauss2").points for c in p)
    assert not any(c.has(sp.Float) for p in rule("hexahedron", "gauss3").points for c in p)


@pytest.mark.parametrize("name", SIMPLICES)
def test_rule_for_degree(name):
    dim = element(name).dim
    for d in range(0, 9):
        r = rule_for_degree(name, d)
        assert r.degree >= d and r.element == name
        assert r.n_points <= rule(name, f"gauss{max(d, 1)}").n_points
        assert rule(name, r.name) == r  # the name round-trips
        assert max(monomial_errors(r, total_degree(dim, d)).values()) < TOL
    assert rule_for_degree("triangle", 3).n_points == 4  # collapsed 2x2 beats 6 points


def test_pyramid_rational_space():
    el = element("pyramid")
    G, N = el.gradients(), el.shape_functions
    pairs = [(i, j) for i in range(5) for j in range(i, 5)]
    stiff = {(i, j): integrate_exact("pyramid", (G[i, :] * G[j, :].T)[0]) for i, j in pairs}
    mass = {(i, j): integrate_exact("pyramid", N[i] * N[j]) for i, j in pairs}
    fG = sp.lambdify(el.xi, G, modules="mpmath")
    fN = sp.lambdify(el.xi, sp.Matrix(N), modules="mpmath")

    def errors(r, f, ref, kind):
        pts, ws = mp_rule(r)
        with mpmath.workdps(40):
            vals = [f(*p) for p in pts]
            out = []
            for i, j in pairs:
                if kind == "stiff":
                    q = mpmath.fsum(w * sum(v[i, k] * v[j, k] for k in range(3))
                                    for w, v in zip(ws, vals))
                else:
                    q = mpmath.fsum(w * v[i] * v[j] for w, v in zip(ws, vals))
                out.append(abs(q - mpmath.mpf(ref[i, j].p) / ref[i, j].q))
        return max(out)

    for n in (2, 3):
        r = rule("pyramid", f"gauss{n}")
        assert errors(r, fG, stiff, "stiff") < TOL
        assert errors(r, fN, mass, "mass") < TOL
    # One point is not enough for the rational stiffness integrand.
    assert errors(rule("pyramid", "gauss1"), fG, stiff, "stiff") > 1e-8


def test_invalid_requests():
    with pytest.raises(ValueError, match="gaussN"):
        rule("tetra", "gauss0")
    with pytest.raises(ValueError, match="gaussN"):
        rule("quad", "collapsed2")
    with pytest.raises(ValueError, match="gaussN"):
        rule("hexahedron", "simpson")
    with pytest.raises(ValueError, match="tetra"):
        rule("prism", "gauss1")
    with pytest.raises(ValueError, match="simplices"):
        rule_for_degree("hexahedron", 2)


def test_deterministic():
    a = rule("pyramid", "gauss4")
    rule.cache_clear()
    quadrature.gauss_line.cache_clear()  # recompute the Gauss-Jacobi roots too
    b = rule("pyramid", "gauss4")
    assert a is not b and a == b
    assert [str(c) for p in a.points for c in p] == [str(c) for p in b.points for c in p]
