"""What each integrator is, declared once and light (no numba, no scipy): the scene parser, the
resource estimate, the model and the run read these, and runtime.physics.integrators builds the
integrators that match them (a test checks the two agree)."""
from __future__ import annotations

from dataclasses import dataclass

from .errors import TensormassError

__all__ = ["IntegratorKind", "KINDS", "NAMES", "get"]


@dataclass(frozen=True)
class IntegratorKind:
    name: str
    dynamic: bool                 # time stepping with inertia; False: load stepping to equilibria
    outputs: tuple                # the kernel outputs it calls (the model compiles exactly these)
    newton_iterations: int        # typical Newton iterations per step (the resource estimate's time)
    consistent_mass: bool         # accepts solver.mass = "consistent" (explicit steps invert the lumped mass)
    hanging_nodes: bool           # solves with hanging-node constraints eliminated (1:8 refinement)
    takes_rho_inf: bool = False   # solver.rho_inf (high-frequency damping) applies

    @property
    def step_output(self) -> str:
        """The kernel call of one iteration: forces alone, or forces and stiffness together."""
        return "forces_and_stiffness" if "stiffness" in self.outputs else "forces"


KINDS = {k.name: k for k in (
    IntegratorKind("static", dynamic=False, outputs=("energy", "forces", "stiffness"), newton_iterations=4,
                   consistent_mass=True, hanging_nodes=True),
    IntegratorKind("implicit_euler", dynamic=True, outputs=("energy", "forces", "stiffness"), newton_iterations=1,
                   consistent_mass=True, hanging_nodes=True),
    IntegratorKind("backward_euler", dynamic=True, outputs=("energy", "forces", "stiffness"), newton_iterations=2,
                   consistent_mass=True, hanging_nodes=True),
    # energy every few steps only (health monitor, reports)
    IntegratorKind("explicit", dynamic=True, outputs=("forces", "energy"), newton_iterations=1,
                   consistent_mass=False, hanging_nodes=False),
    IntegratorKind("generalized_alpha", dynamic=True, outputs=("energy", "forces", "stiffness"), newton_iterations=2,
                   consistent_mass=True, hanging_nodes=False, takes_rho_inf=True),
)}
NAMES = tuple(KINDS)


def get(name: str) -> IntegratorKind:
    try:
        return KINDS[name]
    except KeyError:
        raise TensormassError(f"unknown solver.kind {name!r}; known: {', '.join(NAMES)}") from None
