"""Saint-Venant–Kirchhoff: Hooke's energy written with the Green–Lagrange strain.

W = lam/2 (tr E)^2 + mu tr(E^2), E = (F^T F - I)/2. Rotation invariant, but it
softens and collapses under strong compression (it has no barrier at J = 0).
"""
from . import sympy_lazy as sp

from .base import Law, lame_from_E_nu


def energy(F, lam, mu):
    E = (F.T * F - sp.eye(3)) / 2
    return lam / 2 * E.trace() ** 2 + mu * (E * E).trace()


LAW = Law(
    name="stvk",
    parameters=("lam", "mu"),
    energy=energy,
    from_E_nu=lambda E, nu: dict(zip(("lam", "mu"), lame_from_E_nu(E, nu))),
    description="Saint-Venant–Kirchhoff (large rotation, moderate strain)",
    validity="large rotations, strains up to ~20 %; unstable under strong compression",
)
