"""Finite-strain viscoelasticity with a Prony series, on top of any hyperelastic law.

The model (Simo, Comput. Methods Appl. Mech. Eng. 60 (1987) 153-173; Holzapfel, Nonlinear Solid
Mechanics (2000) section 6.10, here without the volumetric-isochoric split): the second
Piola-Kirchhoff stress is the law's S(C) = 2 dW/dC plus one non-equilibrium stress Q_i per branch,

    dQ_i/dt + Q_i / tau_i = beta_i dS/dt,

so that at small strain the relaxation modulus is E(t) = E (1 + sum_i beta_i exp(-t / tau_i)): E
is the long-term (relaxed) modulus and E (1 + sum beta_i) the instantaneous one.

Integrated over a step of length h (the source dS/dt taken constant over the step; exact for the
exponential), with xi_i = exp(-h / (2 tau_i)):

    Q_i(n+1) = xi_i^2 Q_i(n) + beta_i xi_i (S(n+1) - S(n)).

Everything from step n is known during the step, so the total stress S(n+1) + sum_i Q_i(n+1) is
g S(C) + H with the numbers

    g = 1 + sum_i beta_i xi_i,    H = sum_i (xi_i^2 Q_i(n) - beta_i xi_i S(n)),

which is the stress of the step's energy g W(F) + H : E, E = (F^T F - I) / 2. The generator
differentiates this energy like any law's: its tangent is the algorithmic (consistent) one.
g and H are the derived law's point inputs (Law.point_inputs): the runtime writes them into each
integration point's constants before a step (runtime.physics.viscous) and updates Q_i once the
step is accepted; the kernels stay functions of (D, u).

The derived law of a law NAME is NAME_viscous: kernel_law("neohookean_viscous").
"""
from __future__ import annotations

import sys
from dataclasses import replace
from functools import lru_cache

from . import sympy_lazy as sp

from .base import Law

SUFFIX = "_viscous"
# The symmetric H stored as its 6 components (Voigt order xx, yy, zz, yz, xz, xy), then g.
PAIRS = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
H_NAMES = tuple(f"visc_h{a}{b}" for a, b in PAIRS)
G_NAME = "visc_g"
POINT_INPUTS = ((G_NAME, 1.0),) + tuple((name, 0.0) for name in H_NAMES)


def step_energy(base: Law, F, inputs: dict):
    """g W(F) + H : E(F) with the base law's energy and the point inputs g, H."""
    point = {name: inputs.pop(name) for name, _ in POINT_INPUTS}
    E = (F.T * F - sp.eye(3)) / 2
    H = sum((1 if a == b else 2) * point[name] * E[a, b] for (a, b), name in zip(PAIRS, H_NAMES))
    return point[G_NAME] * base.energy(F, **inputs) + H


@lru_cache(maxsize=None)
def viscous(base: Law) -> Law:
    """The law NAME_viscous: the step energy of base under a Prony series (module docstring)."""
    if base.kind != "continuum" or base.point_inputs:
        raise ValueError(f"law {base.name!r}: viscoelasticity applies to a hyperelastic law W(F)")
    return replace(base, name=base.name + SUFFIX, energy=_Energy(base),
                   description=f"{base.description}, viscoelastic (Prony series)",
                   point_inputs=POINT_INPUTS, sources=(sys.modules[base.energy.__module__].__name__,) + base.sources)


class _Energy:
    """energy(F, **inputs) of a derived law; its module (this file) is hashed into the kernels and
    `sources` adds the base law's file."""

    def __init__(self, base: Law):
        self.base = base
        self.__module__ = __name__

    def __call__(self, F, **inputs):
        return step_energy(self.base, F, dict(inputs))


def base_name(name: str) -> str | None:
    """NAME for NAME_viscous, else None."""
    return name[:-len(SUFFIX)] if name.endswith(SUFFIX) else None
