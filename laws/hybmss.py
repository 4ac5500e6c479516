"""HybMSS, the hybrid mass-spring system of the thesis (chapter 7, Golec et al.) on cubic cells.

Per cube: 12 edge, 12 face-diagonal and 4 inner-diagonal springs with the lattice stiffnesses of
springs.hybmss (ratio A = k_f / k_c of face-diagonal to inner-diagonal stiffness; A = 0 is
HybMSS-FD), plus the volume-correction energy 1/2 kappa (V - V0)^2 / V0 of the cube's averaged
volume (eq. 7.13), kappa = E (4 nu - 1) / (2 (1 + nu)(1 - 2 nu)).  Small strains: the isotropic
linear material of E and nu for any nu in (-1, 0.5).  The restoring force is -grad W (the printed
eq. 7.12 has the opposite sign).  Cells must be cubes.
"""
from .. import elements
from . import springs
from .base import DiscreteLaw


def energy(element, x, X, E, nu, A):
    ref = elements.get(element)
    l = springs.cube_edge(ref, X)
    V0, V = springs.cube_volume(ref, X), springs.cube_volume(ref, x)
    kappa = springs.volume_modulus(E, nu)
    return springs.lattice_energy(ref, x, X, springs.hybmss(E, nu, A, l)) + kappa / 2 * (V - V0) ** 2 / V0


LAW = DiscreteLaw(
    name="hybmss",
    parameters=("E", "nu", "A"),
    options=(("A", 1.0, (0.0, 1e6)),),
    element_energy=energy,
    rest_measure=lambda element, X: springs.cube_volume(elements.get(element), X),
    rest_checks=lambda element, X: springs.cube_check(elements.get(element), X),
    elements=("hexahedron",),
    description="hybrid mass-spring system: cube lattice springs + volume correction (any nu)",
    validity="small strains reproduce E and nu; cubic hexahedra only; stable in compression for A > 0",
)
