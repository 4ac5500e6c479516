"""sympy, imported on the first use of one of its names.

The built-in law files write ``from . import sympy_lazy as sp`` instead of ``import sympy as sp``:
a run whose kernels are committed reads each law's declaration (parameters, E, nu conversion,
validity) and never builds its energy, so it does not pay sympy's import (about 0.4 s).  The
energy functions use ``sp.log``, ``sp.Matrix``, ... as usual; the first of them imports sympy.
A law file outside the package may import sympy directly: its kernels are generated anyway.
"""
from __future__ import annotations


def __getattr__(name: str):
    import sympy
    value = getattr(sympy, name)
    globals()[name] = value           # later lookups find it without this function
    return value
