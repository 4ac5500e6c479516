"""Consistent loads: body forces and tractions integrated with the element's own shape functions.

    f = body_force(points, {"tetra10": cells}, density, g)       # f_a = sum_q w_q N_a rho g det J
    f = traction(points, {"triangle6": faces}, t)                # f_a = sum_q w_q N_a t |dA|
    faces = boundary_faces_by_type(mesh)                         # {face type: (n, k) node ids}
    faces = faces_in_box(mesh, box, tol)                         # those whose nodes all lie in the box

N, dN/dxi, points and weights come from generated/shape_tables.json (generator/shape_tables.py,
written by `tensormass generate`): a rule exact for N_a N_b det J of every isoparametric element,
so det J is the true one (curved quadratic elements included) and the loads are exact for
constant densities, gravities and tractions on flat faces.  Face arrays are {face type: (n, k)}
in the face type's node order (corners first, outward: the element table's `Face`), so faces
selected any other way (mesh regions) plug in the same way as boxes.  numpy only at run time.
"""
from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ... import elements as _types
from ... import generated as _generated
from ..base.errors import TensormassError
from ..mesh.regions import region_faces

__all__ = ["ShapeTable", "shape_table", "body_force", "volume_shares", "traction", "face_shares",
           "face_jacobians", "normal_areas", "boundary_faces_by_type", "faces_in_box"]

TABLE_FILE = "shape_tables.json"


@dataclass(frozen=True)
class ShapeTable:
    """One element or face type at the points of its rule: N (q, k), dN (q, k, r), weights (q,)."""
    name: str
    dim: int
    points: np.ndarray
    weights: np.ndarray
    N: np.ndarray
    dN: np.ndarray
    rule: str
    degree: int


@functools.cache
def _all_tables() -> dict:
    path = Path(_generated.__file__).resolve().parent / TABLE_FILE
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise TensormassError(f"the shape-function tables {path} cannot be read ({exc}); "
                              "regenerate them with: tensormass generate --out generated") from None
    return data


@functools.cache
def shape_table(name: str) -> ShapeTable:
    """The table of an element type or face type (line, line3, triangle, triangle6, quad, ...)."""
    types = _all_tables()["types"]
    if name not in types:
        raise TensormassError(f"no shape-function table for {name!r} (known: {', '.join(sorted(types))}); "
                              "regenerate generated/shape_tables.json with: tensormass generate")
    t = types[name]
    return ShapeTable(name, int(t["dim"]), np.array(t["points"], float), np.array(t["weights"], float),
                      np.array(t["N"], float), np.array(t["dN"], float).reshape(len(t["weights"]), t["nodes"], t["dim"]),
                      t["rule"], int(t["degree"]))


def _det(J):
    if J.shape[-1] == 1:
        return J[..., 0, 0]
    if J.shape[-1] == 2:
        return J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    return np.linalg.det(J)


def jacobians(X: np.ndarray, table: ShapeTable) -> np.ndarray:
    """(n, q, d, r) dx/dxi at the rule's points of cells with node coordinates X (n, k, d)."""
    return np.einsum("nkd,qkr->nqdr", X, table.dN)


def measure_weights(X: np.ndarray, table: ShapeTable) -> np.ndarray:
    """(n, q) w_q |det J| (cells of the space dimension) or w_q sqrt(det J^T J) (faces, edges)."""
    J = jacobians(X, table)
    d, r = J.shape[-2:]
    if d == r:
        dets = _det(J)
    else:
        G = np.einsum("nqdr,nqds->nqrs", J, J)
        dets = np.sqrt(np.maximum(_det(G), 0.0))
    return dets * table.weights


def has_table(name: str, space_dim: int | None = None) -> bool:
    """Whether the generated tables integrate cells of this type in a space of space_dim.

    Registered custom elements have no table, and a lower-dimensional cell (a bar in 3D) has a
    cross-section only its kernel knows: both use the kernel's measure instead."""
    types = _all_tables()["types"]
    return name in types and (space_dim is None or int(types[name]["dim"]) == space_dim)


def volume_shares(points: np.ndarray, cell_type: str, cells: np.ndarray, weight=None, measure=None) -> np.ndarray:
    """(n, k) integral of N_a (times a per-cell weight, e.g. the density) over each cell.

    measure: (n,) cell measures (from the kernel's constants) for a type without a shape table
    (an element registered with a hand-written kernel): split equally over its nodes."""
    cells = np.asarray(cells, dtype=np.int64)
    if cells.size == 0:
        return np.zeros(cells.shape)
    if measure is not None and not has_table(cell_type, points.shape[1]):
        shares = np.repeat(np.asarray(measure, float).reshape(-1, 1) / cells.shape[1], cells.shape[1], axis=1)
        return shares if weight is None else shares * np.asarray(weight, float).reshape(-1, 1)
    table = shape_table(cell_type)
    dV = measure_weights(points[cells], table)                   # (n, q)
    shares = dV @ table.N                                        # (n, k)
    return shares if weight is None else shares * np.asarray(weight, float).reshape(-1, 1)


def body_force(points: np.ndarray, cells: dict, density: dict, g) -> np.ndarray:
    """Nodal forces (n_points, d) of the body force rho g: f_a = sum_q w_q N_a rho g det J.

    cells {cell type: (n, k)}, density {cell type: (n,) or scalar}, g the acceleration (d,)."""
    f = np.zeros(points.shape)
    g = np.asarray(g, float).reshape(-1)[:points.shape[1]]
    for name, c in cells.items():
        c = np.asarray(c, dtype=np.int64)
        rho = np.broadcast_to(np.asarray(density[name], float), (len(c),))
        shares = volume_shares(points, name, c, rho)
        np.add.at(f, c, shares[:, :, None] * g)
    return f


def face_shares(points: np.ndarray, face_type: str, faces: np.ndarray) -> np.ndarray:
    """(n, k) integral of N_a |dA| over each face (|dA| from the face Jacobian)."""
    return volume_shares(points, face_type, faces)


def traction(points: np.ndarray, faces: dict, t) -> np.ndarray:
    """Nodal forces (n_points, d) of a traction t (force per unit area): f_a = sum_q w_q N_a t |dA|."""
    f = np.zeros(points.shape)
    t = np.asarray(t, float).reshape(-1)[:points.shape[1]]
    for name, c in faces.items():
        c = np.asarray(c, dtype=np.int64)
        if c.size:
            np.add.at(f, c, face_shares(points, name, c)[:, :, None] * t)
    return f


def face_jacobians(x: np.ndarray, table: ShapeTable) -> np.ndarray:
    """(n, q, d, r) tangents of faces with node coordinates x (n, k, d): r = d - 1."""
    return jacobians(x, table)


def normal_areas(x: np.ndarray, table: ShapeTable) -> np.ndarray:
    """(n, q, d) outward normal times the area element at the rule's points (not weighted).

    3D faces: t1 x t2; 2D edges (the cell on the left of the edge direction t): (t_y, -t_x)."""
    J = face_jacobians(x, table)
    if J.shape[-2] == 3:
        return np.cross(J[..., 0], J[..., 1])
    t = J[..., 0]
    return np.stack([t[..., 1], -t[..., 0]], axis=-1)


# --------------------------------------------------------------------------- boundary faces


def boundary_faces_by_type(mesh) -> dict:
    """{face type: (n, k) node ids} of the body's boundary faces, outward (runtime.mesh.regions.region_faces)."""
    return region_faces(mesh)


def faces_in_box(mesh, box, tol: float) -> dict:
    """The boundary faces whose nodes all lie in the box (closed, +- tol): runtime.mesh.regions.region_faces."""
    return region_faces(mesh, box=box, tol=tol)


def n_faces(faces: dict) -> int:
    return sum(len(f) for f in faces.values())
