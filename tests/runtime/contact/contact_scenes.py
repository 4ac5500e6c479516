"""Small scenes and checks the contact tests share: a tetra bar (Hooke, one-point tetrahedra: a kernel
of the quick pool, tests/helpers.py), two tetra blocks a gap apart, central differences over every dof,
and an independent triangle-triangle intersection test."""
from __future__ import annotations

import copy

import numpy as np

from tensormass.runtime.model.model import Model
from tensormass.runtime.scene.scene import Scene

SIDE = 0.1          # the bar: [0, SIDE]^3, 2 x 2 x 2 cubes of tetrahedra (27 nodes)


def bar(obstacles=(), contact=None, solver=None, cells=(2, 2, 2), **extra) -> dict:
    data = {"mesh": {"generate": "bar", "size": [SIDE, SIDE, SIDE], "cells": list(cells), "element": "tetra"},
            "material": [{"law": "hooke", "quadrature": "gauss1", "E": 1e5, "nu": 0.3, "density": 1000.0}],
            "fixed": [{"box": [[-1, -1, -1e-9], [1, 1, 1e-9]]}],
            "obstacle": [copy.deepcopy(o) for o in obstacles],
            "solver": solver or {"kind": "static", "steps": 1}}
    if contact is not None:
        data["contact"] = dict(contact)
    if not data["obstacle"]:
        del data["obstacle"]
    data.update(extra)
    return data


def model_of(data, base_dir=None) -> Model:
    return Model.from_scene(Scene.from_dict(copy.deepcopy(data), base_dir))


def two_blocks(tmp_path, gap: float, shift=(0.013, 0.007)) -> str:
    """A mesh file of two 0.05 m tetra cubes (one cube of the bar generator's tetrahedra each), the
    second above the first with `gap` between them and moved sideways by `shift`."""
    import meshio
    cube = model_of(bar(cells=(1, 1, 1))).mesh
    P = np.asarray(cube.points, dtype=float) * 0.5
    cells = np.asarray(cube.blocks[0].cells)
    top = P + np.array([shift[0], shift[1], 0.05 + gap])
    path = tmp_path / "two_blocks.vtu"
    meshio.write(str(path), meshio.Mesh(np.vstack([P, top]), [("tetra", np.vstack([cells, cells + len(P)]))]))
    return str(path)


def fd_gradient(f, u, h) -> np.ndarray:
    """Central differences of the scalar f at u along every dof."""
    g = np.zeros_like(u)
    for k in range(u.size):
        e = np.zeros_like(u)
        e[k] = h
        g[k] = (f(u + e) - f(u - e)) / (2 * h)
    return g


def fd_jacobian(g, u, h) -> np.ndarray:
    """Central differences of the vector g at u: column k is dg/du_k."""
    cols = []
    for k in range(u.size):
        e = np.zeros_like(u)
        e[k] = h
        cols.append((g(u + e) - g(u - e)) / (2 * h))
    return np.stack(cols, axis=1)


def relative(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


# ------------------------------------------------------------------ triangle-triangle intersection


def _segments_hit_triangles(P, Q, A, B, C, eps) -> np.ndarray:
    """(s, t) bool: segment s (P[s] -> Q[s]) crosses triangle t (A, B, C) (Moller-Trumbore, closed
    with tolerance eps in the barycentric coordinates and the segment parameter)."""
    d = (Q - P)[:, None, :]                               # (s, 1, 3)
    e1, e2 = (B - A)[None], (C - A)[None]                 # (1, t, 3)
    p = np.cross(d, e2)
    det = np.einsum("stk,stk->st", e1 * np.ones_like(p), p)
    ok = np.abs(det) > 1e-30
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = P[:, None, :] - A[None]
    u = np.einsum("stk,stk->st", s, p) * inv
    q = np.cross(s, e1 * np.ones_like(s))
    v = np.einsum("stk,stk->st", d * np.ones_like(q), q) * inv
    t = np.einsum("stk,stk->st", e2 * np.ones_like(q), q) * inv
    return ok & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (t >= -eps) & (t <= 1 + eps)


def surfaces_intersect(V1, F1, V2, F2, eps=0.0) -> bool:
    """Whether two triangle surfaces cross: some edge of one passes through a triangle of the other
    (every crossing of two triangles puts an edge of one of them through the other)."""
    def edges(F):
        E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        return np.unique(E, axis=0)
    for (Va, Fa), (Vb, Fb) in (((V1, F1), (V2, F2)), ((V2, F2), (V1, F1))):
        E = edges(Fa)
        if _segments_hit_triangles(Va[E[:, 0]], Va[E[:, 1]], Vb[Fb[:, 0]], Vb[Fb[:, 1]], Vb[Fb[:, 2]], eps).any():
            return True
    return False


def self_intersecting_pairs(V, F) -> int:
    """The number of (edge, triangle) pairs of one surface that cross, edges and triangles sharing no vertex."""
    E = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)
    hit = _segments_hit_triangles(V[E[:, 0]], V[E[:, 1]], V[F[:, 0]], V[F[:, 1]], V[F[:, 2]], 0.0)
    shares = (E[:, None, :, None] == F[None, :, None, :]).any(axis=(2, 3))
    return int(np.sum(hit & ~shares))
