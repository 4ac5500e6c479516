"""Fibre-reinforced tissue with two fibre families (arterial walls, the cornea): Holzapfel-Gasser-
Ogden as in laws/hgo.py with a second family of direction b and the same k1, k2 and dispersion:

    W = matrix + family(a) + family(b)

(Gasser, Ogden & Holzapfel 2006, eq. 2.8 with two families).  [[material]] fibres gives both
directions: fibres = [[1, 0, 0], [0, 1, 0]], or two "FILE.py:FUNCTION" entries.
"""
from .base import Law
from .hgo import OPTIONS, family, from_E_nu, matrix


def energy(F, mu, kappa, k1, k2, dispersion, a, b):
    return matrix(F, mu, kappa) + family(F, a, k1, k2, dispersion) + family(F, b, k1, k2, dispersion)


LAW = Law(
    name="hgo2",
    parameters=("mu", "kappa"),
    energy=energy,
    from_E_nu=from_E_nu,
    description="Holzapfel-Gasser-Ogden fibre-reinforced (two fibre families, dispersion d)",
    validity="large strains; fibres in tension only; undefined for inverted elements (det F <= 0)",
    requires_positive_J=True,
    options=OPTIONS,
    directions=("a", "b"),
    sources=("tensormass.laws.hgo",),
)
