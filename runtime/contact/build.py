"""The contact of a model's scene: IPC or penalty (runtime.contact.ipc, .penalty), or None."""
from __future__ import annotations

from .base import ContactSpec, check_integrator
from .ipc import IPCContact
from .penalty import PenaltyContact
from .surface import contact_surface

__all__ = ["build_contact"]


def build_contact(model):
    """The contact of a model's scene (runtime.contact.ipc or .penalty), or None without contact."""
    scene = getattr(model, "scene", None)
    spec = getattr(scene, "contact", None)
    obstacles = getattr(scene, "obstacles", None) or []
    if spec is None and not obstacles:
        return None
    spec = spec or ContactSpec()
    check_integrator(model.solver.kind, spec.method)
    surface = contact_surface(model)
    if spec.method == "penalty":
        return PenaltyContact(model, spec, obstacles, surface)
    return IPCContact(model, spec, obstacles, surface)
