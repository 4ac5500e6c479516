"""C backend: one C99 translation unit per kernel, plain loops over elements.

The runtime (tensormass.runtime.compile) compiles the file into a shared
library and calls it through cffi. The template computes exactly what the
numba template computes, with the same array layouts (row-major, flat).
"""
from __future__ import annotations

import json

from sympy.printing.c import C99CodePrinter

from . import environment, header_line, templates_hash
from .printing import DoubleLiterals, power

LANGUAGE = "c"
SUFFIX = ".c"

# Marks the metadata comment of a generated file; runtime/compile.py looks for it.
METADATA_TAG = "tensormass-metadata"

# Small powers of a compound base: a call instead of the base repeated textually.
_POWER_HELPERS = {2: "tm_sq", 3: "tm_cube", 4: "tm_pow4"}


class CPrinter(DoubleLiterals, C99CodePrinter):
    """Scalar math for C99: <math.h> functions, full-precision double literals, products for small powers."""

    _sqrt = "sqrt"

    def __init__(self):
        super().__init__()

    def _print_Pow(self, expr, rational=False):
        base, exp = expr.as_base_exp()
        if exp.is_Integer and 2 <= abs(int(exp)) <= 4 and not base.is_Symbol:
            call = f"{_POWER_HELPERS[abs(int(exp))]}({self._print(base)})"
            return call if exp > 0 else f"(1.0/{call})"
        return power(self, expr, "pow")


class CVectorPrinter(CPrinter):
    """The same code on tm_vd vectors (4 elements per value): math calls go through the
    per-lane helpers of simd.c.j2, arithmetic is unchanged (GCC/Clang vector extensions)."""

    _sqrt = "tm_vsqrt"

    def __init__(self):
        super().__init__()
        self.known_functions = {**self.known_functions, "log": "tm_vlog", "exp": "tm_vexp", "sqrt": "tm_vsqrt"}

    def doprint(self, expr, assign_to=None):
        # A bare number (a constant tangent entry of Hooke, say) must become a vector.
        text = super().doprint(expr, assign_to)
        return f"TM_SPLAT({text})" if getattr(expr, "is_Number", False) else text

    def _print_Pow(self, expr, rational=False):
        base, exp = expr.as_base_exp()
        if exp.is_Integer and 2 <= abs(int(exp)) <= 4 and not base.is_Symbol:
            call = f"tm_v{_POWER_HELPERS[abs(int(exp))][3:]}({self._print(base)})"
            return call if exp > 0 else f"(1.0/{call})"
        return power(self, expr, "tm_vpow")


def simd_context(ir) -> dict:
    """The law code printed for vectors: only calls differ from the scalar text."""
    from . import print_fragment
    vec = CVectorPrinter()
    return {
        "law": {"gradient_tangent": [print_fragment(f, vec) for f in ir.law_code["gradient_tangent"]]},
        "J": vec.doprint(ir.J) if ir.J is not None else None,
    }


def metadata(ir) -> str:
    """What the runtime needs to know about the kernel, as one line of JSON (sorted keys)."""
    return json.dumps({
        "name": ir.name,
        "element": ir.element,
        "law": ir.law,
        "quadrature": ir.quadrature,
        "dim": ir.dim,
        "n_nodes": ir.n_nodes,
        "n_points": ir.n_points,
        "n_constants": ir.n_constants,
        "n_dofs": ir.n_dofs,
        "parameters": list(ir.parameters),
        "requires_positive_J": bool(ir.requires_positive_J),
        **({"recompute": True} if ir.recompute else {}),
        "ops": dict(sorted(ir.ops.items())),
        "templates": templates_hash(LANGUAGE)[:16],
    }, sort_keys=True)


def render(ir, context: dict) -> str:
    return environment(LANGUAGE).get_template("kernel.c.j2").render(
        ir=ir, header=header_line(ir, LANGUAGE), metadata=metadata(ir), metadata_tag=METADATA_TAG,
        simd=simd_context(ir), **context)


def printer():
    return CPrinter()


def file_name(ir) -> str:
    return ir.name + SUFFIX
