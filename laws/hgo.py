"""Fibre-reinforced tissue: Holzapfel-Gasser-Ogden with one fibre family (transversely isotropic).

    W = mu/2 (J^(-2/3) I1 - 3) + kappa/2 ((J^2 - 1)/2 - ln J)
        + k1 / (2 k2) (exp(k2 <E>^2) - 1),      E = d (I1 - 3) + (1 - 3 d)(I4 - 1),

with I1 = tr C, I4 = a.C.a the squared stretch of the fibre direction a (a unit vector of the rest
configuration, given per cell by the scene: [[material]] fibres), d the fibres' dispersion (0:
perfectly aligned, 1/3: isotropic) and <E> = max(E, 0): fibres carry no compression (Gasser,
Ogden & Holzapfel, J. R. Soc. Interface 3 (2006) 15-35, eq. 2.8).  The fibre term uses the full
invariants I1 and I4, not their isochoric parts: with the isochoric I4 a fibre-reinforced body
under hydrostatic tension does not stay spherical (Nolan, Gower, Destrade, Ogden & McGarry, J.
Mech. Behav. Biomed. Mater. 39 (2014) 48-60).  The matrix is a nearly incompressible neo-Hookean
solid; mu and kappa follow from E and nu of the matrix (k1, k2 and d are given by name).
laws/hgo2.py adds a second family with the same pieces.

At rest E = 0 and the fibre term has no stiffness: small strains see the isotropic matrix.  As E
passes 0 the fibres' stiffness (k1 in d2W/dE2) switches on at once: the tangent jumps there,
which Newton's method meets as a kink.
"""
from . import sympy_lazy as sp

from .base import Law

# the options of every HGO law: ((name, default (None: required), (low, high)), ...)
OPTIONS = (("k1", None, (0.0, float("inf"))), ("k2", None, (1e-6, 1e3)), ("dispersion", 0.0, (0.0, 1 / 3)))


def matrix(F, mu, kappa):
    """The neo-Hookean matrix: mu/2 (J^(-2/3) I1 - 3) + kappa/2 ((J^2 - 1)/2 - ln J)."""
    J = F.det()
    return mu / 2 * (J ** sp.Rational(-2, 3) * (F.T * F).trace() - 3) + kappa / 2 * ((J**2 - 1) / 2 - sp.log(J))


def family(F, a, k1, k2, dispersion):
    """One fibre family of direction a: k1/(2 k2) (exp(k2 <E>^2) - 1), in tension only."""
    C = F.T * F
    E = dispersion * (C.trace() - 3) + (1 - 3 * dispersion) * ((a.T * C * a)[0, 0] - 1)
    return sp.Piecewise((k1 / (2 * k2) * (sp.exp(k2 * E**2) - 1), E > 0), (0, True))


def energy(F, mu, kappa, k1, k2, dispersion, a):
    return matrix(F, mu, kappa) + family(F, a, k1, k2, dispersion)


def from_E_nu(E, nu):
    return {"mu": E / (2 * (1 + nu)), "kappa": E / (3 * (1 - 2 * nu))}


LAW = Law(
    name="hgo",
    parameters=("mu", "kappa"),
    energy=energy,
    from_E_nu=from_E_nu,
    description="Holzapfel-Gasser-Ogden fibre-reinforced (one fibre family, dispersion d)",
    validity="large strains; fibres in tension only; undefined for inverted elements (det F <= 0)",
    requires_positive_J=True,
    options=OPTIONS,
    directions=("a",),
)
