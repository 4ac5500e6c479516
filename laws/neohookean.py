"""Compressible neo-Hookean: W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2.

I1 = tr(F^T F), J = det F. Undefined for J <= 0: kernels flag inverted elements.
"""
from . import sympy_lazy as sp

from .base import Law, lame_from_E_nu


def energy(F, lam, mu):
    I1 = (F.T * F).trace()
    lnJ = sp.log(F.det())
    return mu / 2 * (I1 - 3) - mu * lnJ + lam / 2 * lnJ**2


LAW = Law(
    name="neohookean",
    parameters=("lam", "mu"),
    energy=energy,
    from_E_nu=lambda E, nu: dict(zip(("lam", "mu"), lame_from_E_nu(E, nu))),
    description="compressible neo-Hookean",
    validity="large strains; undefined for inverted elements (det F <= 0)",
    requires_positive_J=True,
)
