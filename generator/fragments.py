"""Straight-line code from expressions: common-subexpression elimination and splitting.

A Fragment is an ordered list of temporaries plus named outputs. When one
fragment would exceed ``max_ops`` operations, its outputs are split into
smaller groups, each eliminated separately: a few recomputed subexpressions
are cheaper than a function the compiler cannot swallow.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

DEFAULT_MAX_OPS = 4000


@dataclass(frozen=True)
class Fragment:
    temporaries: tuple   # ((Symbol, Expr), ...) in evaluation order
    outputs: tuple       # ((name, Expr), ...)

    @property
    def ops(self) -> int:
        return sum(count_ops(e) for _, e in self.temporaries) + sum(count_ops(e) for _, e in self.outputs)


def count_ops(expr) -> int:
    return int(sp.count_ops(expr, visual=False))


def eliminate(outputs: list[tuple[str, sp.Expr]], prefix: str) -> Fragment:
    """One fragment: sympy's CSE with stable temporary names prefix0, prefix1, ..."""
    names = [n for n, _ in outputs]
    temps, reduced = sp.cse([e for _, e in outputs], symbols=sp.numbered_symbols(prefix, real=True),
                            order="canonical")
    temps, reduced = _inline_conditions(temps, reduced)
    return Fragment(tuple(temps), tuple(zip(names, reduced)))


def _inline_conditions(temps, reduced):
    """Put the conditions of Piecewise values (E > 0) back where they are used: every temporary
    holds a number (the vector code's temporaries are vectors of doubles, never of truth values)."""
    conditions = {}
    kept = []
    for symbol, value in temps:
        value = value.xreplace(conditions) if conditions else value
        if isinstance(value, sp.logic.boolalg.Boolean):
            conditions[symbol] = value
        else:
            kept.append((symbol, value))
    if not conditions:
        return temps, reduced
    return kept, [e.xreplace(conditions) for e in reduced]


def split(outputs: list[tuple[str, sp.Expr]], prefix: str, max_ops: int = DEFAULT_MAX_OPS) -> list[Fragment]:
    """Fragments covering ``outputs`` in order, each under ``max_ops`` where splitting can help."""
    whole = eliminate(outputs, prefix)
    if whole.ops <= max_ops or len(outputs) == 1:
        return [whole]
    half = len(outputs) // 2
    first = split(outputs[:half], f"{prefix}a", max_ops)
    second = split(outputs[half:], f"{prefix}b", max_ops)
    return first + second
