"""The mass-spring system (thesis chapter 3): damped linear springs between particles.

- hexahedron: a cubic lattice, Baudet's stiffnesses (12 edge and 4 inner-diagonal springs per
  cube, no face diagonals, no volume term).  Central springs obey the Cauchy relation: the lattice
  is isotropic only for nu = 1/4 (its volume change barely depends on nu), and it buckles under
  compression (thesis section 3.5).  Cells must be cubes.
- tetra, triangle: a spring on every edge, each simplex adding its share E V / l^2 (Van Gelder).
  No spring network reproduces a given E and nu on an unstructured mesh: measure what you get.
Damping: Rayleigh beta (solver.rayleigh) damps every spring along its axis with d = beta k.
"""
from . import sympy_lazy as sp

from .. import elements
from . import springs
from .base import DiscreteLaw


def simplex_measure(element, X):
    """Volume of a tetrahedron, area of a triangle (unit thickness), from its corners."""
    dim = elements.get(element).dim
    M = sp.Matrix(dim, dim, lambda r, c: X[c + 1, r] - X[0, r])
    return M.det() / (6 if dim == 3 else 2)


def measure(element, X):
    if element == "hexahedron":
        return springs.cube_volume(elements.get(element), X)
    return simplex_measure(element, X)


def energy(element, x, X, E, nu):
    ref = elements.get(element)
    if element == "hexahedron":
        return springs.lattice_energy(ref, x, X, springs.baudet(E, nu, springs.cube_edge(ref, X)))
    V, W = simplex_measure(element, X), 0
    for i, j in ref.edges:
        l = springs.length([X[j, c] - X[i, c] for c in range(ref.dim)])
        W += springs.spring_energy(springs.van_gelder(E, V, l), [x[i, c] for c in range(ref.dim)],
                                   [x[j, c] for c in range(ref.dim)], l)
    return W


def checks(element, X):
    if element == "hexahedron":
        return springs.cube_check(elements.get(element), X)
    return []


LAW = DiscreteLaw(
    name="mss",
    parameters=("E", "nu"),
    element_energy=energy,
    rest_measure=measure,
    rest_checks=checks,
    elements=("hexahedron", "tetra", "triangle"),
    description="mass-spring system: Baudet lattice on cubes, Van Gelder edge springs on simplices",
    validity="nu = 1/4 on cubes (Cauchy limit); buckles in compression; cubic hexahedra only",
)
