# yeoh.py: the Yeoh law, W = C10 (I1bar - 3) + C20 (I1bar - 3)^2 + kappa/2 (J - 1)^2
import sympy as sp

from tensormass.laws import Law


def energy(F, C10, C20, kappa):
    J = F.det()
    I1bar = J ** sp.Rational(-2, 3) * (F.T * F).trace()      # isochoric first invariant
    return C10 * (I1bar - 3) + C20 * (I1bar - 3) ** 2 + kappa / 2 * (J - 1) ** 2


def from_E_nu(E, nu):
    """At small strain Yeoh is Hooke with shear modulus 2 C10 and bulk modulus kappa."""
    return {"C10": E / (4 * (1 + nu)), "C20": 0 * E, "kappa": E / (3 * (1 - 2 * nu))}


LAW = Law(
    name="yeoh",
    parameters=("C10", "C20", "kappa"),
    energy=energy,
    from_E_nu=from_E_nu,
    description="Yeoh (isochoric I1bar, volumetric (J - 1)^2)",
    validity="large strains of rubber-like solids; undefined for inverted elements (det F <= 0)",
    requires_positive_J=True,
)
