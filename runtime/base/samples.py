"""Random well-shaped elements of a reference element: the inputs of the kernel tests
(tests/helpers.py) and of the kernel benchmark (apps/bench.py), from one generator so both
draw the same elements for a seed."""
from __future__ import annotations

import numpy as np

from ...generator.elements import element as reference
from ...generator.ir import midside_triples


def random_elements(element: str, n: int, seed: int = 0, straight: bool = False, distortion: float = 0.08) -> np.ndarray:
    """n random well-shaped elements: random affine images (det >= 0.5) of the reference
    element, moved, with every node perturbed by `distortion` (0.3x that for quadratic
    elements, whose midside nodes tolerate less). straight=True then puts midside nodes
    back at their edge midpoints (what 'exact' quadrature requires). Shared with the tests."""
    ref_el = reference(element)
    ref = np.array([[float(x) for x in node] for node in ref_el.nodes])
    dim = ref.shape[1]
    rng = np.random.default_rng(seed)
    A = np.empty((n, dim, dim))
    todo = np.arange(n)
    while todo.size:
        A[todo] = np.eye(dim) + 0.3 * rng.standard_normal((todo.size, dim, dim))
        todo = todo[np.linalg.det(A[todo]) <= 0.5]
    scale = distortion * (0.3 if ref_el.order == 2 else 1.0)
    X = np.einsum("ik,nak->nia", ref, A) + rng.standard_normal((n, 1, dim))
    X += scale * rng.standard_normal(X.shape)
    if straight:
        for m, a, b in midside_triples(ref_el):
            X[:, m] = (X[:, a] + X[:, b]) / 2
    return np.ascontiguousarray(X)
