"""A law's energy density and its derivatives with respect to F, symbolically.

Differentiating with respect to the dim*dim entries of F (not the element's
n_nodes*dim displacements) keeps sympy's work independent of the element: the
chain rule to nodes, f_i = -v P g_i and K_ij = v g_i . A . g_j, is linear in the
number of nodes and is done by the generated code (see ir.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import sympy as sp

from .kinematics import F_symbols, embed_plane_strain


@dataclass(frozen=True)
class LawDerivatives:
    dim: int
    F: tuple            # dim x dim symbols, the unknowns
    params: tuple       # parameter symbols, in the law's order
    J: sp.Expr          # det F of the (plane-strain embedded) 3x3 gradient
    W: sp.Expr          # energy density
    P: tuple            # dim x dim, first Piola-Kirchhoff stress dW/dF
    A: dict             # {(ab, cd): d2W/dF_ab dF_cd} for flat indices ab <= cd only
    P33: sp.Expr | None  # 2D (plane strain) only: the out-of-plane stress dW/dF33 at F33 = 1

    def A_entry(self, a, b, c, d) -> sp.Expr:
        ab, cd = a * self.dim + b, c * self.dim + d
        return self.A[(min(ab, cd), max(ab, cd))]


@lru_cache(maxsize=None)
def law_derivatives(law, dim: int) -> LawDerivatives:
    F = F_symbols(dim)
    flat = [F[a][b] for a in range(dim) for b in range(dim)]
    params = law.symbols()
    F3 = embed_plane_strain(F)
    W = law.W(F3, params)
    P = [sp.diff(W, s) for s in flat]
    # The Hessian is symmetric: differentiate each pair once.
    A = {(i, j): sp.diff(P[i], flat[j]) for i in range(len(flat)) for j in range(i, len(flat))}
    P33 = None
    if dim == 2:
        # The embedded F33 = 1 is a constant of the unknowns, but the out-of-plane stress (which
        # plane-strain Cauchy sigma33 and von Mises need) is dW/dF33 there: differentiate the law
        # with F33 a symbol (F22 in 0-based names, free in 2D), then put F33 = 1 back.
        F33 = sp.Symbol("F22", real=True)
        F3_free = F3.copy()
        F3_free[2, 2] = F33
        P33 = sp.diff(law.W(F3_free, params), F33).subs(F33, 1)
    return LawDerivatives(
        dim=dim,
        F=tuple(tuple(row) for row in F),
        params=tuple(params[p] for p in law.inputs),
        J=F3.det(),
        W=W,
        P=tuple(tuple(P[a * dim:(a + 1) * dim]) for a in range(dim)),
        A=A,
        P33=P33,
    )
