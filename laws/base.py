"""What a constitutive law declares, and the E, nu -> Lamé conversion they share."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from . import sympy_lazy as sp


class LawError(ValueError):
    """Unknown law, missing or invalid material parameter."""


@dataclass(frozen=True, eq=False)
class Law:
    """A hyperelastic law W(F; parameters).

    energy(F, **params) receives a 3x3 sympy Matrix F (2D elements embed their
    2x2 gradient with F33 = 1: plane strain) and sympy symbols named after
    ``parameters`` and ``options``, and for each name of ``directions`` a 3x1 sympy Matrix of
    symbols (a unit vector in the rest configuration: a fibre family); it returns the energy
    density per unit rest volume.
    from_E_nu(E, nu) returns the native parameters as a dict (numpy-friendly).
    options: ((name, default, (low, high)), ...): parameters always given by name, never derived
    from E and nu (a fibre stiffness); default None: required.
    directions: names of unit vectors given per cell by the scene ([[material]] fibres); the
    kernels receive their components as inputs named NAME_x, NAME_y, NAME_z.
    point_inputs: ((name, value at rest), ...): numbers per integration point that the runtime
    writes into the per-element constants between steps (a viscous law's history: laws/viscous.py);
    energy() receives them as symbols. They are never hoisted: they change every step.
    sources: the modules whose source the kernels depend on beyond energy's (a derived law's base).
    """

    name: str
    parameters: tuple[str, ...]
    energy: Callable[..., sp.Expr]
    from_E_nu: Callable[..., dict]
    description: str
    validity: str
    # Laws with ln J or J^(-2/3) are undefined for det F <= 0: kernels flag those elements.
    requires_positive_J: bool = False
    options: tuple = ()
    directions: tuple = ()
    point_inputs: tuple = ()
    sources: tuple = ()
    kind = "continuum"               # an energy density W(F); DiscreteLaw: an element energy in nodal positions

    @property
    def option_names(self) -> tuple[str, ...]:
        return tuple(name for name, _, _ in self.options)

    @property
    def direction_components(self) -> tuple[str, ...]:
        return tuple(f"{d}_{c}" for d in self.directions for c in "xyz")

    @property
    def inputs(self) -> tuple[str, ...]:
        """What the constants kernel receives, in order: parameters, options, direction components."""
        return tuple(self.parameters) + self.option_names + self.direction_components

    def symbols(self) -> dict[str, sp.Symbol]:
        """The kernel inputs' symbols (what hoisting treats as per-element constants)."""
        return {p: sp.Symbol(p, real=True) for p in self.inputs}

    def point_symbols(self) -> dict[str, sp.Symbol]:
        return {p: sp.Symbol(p, real=True) for p, _ in self.point_inputs}

    def W(self, F, symbols: dict | None = None):
        """The energy density at F with the input symbols (default: symbols()); the direction
        components are passed as the 3x1 vectors energy() receives, the point inputs as symbols."""
        symbols = self.symbols() if symbols is None else symbols
        scalars = {p: symbols[p] for p in tuple(self.parameters) + self.option_names}
        vectors = {d: sp.Matrix([symbols[f"{d}_{c}"] for c in "xyz"]) for d in self.directions}
        return self.energy(F, **scalars, **vectors, **self.point_symbols())

    def native_parameters(self, E=None, nu=None, incompressible=False, **given) -> dict[str, np.ndarray]:
        """Native parameters from either (E, nu) or the native names, validated; the options (their
        defaults where not given) and the direction components given.  incompressible: nu = 0.5 is
        allowed (a mixed u-p formulation, runtime.assembly.mixed), and the bulk parameter it makes
        infinite is returned as inf."""
        options = {k: given.pop(k) for k in list(given) if k in self.option_names}
        directions = {k: given.pop(k) for k in list(given) if k in self.direction_components}
        out = self._native(E, nu, given, incompressible)
        out.update(_options(self, options))
        for k, v in directions.items():
            value = np.asarray(v, dtype=float)
            if not np.all(np.isfinite(value)):
                raise LawError(f"law {self.name!r}: direction component {k} is not finite")
            out[k] = value
        return out

    def _native(self, E, nu, native, incompressible=False) -> dict[str, np.ndarray]:
        if native and (E is not None or nu is not None):
            raise LawError(f"law {self.name!r}: give either E and nu or native parameters, not both")
        if not native and self.parameters:
            if E is None or nu is None:
                raise LawError(f"law {self.name!r} needs E and nu (or native parameters {', '.join(self.parameters)})")
            E, nu = validate_E_nu(E, nu, incompressible)
            with np.errstate(divide="ignore"):     # nu = 0.5: the bulk modulus is infinite
                native = self.from_E_nu(E, nu)
        unknown = sorted(set(native) - set(self.parameters))
        missing = [p for p in self.parameters if p not in native]
        if unknown:
            takes = ", ".join(tuple(self.parameters) + self.option_names)
            raise LawError(f"law {self.name!r} has no parameter {', '.join(unknown)}; it takes {takes}")
        if missing:
            raise LawError(f"law {self.name!r} is missing parameter {', '.join(missing)}")
        out = {}
        for p in self.parameters:
            value = np.asarray(native[p], dtype=float)
            if not np.all(np.isfinite(value)) and not (incompressible and np.all(value == np.inf)):
                raise LawError(f"law {self.name!r}: parameter {p} is not finite")
            out[p] = value
        return out


def _options(law, given: dict) -> dict[str, np.ndarray]:
    """A law's options: given or their default, each a finite number in its bounds."""
    out = {}
    for name, default, (low, high) in law.options:
        if name not in given and default is None:
            raise LawError(f"law {law.name!r} needs parameter {name} (a number in [{low:g}, {high:g}])")
        value = np.asarray(given.get(name, default), dtype=float)
        if not np.all(np.isfinite(value)) or np.any(value < low) or np.any(value > high):
            raise LawError(f"law {law.name!r}: parameter {name} must be a number in [{low:g}, {high:g}], "
                           f"got {given.get(name)!r}")
        out[name] = value
    return out


def validate_E_nu(E, nu, incompressible=False):
    """E and nu as float arrays, or LawError; incompressible: nu = 0.5 is allowed (a mixed formulation)."""
    E = np.asarray(E, dtype=float)
    nu = np.asarray(nu, dtype=float)
    if not (np.all(np.isfinite(E)) and np.all(np.isfinite(nu))):
        raise LawError("E and nu must be finite numbers (got NaN or Inf)")
    if np.any(E <= 0):
        raise LawError(f"Young's modulus E must be > 0 (got {E.min():g})")
    too_large = nu > 0.5 if incompressible else nu >= 0.5
    if np.any(too_large) or np.any(nu <= -1.0):
        bad = nu.max() if np.any(too_large) else nu.min()
        if incompressible:
            raise LawError(f"Poisson's ratio nu must satisfy -1 < nu <= 0.5 (got {bad:g})")
        raise LawError(f"Poisson's ratio nu must satisfy -1 < nu < 0.5 (got {bad:g}); "
                       "nu = 0.5 is incompressible: it needs formulation = \"mixed\" (pressure unknowns)")
    return E, nu


def lame_from_E_nu(E, nu) -> tuple:
    """Lamé's lambda and mu from Young's modulus and Poisson's ratio."""
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    return lam, mu


def _no_density(*args, **kwargs):
    raise LawError("a discrete law has no energy density W(F): its energy is a function of the nodal "
                   "positions (DiscreteLaw.element_energy)")


@dataclass(frozen=True, eq=False)
class DiscreteLaw(Law):
    """An energy of one element written directly in its nodal positions: springs, lattice cubes.

    The second kind of energy source of the generator (generator/discrete.py) beside W(F):
      element_energy(element, x, X, **params) -> sympy expression: the element's energy (J) with
          x, X the (n_nodes, dim) sympy matrices of current and rest positions and the parameter
          symbols; it must be invariant under translations (the kernels store rest positions
          relative to the first node) and rotations (tests check both).
      rest_measure(element, X) -> the element's rest volume (area in 2D): stored as the "point
          volume" the runtime reads (summary, fields: energy density = energy / measure).
      rest_checks(element, X) -> [(left, right, flag, message)]: the constants kernel flags an
          element with `flag` where left > right (e.g. a lattice cube that is not a cube).
    `parameters` are what the constants kernel receives (E, nu and options such as HybMSS's A,
    all hoisted with the rest geometry into per-element stiffnesses); `options` gives their
    defaults; `elements` the element types the law is defined on (one kernel each, quadrature
    "discrete")."""
    energy: Callable[..., sp.Expr] = _no_density
    from_E_nu: Callable[..., dict] = None
    description: str = ""
    validity: str = ""
    element_energy: Callable[..., sp.Expr] = None
    rest_measure: Callable[..., sp.Expr] = None
    rest_checks: Callable[..., list] = lambda element, X: []
    elements: tuple = ()
    options: tuple = ()              # ((name, default, (low, high)), ...): parameters beyond E and nu
    kind = "discrete"

    @property
    def inputs(self) -> tuple[str, ...]:
        """What the constants kernel receives: `parameters` (E, nu and the options among them)."""
        return tuple(self.parameters)

    def native_parameters(self, E=None, nu=None, **options) -> dict[str, np.ndarray]:
        """E and nu (validated) and the options (their defaults where not given)."""
        known = {name: (default, bounds) for name, default, bounds in self.options}
        unknown = sorted(set(options) - set(known))
        if unknown:
            takes = ", ".join(["E", "nu"] + list(known))
            raise LawError(f"law {self.name!r} has no parameter {', '.join(unknown)}; it takes {takes}")
        if E is None or nu is None:
            raise LawError(f"law {self.name!r} needs E and nu"
                           + (f" (and optionally {', '.join(known)})" if known else ""))
        E, nu = validate_E_nu(E, nu)
        out = {"E": E, "nu": nu}
        for name, (default, (low, high)) in known.items():
            value = np.asarray(options.get(name, default), dtype=float)
            if not np.all(np.isfinite(value)) or np.any(value < low) or np.any(value > high):
                raise LawError(f"law {self.name!r}: parameter {name} must be a number in [{low:g}, {high:g}], "
                               f"got {options.get(name)!r}")
            out[name] = value
        return {p: out[p] for p in self.parameters}
