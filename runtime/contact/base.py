"""What IPC and penalty contact share: the [contact] settings, obstacle poses, records per step.

    contact = build_contact(model)       # runtime.contact.build: None without [contact] / [[obstacle]]
    contact.begin_step(u, s0, s1, h)     # the step from run fraction s0 to s1 (h: its length; statics 1)
    contact.energy(u); contact.gradient(u); contact.hessian(u, project)   # terms of the potential
    contact.max_step(u, d)               # largest a <= 1 with u + a d free of intersections (IPC)
    contact.record(u)                    # the step's row: pairs, minimum distance, forces on obstacles

Integrators take contact through runtime.physics.newton's Potential (energy, gradient, the Hessian
as an extra sparse matrix, the line search's step limit) and through contact_solve (the obstacles'
motion within a step and friction's lagging iterations).  Which integrator takes which method:
METHODS_OF.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..base.errors import TensormassError

__all__ = ["ContactSpec", "METHODS", "METHODS_OF", "ContactBase", "check_integrator"]

METHODS = ("ipc", "penalty")
# solver kind -> the contact methods it takes.  IPC needs Newton on an incremental potential with a
# CCD-capped line search (static, backward Euler).  Implicit Euler's one linear solve per step knows
# the barrier to first order only: capped by CCD, a block resting on a floor closes its gap by the
# cap's share every step until it touches (measured: gap 1e-17 m after 25 steps), so it takes the
# penalty.  Explicit steps are not solves: penalty forces only; the generalized-alpha state y mixes
# two times, so a barrier on y does not keep u_{n+1} apart.
METHODS_OF = {"static": ("ipc", "penalty"), "backward_euler": ("ipc", "penalty"),
              "implicit_euler": ("penalty",), "explicit": ("penalty",),
              "generalized_alpha": ("penalty",)}


@dataclass
class ContactSpec:
    """The [contact] table."""
    method: str = "ipc"
    dhat: float | None = None             # barrier activation distance [m]; None: dhat_relative x body diagonal
    dhat_relative: float = 1e-3
    stiffness: float | None = None        # IPC: barrier stiffness (None: adaptive); penalty: N/m per vertex
    mu: float = 0.0                       # friction coefficient (IPC)
    friction_iterations: int = 2          # lagging iterations of the friction's normal forces and bases
    eps_v: float | None = None            # friction's smoothing velocity [m/s]; None: 1e-3 x body diagonal / s
    self_contact: bool = False            # a body against itself
    bodies: bool = True                   # distinct bodies of the mesh against each other
    check_every: int = 1                  # IPC: intersection test of the contact surfaces every this many steps
    max_penetration: float | None = None  # penalty: warn above this [m]; None: 1e-3 x body diagonal


def check_integrator(kind: str, method: str) -> None:
    takes = METHODS_OF.get(kind, ())
    if method not in takes:
        other = [k for k, ms in METHODS_OF.items() if method in ms]
        raise TensormassError(f"contact.method = {method!r} does not work with solver.kind = {kind!r} "
                              f"(it takes {', '.join(repr(m) for m in takes) or 'no contact'}); "
                              f"{method!r} runs with {', '.join(other)}")


class ContactBase:
    """Poses of the obstacles over the run, the dof map of the surface and the step's record."""
    method = ""

    def __init__(self, model, spec: ContactSpec, obstacles, surface):
        self.model, self.spec, self.obstacles, self.surface = model, spec, list(obstacles), surface
        dpn = model.dofs_per_node
        self.dofs = (surface.nodes[:, None] * dpn + np.arange(3)).ravel()
        self.n_dofs = model.n_dofs
        self.X = np.asarray(model.mesh.points, dtype=float)[surface.nodes]
        lo, hi = model.mesh.points.min(axis=0), model.mesh.points.max(axis=0)
        self.diagonal = float(np.linalg.norm(hi - lo))
        self.s = 0.0                       # run fraction of the obstacles' current pose
        self.h = 1.0
        self.step_ccd = 1.0                # smallest step fraction CCD allowed this step
        self.forces_now = None

    # -- poses -------------------------------------------------------------------------------------
    def amplitude(self, obstacle, s: float) -> float:
        return self.model.motion.factor(obstacle.amplitude, s)

    def body_points(self, u: np.ndarray) -> np.ndarray:
        return self.X + u[self.dofs].reshape(-1, 3)

    def set_pose(self, s: float) -> None:
        self.s = float(s)

    # -- a step ------------------------------------------------------------------------------------
    def begin_step(self, u, s0: float, s1: float, h: float) -> None:
        self.h = float(h)
        self.step_ccd = 1.0

    def scatter(self, g_body: np.ndarray) -> np.ndarray:
        out = np.zeros(self.n_dofs)
        out[self.dofs] = g_body
        return out

    def to_global(self, rows, cols, values) -> sp.coo_matrix:
        """Entries over the surface's vertex dofs as an (n_dofs x n_dofs) matrix (COO: Newton adds it to
        its own matrix entry by entry, so nothing here is sorted or compressed)."""
        return sp.coo_matrix((values, (self.dofs[rows], self.dofs[cols])), shape=(self.n_dofs, self.n_dofs))

    def max_step(self, u, d) -> float:
        return 1.0

    # the obstacles' move inside Newton (IPC overrides these; penalty places them at once)
    def pose_moving(self) -> bool:
        return False

    def try_pose(self, a: float) -> None:
        pass

    def accept_pose(self, a: float) -> None:
        pass

    def pose_load(self, u):
        return None

    def stable_time_step(self) -> float:
        """The explicit step the contact itself allows (penalty springs); no limit of its own here."""
        return np.inf

    def intersecting(self, u) -> str | None:
        return None

    def add_work(self, increment: float) -> None:
        """The work the obstacles did on the body over a step (their motion against the contact force):
        the health monitor's energy balance counts it as external work, and its running total of
        magnitudes as an energy scale (a scene driven by obstacles alone has no other)."""
        self.work = getattr(self, "work", 0.0) + float(increment)
        self.work_scale = getattr(self, "work_scale", 0.0) + abs(float(increment))

    def note(self, record: dict) -> None:
        """Keep the run's extremes of the step records (for the summary)."""
        seen = self.__dict__.setdefault("_extremes", {"steps": 0, "max_pairs": 0, "min_distance": None,
                                                      "min_ccd_fraction": None, "max_penetration": None})
        seen["steps"] += 1
        seen["max_pairs"] = max(seen["max_pairs"], int(record["pairs"]))
        for key, pick, name in (("min_distance", min, "min_distance"), ("ccd_fraction", min, "min_ccd_fraction"),
                                ("penetration", max, "max_penetration")):
            value = record.get(key)
            if value is not None:
                seen[name] = value if seen[name] is None else pick(seen[name], value)

    def summary(self) -> dict:
        """summary["contact"]: the method, its settings as used, the surface and the run's extremes."""
        out = {"method": self.method, "obstacles": [o.name for o in self.obstacles],
               "surface": {"vertices": int(self.surface.size), "triangles": int(len(self.surface.triangles)),
                           "bodies": int(self.surface.n_bodies), "offset": float(self.surface.offset),
                           "kind": self.surface.kind},
               **self.settings()}
        out.update(self.__dict__.get("_extremes", {}))
        return out

    def settings(self) -> dict:
        return {}

    def nodal_forces(self, u) -> np.ndarray:
        """(n_points, 3): the force the contact exerts on each node (zero off the surface)."""
        f = np.zeros((self.model.n_points, 3))
        f[self.surface.nodes] = -self.gradient(u)[self.dofs].reshape(-1, 3)
        return f

    def nodal_pressure(self, u) -> np.ndarray:
        """(n_points,): |contact force| / the node's share of the rest surface (a third of the area of
        the triangles around it) [Pa]; zero off the surface."""
        tri = self.X[self.surface.triangles]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        share = np.bincount(self.surface.triangles.ravel(), weights=np.repeat(area / 3.0, 3),
                            minlength=self.surface.size)
        p = np.zeros(self.model.n_points)
        f = self.gradient(u)[self.dofs].reshape(-1, 3)
        p[self.surface.nodes] = np.linalg.norm(f, axis=1) / np.where(share > 0, share, np.inf)
        return p
