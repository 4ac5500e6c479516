"""Hooke: linear elasticity, W = lam/2 (tr eps)^2 + mu tr(eps^2), eps = sym(grad u).

Small strains only (< ~10 %): eps is not invariant under rotation, so a rigidly
rotated body feels spurious ("ghost") forces.
"""
from . import sympy_lazy as sp

from .base import Law, lame_from_E_nu


def energy(F, lam, mu):
    eps = (F + F.T) / 2 - sp.eye(3)
    return lam / 2 * eps.trace() ** 2 + mu * (eps * eps).trace()


LAW = Law(
    name="hooke",
    parameters=("lam", "mu"),
    energy=energy,
    from_E_nu=lambda E, nu: dict(zip(("lam", "mu"), lame_from_E_nu(E, nu))),
    description="linear elasticity (small strain)",
    validity="strains below ~10 %, small rotations",
)
