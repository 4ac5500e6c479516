"""Compressible Mooney–Rivlin with isochoric invariants.

W = C10 (I1bar - 3) + C01 (I2bar - 3) + kappa/2 (J - 1)^2,
I1bar = J^(-2/3) I1, I2bar = J^(-4/3) I2, I2 = ((tr C)^2 - tr(C^2))/2.
Small-strain shear modulus mu = 2 (C10 + C01), bulk modulus kappa. From E and nu
we split mu evenly (C10 = C01 = mu/4) and take kappa = lam + 2 mu / 3.
Undefined for J <= 0.
"""
from . import sympy_lazy as sp

from .base import Law, lame_from_E_nu


def energy(F, C10, C01, kappa):
    C = F.T * F
    J = F.det()
    I1 = C.trace()
    I2 = (I1**2 - (C * C).trace()) / 2
    return (C10 * (J ** sp.Rational(-2, 3) * I1 - 3)
            + C01 * (J ** sp.Rational(-4, 3) * I2 - 3)
            + kappa / 2 * (J - 1) ** 2)


def from_E_nu(E, nu):
    lam, mu = lame_from_E_nu(E, nu)
    return {"C10": mu / 4, "C01": mu / 4, "kappa": lam + 2 * mu / 3}


LAW = Law(
    name="mooney_rivlin",
    parameters=("C10", "C01", "kappa"),
    energy=energy,
    from_E_nu=from_E_nu,
    description="compressible Mooney–Rivlin (isochoric split)",
    validity="large strains of rubber-like tissue; undefined for inverted elements",
    requires_positive_J=True,
)
