"""Constitutive laws: one small file per law, discovered automatically.

A law file defines ``LAW = Law(...)``: the strain-energy density W(F) per unit
rest volume written with sympy, its native parameters and how they follow from
Young's modulus E and Poisson's ratio nu. Adding a law means adding one file to
this folder; nothing else has to change.

A discrete law (``LAW = DiscreteLaw(...)``: mss.py, hybmss.py) writes instead the energy of one
element in its nodal positions (springs, lattice cubes; springs.py has the pieces).
"""
from __future__ import annotations

import importlib
import pkgutil
from functools import lru_cache

from .base import DiscreteLaw, Law, LawError, lame_from_E_nu

__all__ = ["Law", "DiscreteLaw", "LawError", "lame_from_E_nu", "get", "names", "continuum_names", "discrete_names", "shell_names",
           "is_discrete", "is_shell", "is_quadratic", "measure_names", "kernel_law"]


@lru_cache(maxsize=None)
def _registry() -> dict[str, Law]:
    found: dict[str, Law] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_") or info.name == "base":
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        law = getattr(module, "LAW", None)
        if isinstance(law, Law):
            found[law.name] = law
    return dict(sorted(found.items()))


def names() -> list[str]:
    """Names of every known law, sorted."""
    return list(_registry())


def continuum_names() -> list[str]:
    """The laws with an energy density W(F) (the finite elements' materials), sorted."""
    return [n for n, law in _registry().items() if law.kind == "continuum"]


def discrete_names() -> list[str]:
    """The discrete laws (springs, lattice cubes: an element energy in nodal positions), sorted."""
    return [n for n, law in _registry().items() if law.kind == "discrete"]


def shell_names() -> list[str]:
    """The shell laws (laws/cst_dkt.py: an energy in nodal displacements and rotations), sorted."""
    return [n for n, law in _registry().items() if law.kind == "shell"]


def is_shell(name: str) -> bool:
    """True for a shell law (cst_dkt): element "shell", quadrature "exact", 6 dofs per node."""
    return name in shell_names()


def is_discrete(name: str) -> bool:
    """True for a discrete law (mss, hybmss): no W(F), no formulations, quadrature "discrete"."""
    return name in discrete_names()


def measure_names() -> list[str]:
    """The volume measures (laws/measures.py): parameter-free "laws" the generator builds kernels
    for, which the locking-free formulations use; not materials."""
    from .measures import MEASURES
    return sorted(MEASURES)


def get(name: str) -> Law:
    """The law called ``name``; a LawError naming the known laws otherwise."""
    try:
        return _registry()[name]
    except KeyError:
        raise LawError(f"unknown law {name!r}; known laws: {', '.join(names())}") from None


def kernel_law(name: str) -> Law:
    """What a kernel integrates: a law, or a volume measure (generator and kernel loader)."""
    from .measures import MEASURES
    if name in MEASURES:
        return MEASURES[name][0]
    return get(name)


@lru_cache(maxsize=None)
def is_quadratic(name: str) -> bool:
    """True when W is a homogeneous quadratic in the displacement gradient H = F - I.

    Then W_E(u) = 1/2 u.K.u with a constant K, and f_int = -K u exactly: the
    runtime assembles K once and skips the kernel at every step (Hooke).
    """
    import sympy as sp
    law = get(name)
    if law.kind != "continuum":
        return False
    H = sp.Matrix(3, 3, lambda i, j: sp.Symbol(f"H{i}{j}", real=True))
    W = law.energy(sp.eye(3) + H, **law.symbols())
    entries = list(H)
    if not W.is_polynomial(*entries):          # checked before expanding: ln J, J^(-2/3) are slow to expand
        return False
    degrees = {sum(m) for m in sp.Poly(W, *entries).monoms()}
    return degrees == {2}
