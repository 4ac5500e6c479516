"""Element types: one module per type, and the registry everything else reads.

    from tensormass import elements
    el = elements.get("tetra10")          # ElementType: nodes, corners, edges, faces, midsides, ...
    elements.names()                      # every registered type, in registration order
    elements.names(dim=2)                 # those of topological dimension 2
    elements.register(my_type)            # a new type (tests, plug-ins)

Adding an element type = one module here defining ELEMENT (plus its generated
kernels): every module of this package not starting with "_" is loaded.
"""
from __future__ import annotations

import pkgutil
from importlib import import_module

from ._base import (BOX, DOMAINS, PRISM, PYRAMID, SIMPLEX, Domain, ElementType, Face, midpoints,
                    monomial_exponents)

__all__ = ["ElementType", "Face", "Domain", "SIMPLEX", "BOX", "PRISM", "PYRAMID", "DOMAINS",
           "get", "names", "by_dim", "builtin", "register", "unregister", "midpoints", "monomial_exponents"]

# The order messages and tables list the built-in types in; other modules follow, 3D first, by name.
_ORDER = ("tetra", "tetra10", "hexahedron", "wedge", "pyramid", "triangle", "triangle6", "quad")

_REGISTRY: dict[str, ElementType] = {}


def register(element: ElementType, replace: bool = False) -> ElementType:
    """Add an element type; its faces' types need not be registered (line, vertex, ...)."""
    if not isinstance(element, ElementType):
        raise TypeError(f"expected an ElementType, got {type(element).__name__}")
    if element.name in _REGISTRY and not replace and _REGISTRY[element.name] != element:
        raise ValueError(f"element type {element.name!r} is already registered")
    if element.linear not in _REGISTRY and element.linear != element.name:
        raise ValueError(f"{element.name}: linear counterpart {element.linear!r} is not registered")
    _REGISTRY[element.name] = element
    return element


def unregister(name: str) -> None:
    """Remove a type added by register() (the built-in ones stay)."""
    if name in _BUILTIN:
        raise ValueError(f"{name!r} is a built-in element type")
    _REGISTRY.pop(name, None)


def get(name: str) -> ElementType:
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown element type {name!r}; known: {', '.join(_REGISTRY)}") from None


def names(dim: int | None = None) -> tuple:
    """Registered type names (of topological dimension `dim` if given)."""
    return tuple(n for n, e in _REGISTRY.items() if dim is None or e.dim == dim)


def by_dim(dim: int) -> tuple:
    """Registered ElementTypes of topological dimension `dim`."""
    return tuple(e for e in _REGISTRY.values() if e.dim == dim)


def builtin() -> tuple:
    """Names of the built-in types (those the generator's catalogue has kernels for)."""
    return _BUILTIN


def _load() -> tuple:
    found = [import_module(f".{m.name}", __name__).ELEMENT
             for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_")]
    rank = {n: i for i, n in enumerate(_ORDER)}
    found.sort(key=lambda e: (rank.get(e.name, len(rank)), -e.dim, e.linear != e.name, e.name))
    for e in sorted(found, key=lambda e: e.linear != e.name):   # linear counterparts first
        register(e)
    return tuple(e.name for e in found)


_BUILTIN = _load()
for _n in _BUILTIN:     # registration order = listing order
    _REGISTRY[_n] = _REGISTRY.pop(_n)
del _n
