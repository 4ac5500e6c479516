"""Kernels a user writes by hand, for element types the generator has no kernel for.

    from tensormass.runtime.kernels.custom_kernels import register_kernel, unregister_kernel
    register_kernel("line", "hooke", "gauss1", MyBarKernel(area=1e-4))
    model = Model(mesh, [Material(law="hooke", quadrature="gauss1", E=2e11, nu=0.3)], ...)
    unregister_kernel("line", "hooke", "gauss1")

The model takes a registered kernel before any generated one (runtime.kernels.kernels), for
the (element, law, quadrature) a material names; the element type itself comes from
the element table (tensormass.elements.register), which says its topological dimension
and dofs per node.  A kernel is any object with what `Kernel` below lists (the
generated runtime.kernels.kernels.Kernel has it all); `check_kernel` refuses one that lacks it.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from ..base.errors import TensormassError

__all__ = ["Kernel", "register_kernel", "unregister_kernel", "registered_kernel", "registered",
           "check_kernel", "REQUIRED_ATTRIBUTES", "REQUIRED_METHODS"]


@runtime_checkable
class Kernel(Protocol):
    """What the model, the assembler and the integrators use of a kernel.

    Attributes
      element, law, quadrature, backend   names (backend: any label, e.g. "python")
      n_nodes    nodes per element (the element type's count)
      n_points   integration points
      n_dofs     unknowns per element: n_nodes x dofs per node
      dim        space dimension
    The layout of D is the kernel's own; the model reads only point_volumes(D).
    Methods (n elements; u: (n, n_nodes, dofs per node) element dofs, node-major)
      constants(X, **native) -> D (n, n_constants)     X: (n, n_nodes, dim) rest coordinates;
                                                       native: the law's native parameters
      point_volumes(D) -> (n, n_points)                each point's weight x measure (length x
                                                       area for a bar, volume for a solid): their
                                                       sum is the element's rest volume, which sets
                                                       its mass (density x volume) and gravity
      energy(D, u) -> (n,)
      forces(D, u) -> (n, n_dofs)                      f_int = -dW/du
      stiffness(D, u) -> (n, n_dofs, n_dofs)           K = d2W/du2
      forces_and_stiffness(D, u) -> (f, K)
    Optional
      quadratic_energy: True when energy(D, u) = 1/2 u.K.u with a constant K (a linear kernel): the
      assembler then builds K once and takes the forces and energy from it (default False).
      min_det_F(D, u, cells=None), inverted(D, u, cells=None): the health monitor's and the
      positive-J laws' inversion checks (a kernel without them is not checked for inversion);
      raise runtime.base.errors.ElementError subclasses with part-local element ids for bad elements.
      stress(D, u) -> (n, n_points, stress_record["size"]) with the attribute stress_record
      ({"size", "offsets": {"v", "W", "F", "P"(, "P33" in 2D)}}, as the generated kernels'
      metadata): the output fields' records (runtime.physics.fields). A kernel without it gives no stress
      or strain fields: a scene that asks for them is refused (naming the kernel), and the
      default [output] fields leave them out.
    """
    element: str
    law: str
    quadrature: str
    backend: str
    n_nodes: int
    n_points: int
    n_dofs: int
    dim: int

    def constants(self, X, **native) -> np.ndarray: ...
    def point_volumes(self, D) -> np.ndarray: ...
    def energy(self, D, u) -> np.ndarray: ...
    def forces(self, D, u) -> np.ndarray: ...
    def stiffness(self, D, u) -> np.ndarray: ...
    def forces_and_stiffness(self, D, u) -> tuple: ...


REQUIRED_ATTRIBUTES = ("element", "law", "quadrature", "backend", "n_nodes", "n_points", "n_dofs", "dim")
REQUIRED_METHODS = ("constants", "point_volumes", "energy", "forces", "stiffness", "forces_and_stiffness")

_KERNELS: dict = {}


def check_kernel(kernel, key: tuple | None = None) -> None:
    """Refuse (TensormassError) an object that lacks part of the Kernel protocol or names another key."""
    missing = [a for a in REQUIRED_ATTRIBUTES if not hasattr(kernel, a)]
    missing += [m for m in REQUIRED_METHODS if not callable(getattr(kernel, m, None))]
    if missing:
        raise TensormassError(f"kernel {kernel!r} lacks {', '.join(missing)} (see runtime.kernels.custom_kernels.Kernel)")
    for a in ("n_nodes", "n_points", "n_dofs", "dim"):
        value = getattr(kernel, a)
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise TensormassError(f"kernel {kernel!r}: {a} must be a positive integer, got {value!r}")
    if kernel.n_dofs % kernel.n_nodes:
        raise TensormassError(f"kernel {kernel!r}: n_dofs ({kernel.n_dofs}) is not a multiple of "
                              f"n_nodes ({kernel.n_nodes})")
    if key is not None and (kernel.element, kernel.law, kernel.quadrature) != tuple(key):
        raise TensormassError(f"kernel {kernel!r} is for {(kernel.element, kernel.law, kernel.quadrature)}, "
                              f"registered as {tuple(key)}")


def register_kernel(element: str, law: str, quadrature: str, kernel, replace: bool = False):
    """Use `kernel` for (element, law, quadrature) in every model built from now on; returns it."""
    key = (element, law, quadrature)
    check_kernel(kernel, key)
    if key in _KERNELS and not replace and _KERNELS[key] is not kernel:
        raise TensormassError(f"a kernel for {key} is already registered (replace=True to change it)")
    _KERNELS[key] = kernel
    return kernel


def unregister_kernel(element: str, law: str, quadrature: str) -> None:
    """Forget a registered kernel (no error if there is none)."""
    _KERNELS.pop((element, law, quadrature), None)


def registered_kernel(element: str, law: str, quadrature: str):
    """The kernel registered for (element, law, quadrature), or None."""
    return _KERNELS.get((element, law, quadrature))


def registered() -> tuple:
    """Keys (element, law, quadrature) with a registered kernel."""
    return tuple(_KERNELS)
