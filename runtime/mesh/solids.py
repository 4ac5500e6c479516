"""Tetrahedral meshes of solids, built without gmsh (CI installs none).

    points, tetra = ball_tetrahedra(radius, n)     # the solid ball (a cubed ball, 6 tetrahedra per cell)
    q = tetra_quality(points, tetra)               # volumes and dihedral angles, for checks
    faces = boundary_faces(tetra)                  # its surface, wound outward

**The ball** is a cubed ball: a central cube of n x n x n hexahedra (half-side CORE_SIZE R) and six
blocks of n x n x `layers` hexahedra between the cube's faces and the sphere.  A block's node at
direction d (a point of the unit cube's surface) and layer fraction t in [0, 1] sits at

    x = R ((1 - t) A d + t S(d)),      A = CORE_SIZE,

where S is the smooth cube-to-sphere map S(d)_x = d_x sqrt(1 - d_y^2/2 - d_z^2/2 + d_y^2 d_z^2/3)
(and cyclic permutations): it sends the cube's surface onto the unit sphere exactly and spreads
the cells more evenly than d / |d|.  Nodes move along straight blends, so no cell folds.  A
plain cube grid mapped onto the ball would not do: the cells along the cube's edges and corners
would have two or three faces on the sphere, almost coplanar (dihedral angles near 180 deg).

Each hexahedron is cut into six tetrahedra around the diagonal from its corner nearest the
centre (Kuhn's cut).  Every hexahedron's axes point away from the centre (in the cube: away from
the coordinate planes; in a block: outward and away from the face's centre), so neighbours, also
across blocks, orient their shared edges alike and cut their shared faces along the same
diagonal: the mesh is conforming, and mirror-symmetric in x, y and z (a squeeze along z stays
symmetric).

Why this rather than a Delaunay of scattered points: Delaunay tetrahedralisations make slivers
(flat tetrahedra with dihedral angles near 0 and 180 deg) that spoil the stiffness matrix.  Here
the minimum dihedral angle is 17-19 deg at every size from n = 2 (13.8 deg at n = 1), the maximum
135 deg.  The worst tetrahedra sit at the central cube's corners, where three blocks meet (at
n = 6: 18.1 deg, centroids at 0.58 R along the diagonals); CORE_SIZE and LAYERS were tuned on
the minimum angle.

Sizes: 6 (n^3 + 6 n^2 layers) tetrahedra, layers = round(LAYERS n) by default; the default n = 6
(4 layers) has 6 480 tetrahedra and 1 215 nodes, next to the thesis' 6 665 (section 4.7).  The
boundary nodes lie on the sphere (to rounding); the volume is that of an inscribed polyhedron,
below 4/3 pi R^3 by 2.8 % at n = 6, 0.72 % at n = 12 (about 1 / n^2).
"""
from __future__ import annotations

import math
from numbers import Integral, Real

import numpy as np

__all__ = ["ball_tetrahedra", "tetra_volumes", "tetra_quality", "boundary_faces", "CORE_SIZE", "LAYERS"]

CORE_SIZE = 0.35    # the central cube's half-side over the radius ...
LAYERS = 2.0 / 3.0  # ... and the layers from it to the sphere per cell along its edge (tuned on the
                    # minimum dihedral angle over n = 2 .. 16: see the module docstring)

def _check_radius(radius) -> float:
    if isinstance(radius, bool) or not isinstance(radius, Real) or not math.isfinite(radius) or radius <= 0:
        raise ValueError(f"radius must be a finite number > 0, got {radius!r}")
    return float(radius)


def _check_cells(n, name: str = "n", minimum: int = 1) -> int:
    if isinstance(n, bool) or not isinstance(n, Integral) or n < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {n!r}")
    if n > 64:
        raise ValueError(f"{name} must be <= 64, got {n}")
    return int(n)


def _cube_to_sphere(d: np.ndarray) -> np.ndarray:
    """The smooth map of the unit cube's surface (max |d_i| = 1) onto the unit sphere."""
    x2, y2, z2 = (d * d).T
    return d * np.sqrt(np.column_stack([1 - y2 / 2 - z2 / 2 + y2 * z2 / 3,
                                        1 - z2 / 2 - x2 / 2 + z2 * x2 / 3,
                                        1 - x2 / 2 - y2 / 2 + x2 * y2 / 3]))


def _kuhn(hexes: np.ndarray) -> np.ndarray:
    """Six tetrahedra per hexahedron around its diagonal from corner 0 to corner 7 (corners
    numbered by bits: 1 = first local axis, 2 = second, 4 = third).  Each face is cut along the
    diagonal from its lowest to its highest corner, so hexahedra whose shared edges point the same
    way cut their shared faces alike (conforming)."""
    tets = []
    for a, b, c in ((1, 2, 4), (1, 4, 2), (2, 1, 4), (2, 4, 1), (4, 1, 2), (4, 2, 1)):
        tets.append(hexes[:, [0, a, a + b, 7]])
    return np.stack(tets, axis=1).reshape(-1, 4)


def _ball_hexes(n: int, m: int):
    """Nodes (as keys) and hexahedra of the cubed ball: the central cube's n^3 cells and six face
    blocks of n x n x m cells.  A central node is its lattice point q in [-n, n]^3 (step 2, so
    that the centre is a node for any n); a shell node is (q on the cube's surface, layer 1..m).

    Every hexahedron's corner 0 is the one nearest the centre and its axes point away from it:
    in the cube away from the coordinate planes, in a block outward and away from the face's
    centre.  Neighbours (also across blocks) therefore orient their shared edges alike, which is
    what the Kuhn cut needs to conform, and the mesh is mirror-symmetric in x, y and z."""
    keys, hexes = {}, []

    def node(q, layer):
        q = tuple(int(v) for v in q)
        key = (q, layer if layer > 0 else 0)
        if key not in keys:
            keys[key] = len(keys)
        return keys[key]

    steps = range(-n, n, 2)                      # lower lattice coordinate of each cell, per axis
    for lo in np.array(np.meshgrid(steps, steps, steps, indexing="ij")).reshape(3, -1).T:
        sign = np.where(lo >= 0, 1, -1)
        start = np.where(lo >= 0, lo, lo + 2)    # the corner nearest the centre
        hexes.append([node(start + 2 * sign * np.array([c & 1, (c >> 1) & 1, (c >> 2) & 1]), 0)
                      for c in range(8)])
    for axis in range(3):
        for side in (-1, 1):
            u, v = [a for a in range(3) if a != axis]
            for lu in steps:
                for lv in steps:
                    su, sv = (1 if lu >= 0 else -1), (1 if lv >= 0 else -1)
                    pu, pv = (lu if lu >= 0 else lu + 2), (lv if lv >= 0 else lv + 2)
                    for layer in range(m):
                        corners = []
                        for c in range(8):
                            q = np.zeros(3, dtype=np.int64)
                            q[axis] = side * n
                            q[u] = pu + 2 * su * (c & 1)
                            q[v] = pv + 2 * sv * ((c >> 1) & 1)
                            corners.append(node(q, layer + ((c >> 2) & 1)))
                        hexes.append(corners)
    return keys, np.array(hexes, dtype=np.int64)


def ball_tetrahedra(radius=1.0, n: int = 6, layers: int | None = None, *, core_size: float = CORE_SIZE):
    """(points (N, 3) float64, tetra (M, 4) int64) of the solid ball centred at the origin.

    n cells along the central cube's edge and along each face block's sides, `layers` cells
    from the central cube to the sphere (default: round(LAYERS * n), at least 1):
    6 (n^3 + 6 n^2 layers) positively oriented tetrahedra (a consistent, conforming cut),
    boundary nodes on the sphere, mirror-symmetric in x, y and z.  core_size: the central
    cube's half-side over the radius (0 < core_size < 1/sqrt(3) keeps the layers unfolded)."""
    radius, n = _check_radius(radius), _check_cells(n)
    layers = max(1, round(LAYERS * n)) if layers is None else _check_cells(layers, "layers", 1)
    if not 0.0 < core_size < 1.0 / math.sqrt(3.0):
        raise ValueError(f"need 0 < core_size < 1/sqrt(3), got {core_size!r}")
    keys, hexes = _ball_hexes(n, layers)
    q = np.array([k[0] for k in keys], dtype=np.float64) / n          # in [-1, 1]^3
    t = (np.array([k[1] for k in keys], dtype=np.float64) / layers)[:, None]
    d = q / np.abs(q).max(axis=1, keepdims=True).clip(1e-300)         # on the cube's surface (shell nodes)
    shell = (t > 0).ravel()
    points = radius * core_size * q
    points[shell] = radius * ((1.0 - t[shell]) * core_size * d[shell] + t[shell] * _cube_to_sphere(d[shell]))
    surface = (t == 1.0).ravel()
    points[surface] *= radius / np.linalg.norm(points[surface], axis=1, keepdims=True)
    tetra = _kuhn(hexes)
    flip = tetra_volumes(points, tetra) < 0.0                # orientation fixed by the sign, not by hand
    tetra[flip] = tetra[flip][:, [0, 2, 1, 3]]
    return points, tetra.astype(np.int64)


def tetra_volumes(points, tetra) -> np.ndarray:
    """Signed volumes det[x1 - x0, x2 - x0, x3 - x0] / 6 (positive: right-handed)."""
    p = np.asarray(points, dtype=np.float64)[np.asarray(tetra)]
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0


_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
_OPPOSITE = ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1))    # the other two corners of each edge: the
                                                                 # edge's two faces are the faces opposite them


def _dihedral_angles(p: np.ndarray) -> np.ndarray:
    """(M, 6) interior dihedral angles in degrees at the six edges of each tetrahedron."""
    # outward face normals n_l of the face opposite corner l; the angle at edge (a, b) is
    # pi - angle(n_c, n_d), with c, d the two other corners
    faces = ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))
    normals = []
    for f0, f1, f2 in faces:
        nrm = np.cross(p[:, f1] - p[:, f0], p[:, f2] - p[:, f0])
        normals.append(nrm / np.linalg.norm(nrm, axis=1, keepdims=True))
    out = np.empty((len(p), 6))
    for e, (c, d) in enumerate(_OPPOSITE):
        cosang = np.clip(np.einsum("ij,ij->i", normals[c], normals[d]), -1.0, 1.0)
        out[:, e] = 180.0 - np.degrees(np.arccos(cosang))
    return out


def tetra_quality(points, tetra) -> dict:
    """Volumes and angles of a tetrahedral mesh: min/max volume, total volume, min/max dihedral
    angle (degrees) and the minimum of the normalised radius ratio 3 r_in / r_circ (1: regular)."""
    p = np.asarray(points, dtype=np.float64)[np.asarray(tetra)]
    vol = tetra_volumes(points, tetra)
    ang = _dihedral_angles(p)
    return {"n_tetra": int(len(tetra)), "n_nodes": int(len(np.unique(tetra))),
            "volume": float(vol.sum()), "min_volume": float(vol.min()), "max_volume": float(vol.max()),
            "min_dihedral_deg": float(ang.min()), "max_dihedral_deg": float(ang.max())}


def boundary_faces(tetra) -> np.ndarray:
    """(F, 3) faces used by exactly one tetrahedron, wound outward (right-hand normal out)."""
    tetra = np.asarray(tetra, dtype=np.int64)
    # the face opposite corner l, wound so that its normal points away from corner l
    faces = np.concatenate([tetra[:, [1, 2, 3]], tetra[:, [0, 3, 2]], tetra[:, [0, 1, 3]], tetra[:, [0, 2, 1]]])
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inverse.reshape(-1)] == 1]
