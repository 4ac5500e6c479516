"""Code-generation backends: one folder per language behind one protocol (protocol.py) and
one registry (here).

A backend is a folder  backends/<name>/ :
  __init__.py   the Backend object (name, file suffix, metadata reading, render, load)
  printer.py    sympy expressions -> code text, and the template call (rendering only)
  templates/    Jinja templates that lay out the generated file
  loader.py     turns a generated file into callables (compile + cffi, an import, ...)

The generator renders through the registry (`get(name).render(ir)`), the runtime loads
through it (`get(name).load(path, cache)`). Backends import nothing from the runtime: the
runtime passes what a loader needs (the cache folder, a check that a folder is writable)
and wraps BackendError in its own error types.

Every generated file carries the same metadata dict (see METADATA_KEYS), written by the
generator from the IR and read back by `read_metadata`; the runtime builds a Kernel's
attributes, including the layout of the per-element constants, from it alone.
"""
from __future__ import annotations

from .protocol import KERNEL_FUNCTIONS, METADATA_KEYS, Backend, BackendError, check_metadata
from .c import BACKEND as _c
from .c.loader import default_backend
from .numba import BACKEND as _numba
from .cuda import BACKEND as _cuda

__all__ = ["Backend", "BackendError", "KERNEL_FUNCTIONS", "METADATA_KEYS", "BACKENDS", "REGISTRY",
           "check_metadata", "default_backend", "get", "names"]

REGISTRY = {b.name: b for b in (_numba, _c, _cuda)}
BACKENDS = tuple(REGISTRY)


def names() -> tuple:
    return BACKENDS


def get(name: str) -> Backend:
    """The backend called name (BackendError naming the known ones otherwise)."""
    try:
        return REGISTRY[name]
    except (KeyError, TypeError):
        raise BackendError(f"unknown backend {name!r}; known backends: {', '.join(BACKENDS)}") from None
