"""Kinematics at one point: F = I + sum_i u_i (x) G_i, with G_i = grad_X N_i.

The law is always written for a 3x3 F. 2D elements use plane strain: only the
2x2 in-plane block varies and F33 = 1, so only dim*dim entries are unknowns.
"""
from __future__ import annotations

import sympy as sp


def F_symbols(dim: int) -> list[list[sp.Symbol]]:
    """The unknown entries of F as symbols F00, F01, ... (row a, column b)."""
    return [[sp.Symbol(f"F{a}{b}", real=True) for b in range(dim)] for a in range(dim)]


def embed_plane_strain(F_in: list[list[sp.Expr]]) -> sp.Matrix:
    """A 3x3 deformation gradient from a dim x dim one (plane strain: F33 = 1)."""
    dim = len(F_in)
    F = sp.eye(3)
    for a in range(dim):
        for b in range(dim):
            F[a, b] = F_in[a][b]
    return F


def deformation_gradient(u: sp.Matrix, G: sp.Matrix) -> sp.Matrix:
    """F = I + u^T G for nodal displacements u (n x dim) and shape gradients G (n x dim)."""
    return sp.eye(u.shape[1]) + u.T * G


def green_lagrange(F: sp.Matrix) -> sp.Matrix:
    """E = (F^T F - I) / 2."""
    return (F.T * F - sp.eye(F.shape[0])) / 2
