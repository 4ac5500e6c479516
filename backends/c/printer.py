"""C printing: sympy expressions as C99 (scalar and tm_vd vector code) and the template call."""
from __future__ import annotations

from sympy.printing.c import C99CodePrinter

from ..printing import DoubleLiterals, power
from ..render import environment, metadata_json, print_fragment, printed
from .loader import METADATA_TAG

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
    vec = CVectorPrinter()
    return {
        "law": {"gradient_tangent": [print_fragment(f, vec) for f in ir.law_code["gradient_tangent"]]},
        "J": vec.doprint(ir.J) if ir.J is not None else None,
    }


def render(ir, backend) -> str:
    return environment(backend).get_template("kernel.c.j2").render(
        ir=ir, header=backend.header(ir), metadata=metadata_json(ir, backend), metadata_tag=METADATA_TAG,
        simd=simd_context(ir), **printed(ir, CPrinter()))
