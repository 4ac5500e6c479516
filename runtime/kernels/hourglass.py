"""Rank deficiency of an element x law x quadrature kernel: spurious zero-energy ("hourglass") modes.

    spurious_modes("hexahedron", "hooke", "gauss1")    # 12: one-point quadrature, no hourglass control
    spurious_modes("hexahedron", "hooke", "gauss2")    # 0

Decided generically, from the kernel itself: the stiffness of the reference element (its nodes from
tensormass.elements) at rest has as many zero eigenvalues (below ZERO_EIGENVALUE x the largest) as the
element has zero-energy modes; a sound element has only the rigid motions (3 in 2D, 6 in 3D).  Every
further one is a deformation that costs no energy: with nothing else holding it, a static solve is
singular or returns an arbitrary multiple of it, and a dynamic run lets it grow unresisted.

The count does not depend on the (positive) material parameters, so it is computed once per
(element, law, quadrature, backend) with E = 1, nu = 0.3 and cached.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ... import elements, laws
from ..base import integrator_kinds
from ..base.errors import TensormassError
from .kernels import load_kernel

__all__ = ["RIGID_MODES", "ZERO_EIGENVALUE", "UNIQUE_TOLERANCE", "spurious_modes", "hourglass_message", "check_static"]

RIGID_MODES = {2: 3, 3: 6}          # rigid motions: translations + rotations
ZERO_EIGENVALUE = 1e-8              # relative to the largest eigenvalue of the element stiffness


@lru_cache(maxsize=None)
def spurious_modes(element: str, law: str, quadrature: str, backend: str = "numba") -> int | None:
    """Zero-energy modes of the element stiffness at rest beyond the rigid motions; None when unknown
    (a kernel that cannot be loaded or evaluated here, or nodes that carry more than a displacement)."""
    try:
        kernel = load_kernel(element, law, quadrature, backend)
        if kernel.dofs_per_node != kernel.dim or kernel.dim not in RIGID_MODES:
            return None
        X = np.array(elements.get(element).nodes, dtype=float)
        native = {k: float(v) for k, v in laws.get(law).native_parameters(E=1.0, nu=0.3).items()}
        D = kernel.constants(X, **native)
        K = kernel.stiffness(D, np.zeros((1, kernel.n_nodes, kernel.dofs_per_node)))[0]
    except Exception:  # noqa: BLE001 - advisory: an element we cannot evaluate gets no verdict
        return None
    w = np.abs(np.linalg.eigvalsh(0.5 * (K + K.T)))
    if not np.all(np.isfinite(w)) or w.max() <= 0:
        return None
    zero = int(np.count_nonzero(w <= ZERO_EIGENVALUE * w.max()))
    return max(zero - RIGID_MODES[kernel.dim], 0)


def hourglass_message(element: str, quadrature: str, count: int) -> str:
    """The words for a rank-deficient element (advice and the static run's health warning)."""
    return (f"{element} with quadrature {quadrature!r} has {count} spurious zero-energy (hourglass) mode(s) per "
            "element beyond the rigid motions, and no hourglass control: deformations that cost no energy; "
            "use quadrature = \"gauss2\"")



# A static solve is refused when the stiffness at rest does not give back a known displacement to
# this relative accuracy (a sound stiffness does to ~cond x 1e-16; a singular one not at all).
UNIQUE_TOLERANCE = 1e-3


def check_static(ctx) -> None:
    """Refuse (TensormassError, before the first step) a static run whose stiffness at rest is singular
    because of rank-deficient elements: their hourglass modes are free in this mesh, so the displacement
    is not unique (measured: band and LU solvers then fail, pardiso returns an arbitrary field with exit 0).

    Only models with a rank-deficient element x quadrature, or with spring cells (discrete laws), are
    tested (one sparse LU at setup): on a mesh whose constraints hold every hourglass mode (most 2D quad
    meshes clamped along an edge), the static answer is unique and the run goes on (the advice still
    names the element)."""
    model = ctx.model
    if integrator_kinds.get(model.solver.kind).dynamic:
        return
    backend = getattr(model.solver, "backend", "numba")
    deficient = {}
    for part in model.parts:
        if part.quadrature == "discrete":
            # springs: whether a cell alone is rigid depends on the parameters (HybMSS with A = 0 has
            # a zero-energy mode per cube, with A > 0 none) and the lattice may hold the modes or not:
            # the assembled stiffness decides, always
            deficient.setdefault((part.element, part.quadrature), 1)
            continue
        count = spurious_modes(part.element, part.law, part.quadrature, backend)
        if count:
            deficient.setdefault((part.element, part.quadrature), count)
    free = np.asarray(model.free_dofs)
    if not deficient or free.size == 0:
        return
    K = ctx.asm.matrix(ctx.asm.stiffness(np.zeros(model.n_dofs)))[free][:, free].tocsc()
    if _unique(K):
        return
    which = "; ".join(hourglass_message(e, q, n) for (e, q), n in deficient.items() if q != "discrete")
    if any(q == "discrete" for _, q in deficient):
        lattice = ", ".join(sorted({e for e, q in deficient if q == "discrete"}))
        which = "; ".join(filter(None, [which, f"the spring lattice ({lattice} cells) has zero-energy modes that "
                                               "its constraints do not hold (lattices without face diagonals, "
                                               "mss or hybmss with A = 0, under sliding supports)"]))
    raise TensormassError(f"static solve refused: the stiffness at rest is singular, {which}. In this mesh "
                          "these modes are not held by the constraints, so the static displacement is not unique "
                          "(any amount of them solves it)")


def _unique(K) -> bool:
    """Whether K x = K z gives back z (a fixed pseudo-random z): False for a singular K."""
    import scipy.sparse.linalg as spla
    z = np.random.default_rng(0).standard_normal(K.shape[0])
    try:
        with np.errstate(all="ignore"):
            x = spla.splu(K, permc_spec="COLAMD").solve(K @ z)
    except RuntimeError:                      # "Factor is exactly singular"
        return False
    return bool(np.all(np.isfinite(x)) and np.linalg.norm(x - z) <= UNIQUE_TOLERANCE * np.linalg.norm(z))
