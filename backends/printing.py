"""Shared printing rules of the backends: floats at full precision, small integer powers as products."""
from __future__ import annotations

import sympy as sp


def float_literal(value) -> str:
    """Shortest repr that round-trips a double: deterministic and exact."""
    text = repr(float(value))
    return text if ("." in text or "e" in text or "inf" in text or "nan" in text) else text + ".0"


def power(printer, expr: sp.Pow, pow_function: str) -> str:
    """x**n for small integer n as products (exact and faster than pow), square roots as sqrt."""
    base, exp = expr.as_base_exp()
    b = printer.parenthesize(base, sp.printing.precedence.PRECEDENCE["Mul"] + 1)
    if exp.is_Integer and 1 <= abs(int(exp)) <= 4:
        product = "*".join([b] * abs(int(exp)))
        return f"({product})" if exp > 0 else f"(1.0/({product}))"
    if exp == sp.Rational(1, 2):
        return f"{printer._sqrt}({printer._print(base)})"
    if exp == sp.Rational(-1, 2):
        return f"(1.0/{printer._sqrt}({printer._print(base)}))"
    return f"{pow_function}({printer._print(base)}, {float_literal(exp)})"


class DoubleLiterals:
    """Printer mixin: every number is a full-precision double literal (1/2 -> 0.5, 2 -> 2.0)."""

    def _print_Float(self, expr):
        return float_literal(expr)

    def _print_Rational(self, expr):
        return float_literal(expr.p / expr.q)

    def _print_Integer(self, expr):
        return float_literal(int(expr))
