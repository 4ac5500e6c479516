"""Incremental Potential Contact through the IPC Toolkit (ipctk): a barrier that keeps surfaces apart.

The collision mesh holds the body's contact surface (runtime.contact.surface) first, then every
obstacle's triangles (runtime.contact.obstacles) at their current pose.  Its energy is

    kappa sum_k b(d_k),   b(d) = -(d - dhat)^2 log(d / dhat) for d < dhat, 0 beyond

over the primitive pairs k (vertex-face, edge-edge) closer than dhat (less the shells' offset),
so it enters Newton's potential like the elastic energy: its gradient in the residual, its
PSD-projected Hessian in the Newton matrix (added as a sparse matrix: contact pairs couple nodes
the mesh does not).  The line search starts from the largest step that continuous collision
detection (CCD) allows, so no iterate ever intersects.

Barrier stiffness: adaptive by default (IPCContact.start_stiffness: from the Newton matrix's mean
diagonal on the surface and, for pairs active at the start, IPC's gradient balance; then
ipctk.update_barrier_stiffness after each step when the distance keeps shrinking), or the
[contact] stiffness.  Friction (mu > 0): ipctk's smoothed Coulomb friction, lagged: the normal
forces and tangent bases come from the state at the start of each of friction_iterations solves.
Its dissipative potential h D((x - x_n) / h) (relative velocities: obstacles' motion included)
is added to the same potential.

Which pairs can touch: vertices of different obstacles never (they are rigid); body against
obstacles always; distinct bodies of the mesh when [contact] bodies (default true); a body against
itself when [contact] self = true.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..base.errors import TensormassError
from .base import ContactBase
from .candidates import CandidateCache

__all__ = ["IPCContact", "import_ipctk"]



def import_ipctk():
    try:
        import ipctk
    except ImportError:
        raise TensormassError("contact.method = \"ipc\" needs the IPC Toolkit (a dependency of tensormass that is "
                              "not importable here): pip install ipctk; contact.method = \"penalty\" runs without it") from None
    # one thread: ipctk sums its per-pair gradients and Hessians over threads in the order they finish,
    # so with more than one the same state gave Hessians 1e-17 apart (same scene, different bits)
    if ipctk.get_num_threads() != 1:
        ipctk.set_num_threads(1)
    return ipctk


class IPCContact(ContactBase):
    method = "ipc"

    def __init__(self, model, spec, obstacles, surface):
        super().__init__(model, spec, obstacles, surface)
        ipc = self.ipc = import_ipctk()
        nb = surface.size
        centre = self.X.mean(axis=0)
        chords = np.linalg.norm(self.X[surface.triangles] - self.X[np.roll(surface.triangles, 1, axis=1)], axis=2)
        resolution = float(chords.mean())
        reach = self.diagonal + max((np.linalg.norm(o.translation) for o in obstacles if o.translation is not None),
                                    default=0.0)
        self.rest, self.rest_faces, faces = [], [], [surface.triangles]
        offset = nb
        self.owner = []                      # per obstacle: its vertex range in the collision mesh
        for o in obstacles:
            V, F = o.triangles(2.0 * reach, resolution, centre)
            self.rest.append(V)
            self.rest_faces.append(F)
            faces.append(F + offset)
            self.owner.append((offset, offset + len(V)))
            offset += len(V)
        F = np.ascontiguousarray(np.vstack(faces), dtype=np.int32)
        V0 = np.vstack([self.X] + self.rest) if self.rest else self.X.copy()
        self.mesh = ipc.CollisionMesh(np.asfortranarray(V0), ipc.edges(F), F)
        self.n_body = nb
        self.mesh.can_collide = self._filter(ipc, surface, spec, self.mesh.num_vertices)
        self.dhat = float(spec.dhat) if spec.dhat is not None else spec.dhat_relative * self.diagonal
        self.dmin = float(surface.offset)
        self.kappa = None if spec.stiffness is None else float(spec.stiffness)
        self.kappa_max = self.kappa
        self._potential = None
        self.obstacle_V = self._obstacle_vertices(0.0)
        self._cache = None                   # (V, collisions) of the last state asked for
        self.tangential = None               # lagged friction: ipctk.TangentialCollisions
        self.previous = None                 # the collision mesh's vertices at the start of the step
        self.eps_v = float(spec.eps_v) if spec.eps_v is not None else 1e-3 * self.diagonal
        self._last_min = None
        # a bounding-volume hierarchy: the default hash grid sizes its cells by the mean edge, and a
        # plane's square (much larger than the body's triangles) would make it allocate without bound
        self.broad = ipc.LBVH()
        # additive CCD (conservative by construction): ipctk's default Tight Inclusion searched its full
        # 1e7 iterations on a plane pressed flat on a face (parallel edges), 25 s for one step of 27 nodes
        self.ccd = ipc.AdditiveCCD()
        self.ccd_seconds = 0.0
        self.candidates = CandidateCache(ipc, self.mesh, self.broad, reach=self.dhat + self.dmin, margin=self.dhat)
        self.target = None                   # the pose the obstacles move to within this step's Newton
        self.moves = any(o.moves for o in obstacles)
        self._coupling = None                # body x obstacle block of the last Hessian
        self.check_rest()

    @staticmethod
    def _filter(ipc, surface, spec, n_vertices):
        nb = surface.size
        if spec.self_contact:
            patch = np.arange(nb)                          # every pair of the body may touch
        elif spec.bodies:
            patch = surface.body.copy()                    # pairs of distinct bodies only
        else:
            patch = np.zeros(nb, dtype=np.int64)           # no pair of the mesh: obstacles only
        # a label for every vertex of the collision mesh (the filter reads one per vertex): the obstacles'
        # own one, so they touch every body; the static filter keeps obstacles off each other
        patch = np.concatenate([patch, np.full(n_vertices - nb, -1)])
        return ipc.make_vertex_patches_filter(np.asarray(patch, dtype=np.int32)) & ipc.make_static_obstacle_filter(nb)

    # -- geometry ----------------------------------------------------------------------------------
    def _obstacle_vertices(self, s):
        if not self.rest:
            return np.zeros((0, 3))
        return np.vstack([o.placed(V, self.amplitude(o, s)) for o, V in zip(self.obstacles, self.rest)])

    def set_pose(self, s: float) -> None:
        super().set_pose(s)
        self.obstacle_V = self._obstacle_vertices(s)

    def vertices(self, u, obstacle_V=None) -> np.ndarray:
        V = np.empty((self.mesh.num_vertices, 3), order="F")
        V[:self.n_body] = self.body_points(u)
        V[self.n_body:] = self.obstacle_V if obstacle_V is None else obstacle_V
        return V

    def collisions(self, V):
        if self._cache is not None and np.array_equal(self._cache[0], V):
            return self._cache[1]
        ipc = self.ipc
        cs = ipc.NormalCollisions()
        cs.build(self.candidates.at(V), self.mesh, V, self.dhat, self.dmin)
        self._cache = (V.copy(), cs)
        return cs

    def barrier(self):
        if self._potential is None or self._potential[0] != self.kappa:
            self._potential = (self.kappa, self.ipc.BarrierPotential(self.dhat, self.kappa))
        return self._potential[1]

    # -- setup checks -------------------------------------------------------------------------------
    def check_rest(self) -> None:
        """Refuse a body that intersects an obstacle or itself, or lies within the offset, at rest."""
        ipc = self.ipc
        V = self.vertices(np.zeros(self.n_dofs))
        for k, o in enumerate(self.obstacles):
            lo, hi = self.owner[k]
            inside = _inside(o, self.X, self.rest[k], self.rest_faces[k])
            if inside.size or self._pair_intersects(V, lo, hi):
                nodes = self.surface.nodes[inside[:5]] if inside.size else []
                which = (f"; nodes {', '.join(str(int(n)) for n in nodes)}{' ...' if inside.size > 5 else ''} "
                         "are inside it") if len(nodes) else ""
                raise TensormassError(f"obstacle {o.name!r} intersects the body at rest{which}: move it "
                                      "clear of the body (contact cannot start from an intersecting state)")
        if self.spec.self_contact or self.spec.bodies:
            body = ipc.CollisionMesh(np.asfortranarray(self.X), ipc.edges(self._body_faces()), self._body_faces())
            if ipc.has_intersections(body, np.asfortranarray(self.X), broad_phase=self.broad):
                raise TensormassError("contact: the body's surface intersects itself (or two bodies of the mesh "
                                      "overlap) at rest; contact cannot start from an intersecting state")
        d2 = self.collisions(V).compute_minimum_distance(self.mesh, V) if self.dmin > 0 else np.inf
        if np.isfinite(d2) and np.sqrt(d2) <= self.dmin:
            raise TensormassError(f"contact: at rest a pair is {np.sqrt(d2):.3g} m apart, within the shells' "
                                  f"half thickness {self.dmin:.3g} m; move the obstacles (or the mesh's bodies) clear")

    def _body_faces(self):
        return np.ascontiguousarray(self.surface.triangles, dtype=np.int32)

    def _pair_intersects(self, V, lo, hi) -> bool:
        ipc = self.ipc
        tris = np.vstack([self.surface.triangles, np.asarray(self.mesh.faces)[
            np.all((np.asarray(self.mesh.faces) >= lo) & (np.asarray(self.mesh.faces) < hi), axis=1)] - lo + self.n_body])
        pts = np.vstack([V[:self.n_body], V[lo:hi]])
        F = np.ascontiguousarray(tris, dtype=np.int32)
        pair = ipc.CollisionMesh(np.asfortranarray(pts), ipc.edges(F), F)
        pair.can_collide = ipc.make_static_obstacle_filter(self.n_body) & ipc.make_vertex_patches_filter(
            np.concatenate([np.zeros(self.n_body), np.ones(hi - lo)]).astype(np.int32))
        return bool(ipc.has_intersections(pair, np.asfortranarray(pts), broad_phase=self.broad))

    # -- a step --------------------------------------------------------------------------------------
    def begin_step(self, u, s0, s1, h) -> None:
        super().begin_step(u, s0, s1, h)
        self.set_pose(s0)
        self.target = s1
        self.previous = self.vertices(u)
        self.tangential = None

    def start_stiffness(self, potential, u) -> None:
        """The adaptive barrier stiffness, at the first solve.

        kappa_min makes a pair at dhat / 2 as stiff as the Newton matrix's mean diagonal on the surface
        (the body's own stiffness there, inertia included); when pairs are active at the start, the
        stiffness that balances the elastic gradient against the barrier's (IPC's rule) is taken if
        larger, up to kappa_max = 100 kappa_min, the cap update_barrier_stiffness grows towards."""
        if self.kappa is not None:
            return
        V = self.vertices(u)
        cs = self.collisions(V)
        data = potential.hessian(u, False)
        diag = data[potential.asm.pattern.diagonal][self.dofs]
        average = float(np.mean(np.abs(diag))) if diag.size else 1.0
        unit = self.ipc.BarrierPotential(self.dhat, 1.0)
        b = unit.barrier                  # (a view into unit: keep unit alive while b is used)
        d2, dh2 = (0.5 * self.dhat) ** 2, self.dhat ** 2
        pair = 2.0 * b.first_derivative(d2, dh2) + 4.0 * d2 * b.second_derivative(d2, dh2)
        kappa_min = average / pair
        kappa = kappa_min
        if len(cs):
            gB = np.asarray(unit.gradient(cs, self.mesh, V))[:3 * self.n_body]
            gE = potential.gradient(u, contact=False)[self.dofs]
            if gB @ gB > 0:
                kappa = max(kappa, -float(gB @ gE) / float(gB @ gB))
        self.kappa_max = 100.0 * kappa_min
        self.kappa = min(kappa, self.kappa_max)

    def end_step(self, u) -> None:
        """Stiffen the barrier when the pairs keep closing in (ipctk.update_barrier_stiffness)."""
        V = self.vertices(u)
        d2 = self.collisions(V).compute_minimum_distance(self.mesh, V)
        if self.spec.stiffness is None and self._last_min is not None and np.isfinite(d2):
            self.kappa = self.ipc.update_barrier_stiffness(self._last_min, d2, self.kappa_max, self.kappa,
                                                           self.diagonal, dmin=self.dmin)
        self._last_min = d2 if np.isfinite(d2) else None

    # -- the obstacles' move within Newton: a prescribed motion like that of fixed dofs ----------------
    def pose_moving(self) -> bool:
        return self.target is not None and self.s != self.target and self.moves

    def try_pose(self, a: float) -> None:
        """Obstacles at the share a of the remaining move (a line-search trial)."""
        if self.pose_moving():
            self.obstacle_V = self._obstacle_vertices(self.s + a * (self.target - self.s))

    def accept_pose(self, a: float) -> None:
        if self.pose_moving():
            self.set_pose(self.target if a == 1.0 else self.s + a * (self.target - self.s))

    def pose_load(self, u) -> np.ndarray | None:
        """H_bo dV_o: the change of the body's gradient the obstacles' remaining move causes, to first
        order (the right-hand side moving fixed dofs give), from the last hessian()'s coupling block."""
        if not self.pose_moving() or self._coupling is None:
            return None
        dV = (self._obstacle_vertices(self.target) - self.obstacle_V).ravel()
        return self.scatter(self._coupling @ dV)

    def lag_friction(self, u) -> None:
        """Friction's normal forces and tangent bases from the state u (a lagging iteration)."""
        if self.spec.mu <= 0:
            return
        ipc = self.ipc
        V = self.vertices(u)
        tc = ipc.TangentialCollisions()
        tc.build(self.mesh, V, self.collisions(V), self.barrier(), float(self.spec.mu))
        self.tangential = tc
        self._friction = ipc.FrictionPotential(self.eps_v)

    # -- the potential's terms -----------------------------------------------------------------------
    def _velocities(self, V):
        return (V - self.previous) / self.h

    def energy(self, u) -> float:
        V = self.vertices(u)
        cs = self.collisions(V)
        E = float(self.barrier()(cs, self.mesh, V)) if len(cs) else 0.0
        if self.tangential is not None and len(self.tangential):
            E += self.h * float(self._friction(self.tangential, self.mesh, self._velocities(V)))
        return E

    def _gradient_all(self, u, V=None) -> np.ndarray:
        V = self.vertices(u) if V is None else V
        cs = self.collisions(V)
        g = self.barrier().gradient(cs, self.mesh, V) if len(cs) else np.zeros(V.size)
        if self.tangential is not None and len(self.tangential):
            g = g + self._friction.gradient(self.tangential, self.mesh, self._velocities(V))
        return np.asarray(g)

    def gradient(self, u) -> np.ndarray:
        return self.scatter(self._gradient_all(u)[:3 * self.n_body])

    def hessian(self, u, project: bool = True):
        V = self.vertices(u)
        cs = self.collisions(V)
        ipc, nb3 = self.ipc, 3 * self.n_body
        psd = ipc.PSDProjectionMethod.CLAMP if project else ipc.PSDProjectionMethod.NONE
        if not len(cs):
            return None
        H = self.barrier().hessian(cs, self.mesh, V, project_hessian_to_psd=psd)
        if self.tangential is not None and len(self.tangential):
            H = H + self._friction.hessian(self.tangential, self.mesh, self._velocities(V),
                                           project_hessian_to_psd=psd) / self.h
        H = H.tocoo()
        body = H.row < nb3
        inner = body & (H.col < nb3)
        outer = body & ~inner
        self._coupling = sp.coo_matrix((H.data[outer], (H.row[outer], H.col[outer] - nb3)),
                                       shape=(nb3, H.shape[1] - nb3)) if self.obstacles else None
        return self.to_global(H.row[inner], H.col[inner], H.data[inner])

    def max_step(self, u, d) -> float:
        """The largest a <= 1 for which the path to (u + a d, the obstacles a of the way to their target)
        crosses nothing (ipctk's CCD, which already keeps a margin)."""
        moving = self.pose_moving()
        if not np.any(d[self.dofs]) and not moving:
            return 1.0
        end = self._obstacle_vertices(self.target) if moving else None
        V0, V1 = self.vertices(u), self.vertices(u + d, end)
        candidates = self.candidates.along(V0, V1)
        start = time.perf_counter()
        a = float(candidates.compute_collision_free_stepsize(self.mesh, V0, V1, min_distance=self.dmin,
                                                             narrow_phase_ccd=self.ccd))
        self.ccd_seconds += time.perf_counter() - start      # read by benchmarks only
        self.step_ccd = min(self.step_ccd, a)
        return a

    # -- checks and records ---------------------------------------------------------------------------
    def settings(self) -> dict:
        return {"dhat": self.dhat, "stiffness": self.kappa, "adaptive_stiffness": self.spec.stiffness is None,
                "mu": self.spec.mu, "friction_iterations": self.spec.friction_iterations if self.spec.mu > 0 else 0,
                "eps_v": self.eps_v if self.spec.mu > 0 else None, "self": self.spec.self_contact,
                "bodies": self.spec.bodies, "check_every": self.spec.check_every}

    def intersecting(self, u) -> str | None:
        V = self.vertices(u)
        if self.ipc.has_intersections(self.mesh, V, broad_phase=self.broad):
            return "the contact surfaces intersect (IPC must never reach such a state)"
        return None

    def record(self, u) -> dict:
        V = self.vertices(u)
        cs = self.collisions(V)
        d2 = cs.compute_minimum_distance(self.mesh, V) if len(cs) else np.inf
        g = self._gradient_all(u, V).reshape(-1, 3)
        # the obstacles' work on the body over the step: their vertices' moves against the contact
        # force, trapezoidal between the forces at the step's ends
        nb = self.n_body
        last = getattr(self, "_last_obstacles", None)
        if last is not None and last[0].shape == V[nb:].shape:
            self.add_work(float(np.sum(0.5 * (last[1] + g[nb:]) * (V[nb:] - last[0]))))
        self._last_obstacles = (V[nb:].copy(), g[nb:].copy())
        obstacles = {}
        for k, (o, (lo, hi)) in enumerate(zip(self.obstacles, self.owner)):
            f = -g[lo:hi]
            c = o.centre(self.amplitude(o, self.s), self.rest[k])
            obstacles[o.name] = {"force": f.sum(axis=0).tolist(), "moment": np.cross(V[lo:hi] - c, f).sum(axis=0).tolist()}
        return {"pairs": int(len(cs)), "min_distance": float(np.sqrt(d2)) if np.isfinite(d2) else None,
                "ccd_fraction": float(self.step_ccd), "penetration": None, "obstacles": obstacles,
                "stiffness": self.kappa}


def _inside(o, X, V, F) -> np.ndarray:
    """Indices of the points X inside the obstacle at rest (analytic distance, or winding number)."""
    if o.shape != "mesh":
        d = o.distance(X, 0.0)[0]
        return np.flatnonzero(d < 0)
    return np.flatnonzero(winding_numbers(X, V, F) > 0.5)


def winding_numbers(P, V, F) -> np.ndarray:
    """The generalized winding number of the closed triangle surface (V, F) at the points P."""
    out = np.zeros(len(P))
    for chunk in range(0, len(P), 256):
        p = P[chunk:chunk + 256]
        a, b, c = (V[F[:, i]][None, :, :] - p[:, None, :] for i in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc + np.einsum("pfi,pfi->pf", b, c) * la \
            + np.einsum("pfi,pfi->pf", c, a) * lb
        out[chunk:chunk + 256] = np.arctan2(det, den).sum(axis=1) / (2 * np.pi)
    return out
