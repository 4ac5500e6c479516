"""Penalty contact: a quadratic energy on the penetration of each surface vertex into an obstacle.

    E = k/2 sum_v sum_o max(0, offset - d_o(x_v))^2

with d_o the exact signed distance of the analytic obstacle o (plane, sphere, capsule, box;
runtime.contact.obstacles) and offset the shells' half thickness.  Cheap (no pair search, no CCD)
and usable with the explicit integrator, but it lets vertices in: each step records the largest
penetration, and one above [contact] max_penetration is a warning.  Its Hessian is exact:
k (n n^T - g dn/dx) on penetrating vertices, g = offset - d, dn/dx the obstacle's curvature there.

Default stiffness k (N/m per vertex): 10 E h for the largest Young's modulus E of the materials and
the mean edge h of the contact surface, stiffer than the cells it pushes on.  Mesh obstacles have no
analytic distance and are refused here (IPC takes them); so are contacts between bodies.
"""
from __future__ import annotations

import numpy as np

from ..base.errors import TensormassError
from .base import ContactBase

__all__ = ["PenaltyContact"]


class PenaltyContact(ContactBase):
    method = "penalty"

    def __init__(self, model, spec, obstacles, surface):
        super().__init__(model, spec, obstacles, surface)
        for o in obstacles:
            if o.shape == "mesh":
                raise TensormassError(f"obstacle {o.name!r}: contact.method = \"penalty\" takes plane, sphere, "
                                      "capsule and box obstacles (a mesh obstacle has no exact distance); "
                                      "use contact.method = \"ipc\"")
        if spec.self_contact:
            raise TensormassError("contact.self = true: penalty contact is between the body and obstacles only; "
                                  "use contact.method = \"ipc\" for self-contact")
        self.offset = float(surface.offset)
        if spec.stiffness is not None:
            self.k = float(spec.stiffness)
        else:
            tri = surface.triangles
            edges = np.linalg.norm(self.X[tri] - self.X[np.roll(tri, 1, axis=1)], axis=2)
            E = max((float(m.E) for m in model.materials if m.E is not None), default=None)
            if E is None:
                raise TensormassError("contact.stiffness: give the penalty stiffness (N/m per vertex); the "
                                      "materials give no Young's modulus to derive it from")
            self.k = 10.0 * E * float(edges.mean())
        self.max_penetration = (float(spec.max_penetration) if spec.max_penetration is not None
                                else 1e-3 * self.diagonal)
        self.check_rest()

    def check_rest(self) -> None:
        for o in self.obstacles:
            d = o.distance(self.X, 0.0)[0]
            inside = np.flatnonzero(d < self.offset)
            if inside.size:
                nodes = ", ".join(str(int(n)) for n in self.surface.nodes[inside[:5]])
                raise TensormassError(f"obstacle {o.name!r} intersects the body at rest; nodes {nodes}"
                                      f"{' ...' if inside.size > 5 else ''} are inside it: move it clear of the body")

    def _terms(self, u):
        """Per obstacle: (vertices that penetrate, g = offset - d > 0 there, n, dn/dx)."""
        x = self.body_points(u)
        out = []
        for o in self.obstacles:
            d, n, dn = o.distance(x, self.amplitude(o, self.s))
            hit = np.flatnonzero(d < self.offset)
            out.append((hit, self.offset - d[hit], n[hit], dn[hit]))
        return out

    def energy(self, u) -> float:
        return 0.5 * self.k * float(sum(np.sum(g * g) for _, g, _, _ in self._terms(u)))

    def _vertex_gradient(self, u, terms=None):
        G = np.zeros((self.surface.size, 3))
        per = []
        for hit, g, n, _ in (self._terms(u) if terms is None else terms):
            f = -self.k * g[:, None] * n                 # dE/dx = -k g n
            np.add.at(G, hit, f)
            per.append(f)
        return G, per

    def gradient(self, u) -> np.ndarray:
        return self.scatter(self._vertex_gradient(u)[0].ravel())

    def hessian(self, u, project: bool = True):
        rows, cols, vals = [], [], []
        for hit, g, n, dn in self._terms(u):
            H = self.k * (np.einsum("ni,nj->nij", n, n) - g[:, None, None] * dn)
            if project:                                   # clamp the curvature part's negative modes
                w, Q = np.linalg.eigh(0.5 * (H + H.transpose(0, 2, 1)))
                H = np.einsum("nij,nj,nkj->nik", Q, np.maximum(w, 0.0), Q)
            base = 3 * hit
            r = base[:, None, None] + np.arange(3)[None, :, None]
            c = base[:, None, None] + np.arange(3)[None, None, :]
            rows.append(np.broadcast_to(r, H.shape).ravel())
            cols.append(np.broadcast_to(c, H.shape).ravel())
            vals.append(H.ravel())
        if not rows or not sum(v.size for v in vals):
            return None
        return self.to_global(np.concatenate(rows), np.concatenate(cols), np.concatenate(vals))

    def stable_time_step(self) -> float:
        """2 sqrt(m / k): the explicit step above which the lightest surface node bouncing on its
        penalty spring alone is unstable (the elastic estimate at rest does not see these springs)."""
        m = np.asarray(self.model.mass, dtype=float)[self.dofs]
        m = m[m > 0]
        return 2.0 * float(np.sqrt(m.min() / self.k)) if m.size else np.inf

    def settings(self) -> dict:
        return {"stiffness": self.k, "max_penetration_allowed": self.max_penetration}

    def record(self, u) -> dict:
        terms = self._terms(u)
        _, per = self._vertex_gradient(u, terms)
        x = self.body_points(u)
        obstacles, pairs, depth = {}, 0, 0.0
        last, frames = getattr(self, "_last_frames", None), []
        for k, (o, (hit, g, _, _), f) in enumerate(zip(self.obstacles, terms, per)):
            R1, c1 = o.frame(self.amplitude(o, self.s))          # the motion's and a viewer's shift
            frames.append((R1, c1))
            R0, c0 = (R1, c1) if last is None else last[k]
            if hit.size and not (np.array_equal(R0, R1) and np.array_equal(c0, c1)):
                # work on the body: the force at each vertex inside times the move over the step of the
                # obstacle's point under it (the rigid motion from the last pose to this one)
                X = (x[hit] - c1) @ R1                  # the obstacle's rest frame
                self.add_work(float(np.sum(-f * (x[hit] - (X @ R0.T + c0)))))
            on = f                                      # dE/dx on the body = the force on the obstacle
            c = o.centre(self.amplitude(o, self.s))
            obstacles[o.name] = {"force": on.sum(axis=0).tolist(),
                                 "moment": np.cross(x[hit] - c, on).sum(axis=0).tolist()}
            pairs += hit.size
            depth = max(depth, float(g.max()) if g.size else 0.0)
        self._last_frames = frames
        return {"pairs": int(pairs), "min_distance": None, "ccd_fraction": None, "penetration": depth,
                "obstacles": obstacles, "stiffness": self.k}
