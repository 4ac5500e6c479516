"""numba backend: one Python module per kernel, @njit(cache=True) loops over elements."""
from __future__ import annotations

from sympy.printing.pycode import PythonCodePrinter

from . import environment, header_line
from .printing import DoubleLiterals, power

LANGUAGE = "numba"
SUFFIX = ".py"


class NumbaPrinter(DoubleLiterals, PythonCodePrinter):
    """Scalar math for numba: math.* functions, float literals, products for small powers."""

    _sqrt = "math.sqrt"

    def __init__(self):
        super().__init__({"fully_qualified_modules": True, "standard": "python3"})

    def _print_Pow(self, expr, rational=False):
        return power(self, expr, "math.pow")


def render(ir, context: dict) -> str:
    return environment(LANGUAGE).get_template("kernel.py.j2").render(
        ir=ir, header=header_line(ir, LANGUAGE), **context)


def printer():
    return NumbaPrinter()


def file_name(ir) -> str:
    return ir.name + SUFFIX
