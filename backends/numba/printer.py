"""numba printing: sympy expressions as Python (math.*), the statement tree as Python lines,
and the template call."""
from __future__ import annotations

from sympy.printing.pycode import PythonCodePrinter

from ..printing import DoubleLiterals, power
from ..render import environment, metadata_json, tables
from ..statements import IndexPrinter, RefPrinting, StatementPrinter

# Arrays of the current element: their first index is the element e.
PER_ELEMENT = ("X", "params", "D", "u", "f", "K", "out", "cells", "pos", "S")


class NumbaPrinter(RefPrinting, DoubleLiterals, PythonCodePrinter):
    """Scalar math for numba: math.* functions, float literals, products for small powers."""

    _sqrt = "math.sqrt"

    def __init__(self):
        super().__init__({"fully_qualified_modules": True, "standard": "python3"})

    def _print_Pow(self, expr, rational=False):
        return power(self, expr, "math.pow")


class NumbaStatements(StatementPrinter):
    def __init__(self):
        super().__init__(NumbaPrinter(), IndexPrinter("//"))

    def ref(self, array, indices):
        parts = (["e"] if array in PER_ELEMENT else []) + [self.idx(k) for k in indices]
        return f"{array}[{', '.join(parts)}]"

    def declare(self, st):
        return f"{st.name} = {self.code(st.value)}"

    def loop(self, st):
        start, stop = self.idx(st.start), self.idx(st.stop)
        return f"for {st.var} in range({stop if start == '0' else start + ', ' + stop}):"

    def flag(self, st):
        lines = [f"if not ({self.code(st.value)} > 0.0):", f"    flags[e] = {st.flag}"]
        return lines + (["    break"] if st.leave else [])

    def flag_if(self, st):
        return [f"if {self.code(st.left)} > {self.code(st.right)}:", f"    flags[e] = {st.flag}"]

    def comment(self, text):
        return f"# {text}"


def render(ir, backend) -> str:
    meta = metadata_json(ir, backend)
    # The JSON goes into a single-quoted Python literal: it must hold no quote or backslash.
    assert "'" not in meta and "\\" not in meta, meta
    statements = NumbaStatements()
    bodies = {kind: statements.text(body, 2) for kind, body in ir.bodies.items()}
    return environment(backend).get_template("kernel.py.j2").render(
        ir=ir, header=backend.header(ir), metadata=meta, body=bodies, **tables(ir))
