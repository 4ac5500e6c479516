"""The kernel catalogue as a run sees it: which (element, law, quadrature) combinations exist.

For the built-in laws and the volume measures on the element types of the committed catalogue,
generated/manifest.json answers (what ``tensormass generate`` wrote; ``generate --check`` keeps
it equal to the generator's catalogue).  Anything else (a law file outside the package, an element
type registered after the catalogue was generated) asks the generator, which derives what
applies: its kernels are generated on first use anyway.  So a run whose kernels are committed
never imports the symbolic pipeline (sympy, jinja2).
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

from ... import generated, laws
from ..base.errors import TensormassError

__all__ = ["committed", "quadratures", "check"]


@lru_cache(maxsize=1)
def committed() -> dict:
    """generated/manifest.json entries by (element, law, quadrature)."""
    path = Path(generated.__file__).resolve().parent / "manifest.json"
    try:
        entries = json.loads(path.read_text(encoding="utf-8"))["entries"]
    except (OSError, ValueError, KeyError) as exc:
        raise TensormassError(f"cannot read the kernel catalogue {path}: {exc}") from None
    return {(e["element"], e["law"], e["quadrature"]): e for e in entries.values()}


@lru_cache(maxsize=1)
def _committed_elements() -> frozenset:
    return frozenset(element for element, _, _ in committed())


def _in_manifest(element: str | None, law: str) -> bool:
    """Whether the manifest is the whole answer for this law (and element, when given)."""
    if laws.user_law(law) is not None:
        return False
    if law not in laws.names(user=False) and law not in laws.measure_names():
        return False
    return element is None or element in _committed_elements()


def quadratures(element: str, law: str) -> list[str]:
    """The quadratures with a kernel for (element, law), in the generator's order (gauss1..3, exact;
    discrete or exact for springs and shells); [] where the law does not apply to the element."""
    if _in_manifest(element, law):
        found = [q for e, n, q in committed() if e == element and n == law]
        order = ("gauss1", "gauss2", "gauss3")
        return sorted(found, key=lambda q: (order.index(q) if q in order else len(order), q))
    # deferred: generator.catalogue loads sympy (0.72 s); only for laws or elements it must derive.
    from ...generator.catalogue import quadratures as derived
    return derived(element, law)


def check(element: str | None, law: str, quadrature: str) -> None:
    """ValueError naming the choices unless a kernel exists for (element, law, quadrature); with
    element None: for some element type."""
    if not _in_manifest(element, law):
        from ...generator.catalogue import entries       # deferred: see quadratures()
        entries(None if element is None else [element], [law], [quadrature])
        return
    known = {q for e, n, q in committed() if n == law and element in (None, e)}
    if quadrature not in known:
        raise ValueError(f"unknown quadrature {quadrature}; available: {', '.join(sorted(known))}")
