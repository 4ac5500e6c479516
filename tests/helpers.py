"""Shared test helpers: random well-shaped elements and finite differences."""
from __future__ import annotations

import numpy as np

from tensormass.generator.elements import element as reference


def reference_nodes(name: str) -> np.ndarray:
    return np.array([[float(x) for x in node] for node in reference(name).nodes])


def random_elements(name: str, n: int, seed: int = 0, distortion: float = 0.08, straight: bool = False) -> np.ndarray:
    """n random non-inverted elements: a random affine map of the reference element
    (positive determinant) plus a small random perturbation of every node.
    straight=True puts midside nodes back at their edge midpoints (for 'exact' rules)."""
    rng = np.random.default_rng(seed)
    ref = reference_nodes(name)
    if reference(name).order == 2:
        distortion *= 0.3          # midside nodes tolerate less before det J changes sign
    dim = ref.shape[1]
    out = np.empty((n,) + ref.shape)
    for e in range(n):
        while True:
            A = np.eye(dim) + 0.3 * rng.standard_normal((dim, dim))
            if np.linalg.det(A) > 0.5:
                break
        out[e] = ref @ A.T + rng.standard_normal(dim) + distortion * rng.standard_normal(ref.shape)
    if straight:
        from tensormass.generator.ir import _midside_edges
        for m, a, b in _midside_edges(reference(name)):
            out[:, m] = (out[:, a] + out[:, b]) / 2
    return out


def fd_gradient(fun, u: np.ndarray, h: float) -> np.ndarray:
    """Central differences of a batched fun(u) -> (n_elem, ...) with respect to each dof of u (n_elem, n_dofs)."""
    n, m = u.shape
    cols = []
    for k in range(m):
        up, um = u.copy(), u.copy()
        up[:, k] += h
        um[:, k] -= h
        cols.append((fun(up) - fun(um)) / (2 * h))
    return np.stack(cols, axis=-1)


def relative_error(a, b) -> float:
    a, b = np.asarray(a), np.asarray(b)
    scale = max(np.abs(b).max(), 1e-300)
    return float(np.abs(a - b).max() / scale)
