"""Obstacles: rigid, kinematic bodies the simulated body touches ([[obstacle]] in a scene).

    obstacle = Obstacle(name="floor", shape="plane", point=(0, 0, 0), normal=(0, 0, 1))
    V, F = obstacle.triangles(extent)         # its surface at rest, wound outward (IPC contact)
    x = obstacle.placed(V, a)                 # moved by its rigid motion at amplitude value a
    d, n = obstacle.distance(points, a)       # signed distance and outward normal (penalty contact)

Shapes: plane (a half-space: the body stays on the side its normal points to), sphere, capsule
(a segment swept by a ball: a tool tip), box (axis-aligned at rest), and mesh (a closed triangle
surface read with meshio: STL, OBJ, or anything it reads).  IPC contact sees every obstacle as
triangles: a plane as a square much larger than the body and its motion, a box exactly, a sphere
or capsule through a tessellation whose chords stay within `resolution` (the analytic surface lies
at most resolution^2 / (8 r) outside the triangles).  Penalty contact uses the exact signed distance
of the analytic shapes.

An obstacle moves like a [[fixed]] entry's rigid motion (runtime.physics.motion): the point X of
the obstacle at rest is at R(a angle)(X - p) + p + a t at amplitude value a (default: the ramp
a = s over the run), plus its `shift`, a translation a viewer's mouse sets between steps.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..base.errors import SceneError
from ..physics.motion import Rotation, rigid_displacement, rotation_matrix

__all__ = ["Obstacle", "SHAPES", "capsule_mesh", "box_mesh", "plane_mesh"]

SHAPES = ("plane", "sphere", "capsule", "box", "mesh")


@dataclass
class Obstacle:
    name: str
    shape: str                            # plane | sphere | capsule | box | mesh
    point: tuple | None = None            # plane: a point on it
    normal: tuple | None = None           # plane: the side the body stays on
    center: tuple | None = None           # sphere
    radius: float | None = None           # sphere, capsule
    a: tuple | None = None                # capsule: the segment's ends
    b: tuple | None = None
    box: tuple | None = None              # box: ((x0, y0, z0), (x1, y1, z1))
    file: str | None = None               # mesh: the file (absolute once parsed)
    scale: float = 1.0                    # mesh: a length scale applied to the file's coordinates
    resolution: float | None = None       # sphere, capsule: the largest chord [m]; None: from the body
    translation: tuple | None = None      # rigid motion, as for [[fixed]]
    rotation: Rotation | None = None
    amplitude: str | None = None
    # a translation on top of the motion, set between steps by a viewer's mouse (runtime.run.live:
    # penalty contact only, whose obstacles may jump between steps); None: none
    shift: tuple | None = None

    # -- motion ------------------------------------------------------------------------------------
    @property
    def moves(self) -> bool:
        return self.translation is not None or self.rotation is not None

    def placed(self, X: np.ndarray, a: float) -> np.ndarray:
        """Points X of the obstacle at rest, where its motion has them at amplitude value a."""
        X = np.asarray(X, dtype=float)
        Y = X.copy() if not self.moves or a == 0.0 else X + rigid_displacement(X, a, self.rotation, self.translation)
        return Y if self.shift is None else Y + np.asarray(self.shift, dtype=float)

    def centre(self, a: float, rest=None) -> np.ndarray:
        """The point moments about the obstacle are taken about, placed at amplitude value a: a plane's
        point, the centre of a sphere, capsule or box, the mean of a mesh's rest vertices `rest`."""
        if self.shape == "plane":
            p = np.asarray(self.point, float)
        elif self.shape == "sphere":
            p = np.asarray(self.center, float)
        elif self.shape == "capsule":
            p = 0.5 * (np.asarray(self.a, float) + np.asarray(self.b, float))
        elif self.shape == "box":
            p = 0.5 * (np.asarray(self.box[0], float) + np.asarray(self.box[1], float))
        else:
            p = np.asarray(rest, float).mean(axis=0)
        return self.placed(p[None, :], a)[0]

    def frame(self, a: float):
        """(R, c): x = R X + c maps the rest frame to the placed one."""
        R, c = np.eye(3), np.zeros(3)
        if self.rotation is not None:
            p = np.asarray(self.rotation.point, dtype=float)
            R = rotation_matrix(self.rotation.axis, math.radians(a * self.rotation.angle), 3)
            c = p - R @ p
        if self.translation is not None:
            c = c + a * np.asarray(self.translation, dtype=float)
        if self.shift is not None:
            c = c + np.asarray(self.shift, dtype=float)
        return R, c

    # -- surfaces (IPC) ----------------------------------------------------------------------------
    def triangles(self, extent: float, resolution: float, centre=None) -> tuple:
        """(V, F) of the surface at rest, wound outward (normals away from the obstacle).

        extent: the half-size of a plane's square (the body's size plus the room it moves in), centred
        on the projection of `centre` (the body's centre); resolution: the largest chord of curved
        shapes when the obstacle does not give one."""
        h = self.resolution or resolution
        if self.shape == "plane":
            p, n = np.asarray(self.point, float), np.asarray(self.normal, float) / np.linalg.norm(self.normal)
            if centre is not None:
                p = np.asarray(centre, float) - ((np.asarray(centre, float) - p) @ n) * n
            return plane_mesh(p, n, extent)
        if self.shape == "box":
            return box_mesh(*self.box)
        if self.shape == "sphere":
            return capsule_mesh(self.center, self.center, self.radius, h)
        if self.shape == "capsule":
            return capsule_mesh(self.a, self.b, self.radius, h)
        return self._read()

    def _read(self) -> tuple:
        import meshio
        try:
            m = meshio.read(self.file)
        except Exception as exc:            # meshio raises many kinds: name the file and the reason
            raise SceneError(f"obstacle {self.name!r}: cannot read {self.file}: {exc}") from None
        tris = [np.asarray(b.data) for b in m.cells if b.type == "triangle"]
        quads = [np.asarray(b.data) for b in m.cells if b.type == "quad"]
        faces = tris + [q[:, [0, 1, 2]] for q in quads] + [q[:, [0, 2, 3]] for q in quads]
        if not faces:
            raise SceneError(f"obstacle {self.name!r}: {self.file} holds no triangle or quad "
                             f"(cell types: {', '.join(b.type for b in m.cells) or 'none'})")
        F = np.concatenate(faces).astype(np.int64)
        V = np.asarray(m.points, dtype=float)[:, :3] * self.scale
        if V.shape[1] != 3 or not np.all(np.isfinite(V)):
            raise SceneError(f"obstacle {self.name!r}: {self.file} needs finite 3D coordinates")
        used = np.unique(F)
        remap = np.full(len(V), -1)
        remap[used] = np.arange(used.size)
        V, F = V[used], remap[F]
        check_closed(F, f"obstacle {self.name!r} ({self.file})")
        return V, F

    # -- signed distance (penalty) -----------------------------------------------------------------
    def distance(self, x: np.ndarray, a: float) -> tuple:
        """(d, n, curvature) at the points x (n, 3) with the obstacle placed at amplitude value a.

        d: signed distance (< 0 inside), n: the unit outward normal of the nearest surface point,
        curvature: dn/dx (n, 3, 3), exact where d < 0 (what the penalty's Hessian needs)."""
        R, c = self.frame(a)
        X = (np.asarray(x, dtype=float) - c) @ R            # R^T (x - c), row-wise
        d, n, dn = self._rest_distance(X)
        n = n @ R.T
        dn = np.einsum("ij,njk,lk->nil", R, dn, R)
        return d, n, dn

    def _rest_distance(self, X):
        m = len(X)
        zero = np.zeros((m, 3, 3))
        if self.shape == "plane":
            n = np.asarray(self.normal, float) / np.linalg.norm(self.normal)
            return (X - np.asarray(self.point, float)) @ n, np.tile(n, (m, 1)), zero
        if self.shape == "box":
            lo, hi = (np.asarray(v, float) for v in self.box)
            return _box_distance(X, lo, hi)
        if self.shape == "sphere":
            a = b = np.asarray(self.center, float)
        elif self.shape == "capsule":
            a, b = np.asarray(self.a, float), np.asarray(self.b, float)
        else:
            raise SceneError(f"obstacle {self.name!r}: a mesh obstacle has no analytic distance; "
                             "contact.method = \"penalty\" takes plane, sphere, capsule and box obstacles")
        return _capsule_distance(X, a, b, float(self.radius))


def _capsule_distance(X, a, b, r):
    axis = b - a
    L2 = float(axis @ axis)
    t = np.zeros(len(X)) if L2 == 0 else np.clip((X - a) @ axis / L2, 0.0, 1.0)
    q = a + t[:, None] * axis
    w = X - q
    rho = np.linalg.norm(w, axis=1)
    safe = np.where(rho > 0, rho, 1.0)
    n = np.where(rho[:, None] > 0, w / safe[:, None], np.array([0.0, 0.0, 1.0]))
    # dw/dX: I - tau tau^T along the segment's interior, I at the ends
    tau = axis / math.sqrt(L2) if L2 > 0 else np.zeros(3)
    inner = ((t > 0) & (t < 1))[:, None, None]
    dw = np.eye(3) - np.where(inner, np.outer(tau, tau), 0.0)
    P = np.eye(3) - np.einsum("ni,nj->nij", n, n)
    dn = np.einsum("nij,njk->nik", P, dw) / safe[:, None, None]
    return rho - r, n, dn


def _box_distance(X, lo, hi):
    c, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    q = np.abs(X - c) - half
    sign = np.where(X - c >= 0, 1.0, -1.0)
    outside = np.maximum(q, 0.0)
    out_norm = np.linalg.norm(outside, axis=1)
    inside = np.minimum(q.max(axis=1), 0.0)
    d = out_norm + inside
    n = np.zeros_like(X)
    dn = np.zeros((len(X), 3, 3))
    out = out_norm > 0
    n[out] = sign[out] * outside[out] / out_norm[out, None]
    k = np.argmax(q, axis=1)                 # inside (and on faces): the nearest face's normal
    rows = np.flatnonzero(~out)
    n[rows, k[rows]] = sign[rows, k[rows]]
    # outside an edge or corner the normal turns: dn = (P restricted to the free directions) / |outside|
    free = (q > 0).astype(float)
    if out.any():
        nn = n[out]
        Dfree = np.einsum("ni,ij->nij", free[out], np.eye(3))
        P = Dfree - np.einsum("ni,nj->nij", nn, nn)
        dn[out] = P / out_norm[out, None, None]
    return d, n, dn


# ------------------------------------------------------------------------------------ tessellation


def plane_mesh(point, normal, extent):
    """A square of half-side `extent` centred on point, normal along `normal`: two triangles."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(n, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    p = np.asarray(point, float)
    V = np.array([p + extent * (sx * e1 + sy * e2) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return V, np.array([[0, 1, 2], [0, 2, 3]])           # e1 x e2 = n: wound towards the body


def box_mesh(lo, hi):
    """The axis-aligned box [lo, hi]: 8 corners, 12 triangles wound outward."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    V = np.array([[(hi if (i >> k) & 1 else lo)[k] for k in range(3)] for i in range(8)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    F = np.array([t for q in quads for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))])
    return V, F


def capsule_mesh(a, b, radius, chord):
    """A capsule (a sphere when a == b): rings of a UV sphere split at the equator and pulled apart.

    The angular steps keep every chord at most `chord` (at least 12 around and 3 rings per cap),
    triangles wound outward."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    r = float(radius)
    axis = b - a
    L = float(np.linalg.norm(axis))
    t = axis / L if L > 0 else np.array([0.0, 0.0, 1.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(t[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(t, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(t, e1)
    step = 2.0 * math.asin(min(1.0, 0.5 * chord / r))
    around = max(12, math.ceil(2.0 * math.pi / step))
    rings = max(3, math.ceil(0.5 * math.pi / step))
    along = max(1, math.ceil(L / chord)) if L > 0 else 0
    phi = 2.0 * np.pi * np.arange(around) / around
    circle = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    layers = []                          # (centre, radius of the ring, offset along t) from the a pole up
    polar = np.linspace(0.0, 0.5 * np.pi, rings + 1)[1:]           # from the a pole to the equator
    for th in polar:
        layers.append(a - r * math.cos(th) * t + r * math.sin(th) * circle)
    for k in range(1, along + 1):
        layers.append(a + (L * k / along) * t + r * circle)
    for th in polar[::-1][1:]:
        layers.append(b + r * math.cos(th) * t + r * math.sin(th) * circle)
    V = np.vstack([a - r * t, *layers, b + r * t])
    n_layers = len(layers)
    F = []
    ring = lambda i: 1 + i * around + np.arange(around)              # noqa: E731 (index of layer i)
    nxt = np.roll(np.arange(around), -1)
    first = ring(0)
    F += [(0, first[nxt[j]], first[j]) for j in range(around)]
    for i in range(n_layers - 1):
        lo, hi = ring(i), ring(i + 1)
        for j in range(around):
            F += [(lo[j], lo[nxt[j]], hi[nxt[j]]), (lo[j], hi[nxt[j]], hi[j])]
    last, top = ring(n_layers - 1), len(V) - 1
    F += [(top, last[j], last[nxt[j]]) for j in range(around)]
    return V, np.asarray(F, dtype=np.int64)


def check_closed(F, what: str) -> None:
    """Refuse a surface that is open or non-manifold (an edge not shared by exactly two triangles)."""
    F = np.asarray(F)
    edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    open_edges, many = int(np.sum(counts == 1)), int(np.sum(counts > 2))
    if open_edges or many:
        raise SceneError(f"{what}: the surface must be closed and manifold (every edge in exactly two "
                         f"triangles); {open_edges} open edge(s), {many} edge(s) in more than two")
