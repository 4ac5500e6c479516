"""What a constitutive law declares, and the E, nu -> Lamé conversion they share."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import sympy as sp


class LawError(ValueError):
    """Unknown law, missing or invalid material parameter."""


@dataclass(frozen=True, eq=False)
class Law:
    """A hyperelastic law W(F; parameters).

    energy(F, **params) receives a 3x3 sympy Matrix F (2D elements embed their
    2x2 gradient with F33 = 1: plane strain) and sympy symbols named after
    ``parameters``; it returns the energy density per unit rest volume.
    from_E_nu(E, nu) returns the native parameters as a dict (numpy-friendly).
    """

    name: str
    parameters: tuple[str, ...]
    energy: Callable[..., sp.Expr]
    from_E_nu: Callable[..., dict]
    description: str
    validity: str
    # Laws with ln J or J^(-2/3) are undefined for det F <= 0: kernels flag those elements.
    requires_positive_J: bool = False

    def symbols(self) -> dict[str, sp.Symbol]:
        return {p: sp.Symbol(p, real=True) for p in self.parameters}

    def native_parameters(self, E=None, nu=None, **native) -> dict[str, np.ndarray]:
        """Native parameters from either (E, nu) or the native names, validated."""
        if native and (E is not None or nu is not None):
            raise LawError(f"law {self.name!r}: give either E and nu or native parameters, not both")
        if not native and self.parameters:
            if E is None or nu is None:
                raise LawError(f"law {self.name!r} needs E and nu (or native parameters {', '.join(self.parameters)})")
            native = self.from_E_nu(*validate_E_nu(E, nu))
        unknown = sorted(set(native) - set(self.parameters))
        missing = [p for p in self.parameters if p not in native]
        if unknown:
            raise LawError(f"law {self.name!r} has no parameter {', '.join(unknown)}; it takes {', '.join(self.parameters)}")
        if missing:
            raise LawError(f"law {self.name!r} is missing parameter {', '.join(missing)}")
        out = {}
        for p in self.parameters:
            value = np.asarray(native[p], dtype=float)
            if not np.all(np.isfinite(value)):
                raise LawError(f"law {self.name!r}: parameter {p} is not finite")
            out[p] = value
        return out


def validate_E_nu(E, nu):
    E = np.asarray(E, dtype=float)
    nu = np.asarray(nu, dtype=float)
    if not (np.all(np.isfinite(E)) and np.all(np.isfinite(nu))):
        raise LawError("E and nu must be finite numbers (got NaN or Inf)")
    if np.any(E <= 0):
        raise LawError(f"Young's modulus E must be > 0 (got {E.min():g})")
    if np.any(nu >= 0.5) or np.any(nu <= -1.0):
        bad = nu.max() if np.any(nu >= 0.5) else nu.min()
        raise LawError(f"Poisson's ratio nu must satisfy -1 < nu < 0.5 (got {bad:g}); "
                       "nu = 0.5 is incompressible, which these displacement elements cannot represent")
    return E, nu


def lame_from_E_nu(E, nu) -> tuple:
    """Lamé's lambda and mu from Young's modulus and Poisson's ratio."""
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    return lam, mu
