"""Stable neo-Hookean (Smith, de Goes, Kim 2018), defined for inverted elements.

W = mu'/2 (I1 - 3) + lam'/2 (J - alpha)^2 - mu'/2 ln(I1 + 1) with the
re-parametrisation mu' = 4/3 mu, lam' = lam + 5/6 mu and alpha = 1 + 3 mu'/(4 lam'),
chosen so that the rest state is stress free and the tangent at rest equals
Hooke's for the user's lam and mu (the tests check both). A constant is
subtracted so that W(I) = 0.
"""
from . import sympy_lazy as sp

from .base import Law, lame_from_E_nu


def energy(F, lam, mu):
    mu_s = sp.Rational(4, 3) * mu
    lam_s = lam + sp.Rational(5, 6) * mu
    alpha = 1 + sp.Rational(3, 4) * mu_s / lam_s
    I1 = (F.T * F).trace()
    J = F.det()
    W = mu_s / 2 * (I1 - 3) + lam_s / 2 * (J - alpha) ** 2 - mu_s / 2 * sp.log(I1 + 1)
    # Shift by the (constant) value at rest so that W(I) = 0 like every other law:
    # energies and line searches then compare like with like.
    rest = lam_s / 2 * (1 - alpha) ** 2 - mu_s / 2 * sp.log(4)
    return W - rest


LAW = Law(
    name="stable_neohookean",
    parameters=("lam", "mu"),
    energy=energy,
    from_E_nu=lambda E, nu: dict(zip(("lam", "mu"), lame_from_E_nu(E, nu))),
    description="stable neo-Hookean (Smith et al. 2018), robust to inversion",
    validity="large strains, inverted elements recover",
)
