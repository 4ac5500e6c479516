"""Springs and lattice cubes: the pieces the discrete laws (mss.py, hybmss.py) are written with.

Everything here works on sympy expressions (the generator) and on numpy values (tests, reports):
only arithmetic and sqrt.

Spring energy: W = 1/2 k (|x_j - x_i| - l)^2, l the rest length (thesis eq. 3.1).

A cube of a lattice (an 8-node hexahedron whose rest shape is a cube of edge l) holds three
families of springs, found from the reference node coordinates s_a in {-1, 1}^3:
  edges            12, node pairs that differ in one coordinate        (rest length l)
  face diagonals   12, pairs that differ in two coordinates            (l sqrt 2)
  inner diagonals   4, pairs that differ in all three                  (l sqrt 3)
A lattice spring is shared by the cubes around it; each cube carries its share of the lattice
stiffness (an edge 1/4 of k_e, a face diagonal 1/2 of k_f, an inner diagonal all of k_c), and the
assembly adds the shares: an interior edge gets k_e, a boundary face diagonal k_f / 2 (thesis
section 7.4, the multiplicity rule), with nothing counted by hand.

Stiffness rules (named parameter conversions; G = E / (2 (1 + nu))):
  baudet(E, nu, l)      Baudet et al. 2009 per-cube values: edge E l (4 nu + 1) / (8 (1 + nu)),
                        inner diagonal 3 E l / (8 (1 + nu)); no face diagonals.  A lattice of
                        central springs has C_xxyy = C_xyxy (the Cauchy relation): it is isotropic
                        only at nu = 1/4, whatever the stiffnesses.
  hybmss(E, nu, A, l)   Golec et al. (thesis eq. 7.7, with G for any nu):
                        k_c = 3 G l / (4 + 3 A), k_f = A k_c, k_e = k_f + 8/3 k_c: the springs give
                        lambda = mu = G; the volume term kappa = E (4 nu - 1) / (2 (1 + nu)(1 - 2 nu))
                        (= K - 5/3 G, eq. 7.18) adds kappa to lambda.  A = 0 is HybMSS-FD.
  van_gelder(E, measure, l)   an edge of a simplex: k = E V / l^2 (V the simplex's volume, or area
                        x unit thickness in 2D; Van Gelder 1998), summed over the simplices sharing
                        the edge by the assembly.
"""
from __future__ import annotations

from . import sympy_lazy as sp

EDGE, FACE_DIAGONAL, INNER_DIAGONAL = "edge", "face_diagonal", "inner_diagonal"


def _sqrt(x):
    return sp.sqrt(x) if isinstance(x, sp.Basic) else x ** 0.5


def length(d) -> object:
    """|d| of a vector given as a sequence."""
    return _sqrt(sum(c * c for c in d))


def spring_energy(k, xi, xj, l):
    """1/2 k (|x_j - x_i| - l)^2."""
    return k / 2 * (length([b - a for a, b in zip(xi, xj)]) - l) ** 2


def corner_signs(element_type) -> list:
    """The reference corner coordinates of a hexahedron as signs in {-1, 1}^3, node by node."""
    return [tuple(int(c) for c in node) for node in element_type.nodes[:8]]


def cube_springs(element_type) -> dict:
    """{family: [(i, j), ...]} of a cube's 28 lattice springs, from its reference nodes."""
    s = corner_signs(element_type)
    families = {1: EDGE, 2: FACE_DIAGONAL, 3: INNER_DIAGONAL}
    out = {EDGE: [], FACE_DIAGONAL: [], INNER_DIAGONAL: []}
    for i in range(8):
        for j in range(i + 1, 8):
            out[families[sum(a != b for a, b in zip(s[i], s[j]))]].append((i, j))
    return out


def cube_axes(element_type, x) -> list:
    """The thesis' averaged edge vectors X, Y, Z of a cube (eq. 7.13): axis k is 1/4 of the sum of
    its four edges, sum_a s_a[k] x_a / 4.  For a parallelepiped they are its edges."""
    s = corner_signs(element_type)
    return [[sum(s[a][k] * x[a, c] for a in range(8)) / 4 for c in range(3)] for k in range(3)]


def cube_volume(element_type, x):
    """V = X . (Y x Z) of the averaged edge vectors (thesis eq. 7.13): exact for parallelepipeds."""
    X, Y, Z = cube_axes(element_type, x)
    return (X[0] * (Y[1] * Z[2] - Y[2] * Z[1]) - X[1] * (Y[0] * Z[2] - Y[2] * Z[0])
            + X[2] * (Y[0] * Z[1] - Y[1] * Z[0]))


def cube_edge(element_type, X):
    """The edge l of a rest cube: the cube root of its volume."""
    V = cube_volume(element_type, X)
    return V ** sp.Rational(1, 3) if isinstance(V, sp.Basic) else V ** (1.0 / 3.0)


def cube_check(element_type, X, flag: int = 2, tolerance: float = 1e-6) -> list:
    """Flag a rest hexahedron that is not a cube: the squared relative errors of its 28 spring
    lengths (l, l sqrt 2, l sqrt 3 with l from its volume) summed, against tolerance (1e-6: lengths
    within about 0.1 %).  Edges and face diagonals fix a cube up to a rigid motion."""
    l2 = cube_edge(element_type, X) ** 2
    deviation = 0
    for family, pairs in cube_springs(element_type).items():
        ideal = {EDGE: 1, FACE_DIAGONAL: 2, INNER_DIAGONAL: 3}[family] * l2
        for i, j in pairs:
            d2 = sum((X[j, c] - X[i, c]) ** 2 for c in range(3))
            deviation += (d2 / ideal - 1) ** 2
    return [(deviation, sp.Float(tolerance), flag,
             "not a cube (edges or angles differ by more than about 0.1 %): the lattice stiffnesses hold "
             "for cubic cells only")]


# --------------------------------------------------------------------------- stiffness rules


def shear_modulus(E, nu):
    return E / (2 * (1 + nu))


def baudet(E, nu, l) -> dict:
    """Per-cube spring stiffnesses of Baudet et al. 2009 (N/m): {edge, inner_diagonal}."""
    return {EDGE: E * l * (4 * nu + 1) / (8 * (1 + nu)), INNER_DIAGONAL: 3 * E * l / (8 * (1 + nu))}


def hybmss_lattice(E, nu, A, l) -> dict:
    """The lattice stiffnesses of HybMSS (N/m; thesis eq. 7.7 with G = E / (2 (1 + nu))):
    {edge: k_e, face_diagonal: k_f, inner_diagonal: k_c}."""
    k_c = 3 * shear_modulus(E, nu) * l / (4 + 3 * A)
    k_f = A * k_c
    return {EDGE: k_f + sp.Rational(8, 3) * k_c if isinstance(k_c, sp.Basic) else k_f + 8.0 / 3.0 * k_c,
            FACE_DIAGONAL: k_f, INNER_DIAGONAL: k_c}


# the share of a lattice spring one cube carries: 4 cubes around an edge, 2 around a face diagonal
CUBE_SHARE = {EDGE: 4, FACE_DIAGONAL: 2, INNER_DIAGONAL: 1}


def hybmss(E, nu, A, l) -> dict:
    """Per-cube spring stiffnesses of HybMSS (the lattice values over the cubes sharing them)."""
    return {f: k / CUBE_SHARE[f] for f, k in hybmss_lattice(E, nu, A, l).items()}


def volume_modulus(E, nu):
    """kappa of the volume-correction energy 1/2 kappa (V - V0)^2 / V0 (Pa; thesis eq. 7.18):
    E (4 nu - 1) / (2 (1 + nu)(1 - 2 nu)); 0 at nu = 1/4, negative below."""
    return E * (4 * nu - 1) / (2 * (1 + nu) * (1 - 2 * nu))


def van_gelder(E, measure, l):
    """An edge spring's share from one simplex: E V / l^2 (N/m)."""
    return E * measure / l ** 2


def lattice_energy(element_type, x, X, per_cube: dict):
    """The springs of one cube with the given per-cube stiffnesses {family: k}."""
    W = 0
    for family, pairs in cube_springs(element_type).items():
        k = per_cube.get(family)
        if k is None:
            continue
        for i, j in pairs:
            l = length([X[j, c] - X[i, c] for c in range(3)])
            W += spring_energy(k, [x[i, c] for c in range(3)], [x[j, c] for c in range(3)], l)
    return W
