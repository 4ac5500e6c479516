"""numba printing: sympy expressions as Python (math.*) and the template call."""
from __future__ import annotations

from sympy.printing.pycode import PythonCodePrinter

from ..printing import DoubleLiterals, power
from ..render import environment, metadata_json, printed


class NumbaPrinter(DoubleLiterals, PythonCodePrinter):
    """Scalar math for numba: math.* functions, float literals, products for small powers."""

    _sqrt = "math.sqrt"

    def __init__(self):
        super().__init__({"fully_qualified_modules": True, "standard": "python3"})

    def _print_Pow(self, expr, rational=False):
        return power(self, expr, "math.pow")


def render(ir, backend) -> str:
    meta = metadata_json(ir, backend)
    # The JSON goes into a single-quoted Python literal: it must hold no quote or backslash.
    assert "'" not in meta and "\\" not in meta, meta
    return environment(backend).get_template("kernel.py.j2").render(
        ir=ir, header=backend.header(ir), metadata=meta, **printed(ir, NumbaPrinter()))
