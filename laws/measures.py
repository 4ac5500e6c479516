"""Volume measures theta(F): what the volumetric part of a law depends on.

A locking-free formulation (runtime.formulations) evaluates a law's volumetric energy U(theta) at
a measure averaged over an element or a node's cells instead of at every integration point.  The
measure depends on the law (generator.volumetric finds which one by splitting the law):

- volume:            theta = det F          (neo-Hookean, stable neo-Hookean, Mooney-Rivlin: ln J, (J - 1)^2)
- dilatation:        theta = tr F - 2 = 1 + tr eps        (Hooke: the small-strain volume change)
- green_dilatation:  theta = (tr F^T F - 1) / 2 = 1 + tr E (Saint-Venant-Kirchhoff)

Each is 1 at rest, also for 2D elements (plane strain: F33 = 1), so that theta integrated over an
element is its rest volume.  Each is written as a parameter-free "law" so that the generator gives
its kernels (energy = integral of theta, forces, Hessian) like any law's; they are not materials:
laws.names() does not list them and a scene cannot choose them.
"""
from . import sympy_lazy as sp

from .base import Law


def volume(F):
    return F.det()


def dilatation(F):
    return F.trace() - 2


def green_dilatation(F):
    return ((F.T * F).trace() - 1) / 2


def _measure(name, energy, description, representative):
    law = Law(name=f"measure_{name}", parameters=(), energy=energy, from_E_nu=lambda E, nu: {},
              description=description, validity="a volume measure for locking-free formulations, not a material")
    return law, representative


# name -> (Law, F_theta): F_theta(theta) is a deformation gradient with that measure, used to write a
# volumetric energy that depends on F only through theta as a function of theta alone.
MEASURES = dict((law.name, (law, rep)) for law, rep in (
    _measure("volume", volume, "det F", lambda t: sp.diag(t, 1, 1)),
    _measure("dilatation", dilatation, "tr F - 2 (1 + tr eps)", lambda t: sp.diag(t, 1, 1)),
    _measure("green_dilatation", green_dilatation, "(tr C - 1) / 2 (1 + tr E)",
             lambda t: sp.diag(sp.sqrt(2 * t - 1), 1, 1)),
))
