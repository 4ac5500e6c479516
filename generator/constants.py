"""Per-element constants: everything that depends only on rest geometry and material.

Two sources, both computed once by the generated ``constants`` kernel (the
thesis' Algorithm 3: the per-step code then reads only D and u):
- rest geometry at each integration point: v = w det J and the physical shape
  gradients G_i = J^-T grad_xi N_i (J = dX/dxi of the rest configuration),
  computed from a table of reference shape gradients at the points;
- subexpressions of the law code that involve only material parameters
  (lam/2, 2 mu, alpha of stable neo-Hookean, ...), found by ``hoist``.
"""
from __future__ import annotations

import sympy as sp
from sympy.functions.elementary.piecewise import ExprCondPair


def geometry_code(dim: int):
    """Straight-line code for the rest geometry at one integration point, shared by all points.

    The template accumulates J[a][k] = sum_i X_ia dN_ik from a table of shape
    gradients dN (one row per point: rule-dependent numbers are data, not code,
    which keeps gauss3 kernels small and quick to compile). This code then
    forms det J and J^-1, and G_i = dN_i J^-1 for one node with gradient dn.
    Returns (temporaries, [(b, G_b expression)]).
    """
    J = sp.Matrix(dim, dim, lambda a, k: sp.Symbol(f"J{a}{k}", real=True))
    detJ = sp.Symbol("detJ", real=True)
    inv = sp.Matrix(dim, dim, lambda a, k: sp.Symbol(f"Ji{a}{k}", real=True))
    adj = J.adjugate()
    temps = [(detJ, J.det())] + [(inv[a, k], adj[a, k] / detJ) for a in range(dim) for k in range(dim)]
    dn = [sp.Symbol(f"dn{k}", real=True) for k in range(dim)]
    G = [(b, sum(dn[k] * inv[k, b] for k in range(dim))) for b in range(dim)]
    return temps, G


def hoist(exprs: list[sp.Expr], rest: set[sp.Symbol], prefix: str = "c"):
    """Replace every maximal subexpression that involves only ``rest`` symbols by a constant.

    Returns (new expressions, [(constant symbol, expression in rest symbols)]).
    Within a sum or product the rest-only arguments are grouped, so that
    mu/2 * x * y hoists mu/2 even though sympy stores it as Mul(1/2, mu, x, y).
    """
    table: dict[sp.Expr, sp.Symbol] = {}
    order: list[tuple[sp.Symbol, sp.Expr]] = []

    def constant(e: sp.Expr) -> sp.Expr:
        if e.is_Atom:
            return e
        if e not in table:
            table[e] = sp.Symbol(f"{prefix}{len(order)}", real=True)
            order.append((table[e], e))
        return table[e]

    def is_rest(e: sp.Expr) -> bool:
        # a value only: not a Piecewise branch (expression, condition) nor a condition
        return isinstance(e, sp.Expr) and not isinstance(e, ExprCondPair) and e.free_symbols <= rest

    def visit(e: sp.Expr) -> sp.Expr:
        if e.is_Atom:
            return e
        if is_rest(e):
            return constant(e)
        if isinstance(e, (sp.Add, sp.Mul)):
            fixed = [a for a in e.args if is_rest(a)]
            moving = [visit(a) for a in e.args if not is_rest(a)]
            # A lone number stays a literal; anything else rest-only becomes a constant.
            if len(fixed) > 1 or (fixed and not fixed[0].is_Number):
                fixed = [constant(e.func(*fixed))]
            return e.func(*fixed, *moving)
        return e.func(*[visit(a) for a in e.args])

    return [visit(e) for e in exprs], order
