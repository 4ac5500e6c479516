"""C printing: sympy expressions as C99 (scalar, and tm_vd vectors of 4 elements), the statement
tree as C lines (the vector variant prints the same tree with vector types and its own flag),
and the template call."""
from __future__ import annotations

import sympy as sp
from sympy.printing.c import C99CodePrinter

from ..printing import DoubleLiterals, power
from ..render import environment, metadata_json, tables
from ..statements import IndexPrinter, RefPrinting, StatementPrinter
from .loader import METADATA_TAG

_q = sp.Symbol("q", integer=True, nonnegative=True)     # the point loop's variable (kernel_body)

# Small powers of a compound base: a call instead of the base repeated textually.
_POWER_HELPERS = {2: "tm_sq", 3: "tm_cube", 4: "tm_pow4"}


class CPrinter(RefPrinting, DoubleLiterals, C99CodePrinter):
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

    def _print_Piecewise(self, expr):
        """A lane-wise select (a GNU statement expression): both values are computed, each lane keeps
        the one its condition picks (a value the other lanes' condition rules out is never used)."""
        (value, condition), (otherwise, last) = expr.args if len(expr.args) == 2 else (None, None)
        if last is not sp.true or not isinstance(condition, sp.core.relational.Relational):
            raise ValueError(f"the vector code selects between two values on one comparison, not {expr}")
        return (f"({{ const tm_vd tm_s = {self._print(condition.lhs - condition.rhs)}, "
                f"tm_a = {self.doprint(value)}, tm_b = {self.doprint(otherwise)}; tm_vd tm_r; "
                f"for (int tm_l = 0; tm_l < TM_W; ++tm_l) tm_r[tm_l] = tm_s[tm_l] {condition.rel_op} 0.0 "
                "? tm_a[tm_l] : tm_b[tm_l]; tm_r; })")

    def _print_Pow(self, expr, rational=False):
        base, exp = expr.as_base_exp()
        if exp.is_Integer and 2 <= abs(int(exp)) <= 4 and not base.is_Symbol:
            call = f"tm_v{_POWER_HELPERS[abs(int(exp))][3:]}({self._print(base)})"
            return call if exp > 0 else f"(1.0/{call})"
        return power(self, expr, "tm_vpow")


class CStatements(StatementPrinter):
    """One element per call: locals are doubles; arrays through the element's pointers."""

    loop_end = "}"
    terminator = ";"
    value_type = "double"

    def __init__(self, ir, expr_printer=None, writes_D=False):
        super().__init__(expr_printer or CPrinter(), IndexPrinter("/"))
        d, n_dofs, p = ir.dim, ir.n_dofs, ir.dofs_per_node
        # Inside the point loop, D is read through a pointer to the point's block, Dq (GCC
        # generates better addressing from it than from De[q * stride + ...]: measured).
        self.stride = ir.point_stride
        self.writes_D = writes_D
        # array -> (pointer name, row lengths for flattening; None: a C multi-dimensional table)
        self.arrays = {"X": ("Xe", (d,)), "params": ("pe", ()), "D": ("De", ()), "u": ("ue", (p,)),
                       "f": ("fe", ()), "K": ("Ke", (n_dofs,)), "Gq": ("Gq", (d,)), "out": ("out", ()),
                       "S": ("Se", (ir.stress_record["size"],)),
                       "DN": ("DN", None), "WEIGHTS": ("WEIGHTS", None),
                       # the fused kernel: element rows of cells and pos, global arrays, scratch
                       "cells": ("ce", ()), "pos": ("Pe", (ir.n_nodes,)), "U": ("U", (p,)),
                       "fg": ("fg", ()), "data": ("data", ()),
                       "ul": ("ul", (p,)), "fl": ("fl", ()), "Kl": ("Kl", (n_dofs,))}

    def ref(self, array, indices):
        name, rows = self.arrays[array]
        if array == "out":
            return "out[e]"
        if array == "D" and self.stride and _q in indices[0].free_symbols:
            rest = sp.expand(indices[0] - self.stride * _q)
            if _q not in rest.free_symbols:
                return f"Dq[{self.idx(rest)}]"
        if rows is None:
            return name + "".join(f"[{self.idx(k)}]" for k in indices)
        flat = sp.Integer(0)
        for k, index in enumerate(indices):
            flat = flat * (rows[k - 1] if k else 1) + index
        return f"{name}[{self.idx(sp.expand(flat))}]"

    def declare(self, st):
        if st.integer:
            return f"const long {st.name} = {self.code(st.value)}"
        kind = "double" if st.uniform else self.value_type
        return f"{'' if st.mutable else 'const '}{kind} {st.name} = {self.code(st.value)}"

    def loop_prologue(self, st):
        if st.var != "q" or not self.stride:
            return []
        const = "" if self.writes_D else "const "
        return [f"{const}{'double' if self.writes_D else self.value_type} *restrict Dq = De + q * {self.stride};"]

    def loop(self, st):
        v = st.var
        return f"for (int {v} = {self.idx(st.start)}; {v} < {self.idx(st.stop)}; ++{v}) {{"

    def flag(self, st):
        head = f"if (!({self.code(st.value)} > 0.0))"
        if st.leave:
            return [head + " {", f"    flags[e] = {st.flag};", "    break;", "}"]
        return [head, f"    flags[e] = {st.flag};"]

    def flag_if(self, st):
        return [f"if ({self.code(st.left)} > {self.code(st.right)})", f"    flags[e] = {st.flag};"]

    def comment(self, text):
        return f"/* {text} */"


class CVectorStatements(CStatements):
    """TM_W elements at once: every per-element local is a tm_vd vector whose lanes are elements;
    a det F check leaves the whole block to the scalar code (which flags the inverted elements)."""

    value_type = "tm_vd"

    def __init__(self, ir):
        super().__init__(ir, CVectorPrinter())

    def flag(self, st):
        if not st.leave:
            raise ValueError("the vector code only checks det F (leaving the block)")
        return [f"if (tm_any_nonpositive({self.code(st.value)}))",
                "    goto fallback;      /* the scalar code flags the block's inverted elements */"]


def render(ir, backend) -> str:
    scalar = CStatements(ir)
    bodies = {kind: scalar.text(body, 2) for kind, body in ir.bodies.items() if kind != "constants"}
    bodies["constants"] = CStatements(ir, writes_D=True).text(ir.bodies["constants"], 2)
    bodies["forces_and_stiffness_vector"] = CVectorStatements(ir).text(ir.bodies["forces_and_stiffness"], 2)
    return environment(backend).get_template("kernel.c.j2").render(
        ir=ir, header=backend.header(ir), metadata=metadata_json(ir, backend), metadata_tag=METADATA_TAG,
        body=bodies, **tables(ir))
