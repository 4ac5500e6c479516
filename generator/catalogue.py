"""What the generator can produce: every element x law x quadrature that makes sense."""
from __future__ import annotations

from dataclasses import dataclass

from .. import laws
from .elements import ELEMENTS
from .. import elements as elements_table
from .discrete import QUADRATURE as DISCRETE
from .shell import QUADRATURE as SHELL
from .ir import EXACT, exact_degree
from .quadrature import GAUSS_RULES


@dataclass(frozen=True, order=True)
class Entry:
    element: str
    law: str
    quadrature: str

    @property
    def name(self) -> str:
        return f"{self.element}_{self.law}_{self.quadrature}"


def quadratures(element: str, law: str) -> list[str]:
    """gauss1..3 everywhere; 'exact' where the integrand is a polynomial (Hooke, StVK on simplices);
    a discrete law (springs): 'discrete' on the elements it is defined on, nothing elsewhere."""
    the_law = laws.kernel_law(law)
    if the_law.kind == "discrete":
        return [DISCRETE] if element in the_law.elements else []
    if the_law.kind == "shell":
        return [SHELL] if element in the_law.elements else []
    if not elements_table.get(element).solid:        # structural elements: their own laws only
        return []
    names = list(GAUSS_RULES)
    if exact_degree(element, laws.kernel_law(law)) is not None:
        names.append(EXACT)
    return names


def entries(elements=None, law_names=None, quadrature_names=None) -> list[Entry]:
    """Catalogue entries, sorted, filtered by the given names (None = every element and every
    material law; volume measures only when named). Unknown names raise."""
    elements = _check("element", elements, sorted(ELEMENTS))
    law_names = laws.names(user=False) if law_names is None else _check("law", law_names, catalogue_laws())
    found = []
    for e in elements:
        for law in law_names:
            for q in quadratures(e, law):
                if quadrature_names is None or q in quadrature_names:
                    found.append(Entry(e, law, q))
    if quadrature_names is not None:
        known = {q for e in elements for law in law_names for q in quadratures(e, law)}
        unknown = sorted(set(quadrature_names) - known)
        if unknown:
            raise ValueError(f"unknown quadrature {', '.join(unknown)}; available: {', '.join(sorted(known))}")
    return sorted(found)


def catalogue_laws(user: bool = True) -> list[str]:
    """Every law and volume measure: what generated/ holds kernels of (the measures on every element:
    the generator does not read the runtime's table of which formulation applies where); with user,
    the law files outside the package too (laws.load_file, $TENSORMASS_LAWS) and the viscoelastic
    step energies NAME_viscous (laws/viscous.py), generated on first use like them."""
    return laws.names(user) + laws.measure_names() + (laws.viscous_names() if user else [])


# Viscous step kernels (laws/viscous.py) are generated on first use; the one the tissue examples and
# the quick tests run is committed too, so that a cold run compiles it without deriving it first.
COMMITTED_VISCOUS = (Entry("tetra", "neohookean_viscous", "gauss1"),)


def catalogue() -> list[Entry]:
    """What generated/ holds: every built-in material law's entries, the volume measures'
    (laws/measures.py) and COMMITTED_VISCOUS."""
    return sorted(entries(None, catalogue_laws(user=False)) + list(COMMITTED_VISCOUS))


def _check(kind, given, known):
    if given is None:
        return known
    unknown = [g for g in given if g not in known]
    if unknown:
        raise ValueError(f"unknown {kind} {', '.join(unknown)}; known: {', '.join(known)}")
    return sorted(set(given))
