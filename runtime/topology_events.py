"""The scene's [[cut]] and [[remove]] events during a run (runtime.topology, runtime.cutting).

    events = TopologyEvents(model, scene.topology)     # checked on the rest mesh at setup
    new_model, u, v, record = events.apply(model, step, u, v)   # after a step; None when nothing is due

Cuts are resolved at setup into the cell pairs whose shared face opens (cell ids survive cuts;
removals renumber them and the pairs follow), and every event is rehearsed on the rest mesh in
order, so a cut that opens nothing or a removal that selects no cell is refused before step 1.
The state carries over exactly: a new node takes its parent's displacement and velocity (so the
momentum is unchanged), nodes a removal leaves alone are set at rest and pinned.
"""
from __future__ import annotations

import time

import numpy as np

from .cutting import check_model, removed, separated
from .errors import TensormassError
from .regions import box_tolerance
from .topology import TopologyError, box_cells, check_topology, incidence, plane_pairs, removal, separate

__all__ = ["TopologyEvents", "tearing_pairs"]


def _event_step(event, solver) -> int | None:
    """The step after which a timed event happens; None for a tearing rule (checked every `every` steps)."""
    if event.criterion is not None:
        return None
    if event.step is not None:
        return int(event.step)
    import math
    return max(1, math.ceil(event.time / float(solver.dt) - 1e-9))


def _label(event, index) -> str:
    return event.name or f"{event.kind}[{index}]"


class TopologyEvents:
    """The events of a scene, their cell selections, and the record of what each changed."""

    def __init__(self, model, events, check: bool = True):
        self.events = list(events)
        self.steps = [_event_step(e, model.solver) for e in self.events]
        self.tol = box_tolerance(model.mesh.points)
        self.records: list = []
        if not self.events:
            return
        try:
            check_model(model)
        except TopologyError as exc:
            raise TopologyError(f"{self.events[0].kind}: {exc}") from None
        self.pairs = [None] * len(self.events)
        self._rehearse(model.mesh)

    def _select(self, mesh, i):
        """Cut: the cell pairs on the rest mesh (ids of the mesh at that point); remove: cell ids."""
        e = self.events[i]
        key = f"{e.kind}[{i}]" if e.name is None else f"{e.kind} {e.name!r}"
        try:
            if e.kind == "cut":
                pairs = plane_pairs(mesh, e.point, e.normal, e.box, tol=self.tol)
                if not len(pairs):
                    raise TopologyError("the plane meets no interior face" + (" inside the box" if e.box else ""))
                return pairs
            cells = box_cells(mesh, e.box, self.tol) if e.box is not None else np.arange(mesh.n_cells)
            if e.region is not None:
                from .regions import region_cells
                cells = np.intersect1d(cells, region_cells(mesh, e.region, f"{key}.region"))
            if not cells.size:
                raise TopologyError("no cell has its centroid inside the box" if e.region is None
                                    else "no cell of the region inside the box")
            return cells
        except TensormassError as exc:
            raise TopologyError(f"{key}: {exc}") from None

    def _rehearse(self, mesh) -> None:
        """Apply every timed event to the rest mesh in order: refuse what would fail during the run
        (a tearing rule only needs its box to hold cells)."""
        for i, e in enumerate(self.events):
            if e.criterion is not None and e.box is not None and not box_cells(mesh, e.box, self.tol).size:
                raise TopologyError(f"cut[{i}].box: no cell has its centroid inside it")
        timed = [i for i, s in enumerate(self.steps) if s is not None]
        for i in sorted(timed, key=lambda i: self.steps[i]):
            e = self.events[i]
            selection = self._select(mesh, i)
            key = f"{e.kind}[{i}]" if e.name is None else f"{e.kind} {e.name!r}"
            try:
                if e.kind == "cut":
                    self.pairs[i] = selection
                    mesh = separate(mesh, _still_joined(mesh, selection)).apply(mesh)
                else:
                    gone = removal(mesh, selection)
                    self._renumber(i, gone)
                    mesh = gone.apply(mesh)
            except TopologyError as exc:
                message = str(exc).split(": ", 1)[-1] if str(exc).startswith(("cut:", "remove:")) else str(exc)
                raise TopologyError(f"{key}: {message}") from None
        check_topology(mesh)

    def _renumber(self, i, gone) -> None:
        """Cell pairs of later cuts follow a removal (pairs losing a cell are dropped)."""
        for j, pairs in enumerate(self.pairs):
            if pairs is not None and j != i and self.events[j].kind == "cut" and self.steps[j] >= self.steps[i]:
                mapped = gone.new_ids[pairs]
                self.pairs[j] = mapped[(mapped >= 0).all(axis=1)]

    def due(self, step: int) -> list:
        return [i for i, (s, e) in enumerate(zip(self.steps, self.events))
                if s == step or (s is None and step % e.every == 0)]

    def apply(self, model, step: int, t: float, u: np.ndarray, v: np.ndarray):
        """Apply the events due after `step`: (model, u, v) afterwards, or None when nothing changed
        (none due, or a tearing rule that found nothing to open)."""
        due = self.due(step)
        before = len(self.records)
        for i in due:
            model, u, v = self._apply_one(model, i, step, t, u, v)
        return None if len(self.records) == before else (model, u, v)

    def _apply_one(self, model, i, step, t, u, v):
        e = self.events[i]
        start = time.perf_counter()
        dpn = model.dofs_per_node
        if e.criterion is not None:
            pairs = tearing_pairs(model, u, e.threshold, e.box, self.tol)
            try:
                split = separate(model.mesh, pairs, incidence(model.mesh)) if len(pairs) else None
            except TopologyError:            # faces inside the body with nothing to open yet
                split = None
            if split is None:
                return model, u, v
        if e.kind == "cut":
            if e.criterion is None:
                pairs = _still_joined(model.mesh, self.pairs[i])
                split = separate(model.mesh, pairs, incidence(model.mesh))
            topo = time.perf_counter()
            new = separated(model, split)
            U, V = u.reshape(-1, dpn), v.reshape(-1, dpn)
            u = np.vstack([U, U[split.parents]]).ravel()
            v = np.vstack([V, V[split.parents]]).ravel()
            counts = {"faces": split.faces, "nodes_added": split.n_new, "cells_changed": int(split.changed_cells.size)}
        else:
            cells = self._select(model.mesh, i)
            gone = removal(model.mesh, cells, incidence(model.mesh))
            self._renumber(i, gone)
            topo = time.perf_counter()
            new = removed(model, gone)
            u, v = u.copy(), v.copy()
            for x in (u, v):
                x.reshape(-1, dpn)[gone.orphans] = 0.0
            counts = {"cells_removed": int(gone.removed.size), "nodes_orphaned": int(gone.orphans.size)}
        if model.solver.kind == "static":
            _refuse_floating(new, _label(e, i), step)
        done = time.perf_counter()
        rule = {} if e.criterion is None else {"criterion": e.criterion, "threshold": e.threshold}
        self.records.append({"step": step, "time": t, "kind": e.kind, "name": _label(e, i), **rule, **counts,
                             "n_points": new.n_points, "n_cells": new.mesh.n_cells,
                             "seconds": {"topology": topo - start, "model": done - topo}})
        return new, u, v

    def summary(self) -> list:
        return list(self.records)


def _still_joined(mesh, pairs) -> np.ndarray:
    """The pairs that still share a face (an earlier cut may have opened some of them already)."""
    from .topology import _face_rows, _shared_faces
    if not len(pairs):
        return pairs
    keys, owner = _face_rows(mesh, np.unique(pairs))
    shared = _shared_faces(keys, owner)
    if not len(shared):
        return pairs[:0]
    code = shared[:, 0] * mesh.n_cells + shared[:, 1]
    p = np.sort(pairs, axis=1)
    return pairs[np.isin(p[:, 0] * mesh.n_cells + p[:, 1], code)]


def _mean_gradients(model, u) -> np.ndarray:
    """(n_cells, dim, dim) volume-averaged deformation gradient of every cell (I where no material)."""
    from .adapt import _geometry
    dim = model.dim
    F = np.broadcast_to(np.eye(dim), (model.mesh.n_cells, dim, dim)).copy()
    for part in model.parts:
        if not part.n_active:
            continue
        v, G = _geometry(part)
        Gbar = np.einsum("eq,eqib->eib", v, G, optimize=True) / v.sum(axis=1)[:, None, None]
        ue = model.element_displacements(part, u)[:, :, :dim]
        F[part.cell_ids_active] = np.eye(dim) + np.einsum("eia,eib->eab", ue, Gbar, optimize=True)
    return F


def _face_normals(points, keys) -> np.ndarray:
    """Unit normals (m, dim) of faces given by sorted corner keys (m, 4), -1 padded (3D), or edges (2D)."""
    if points.shape[1] == 2:
        t = points[keys[:, 1]] - points[keys[:, 0]]
        n = np.stack([t[:, 1], -t[:, 0]], axis=1)
    else:
        quad = keys[:, 3] >= 0
        a, b, c = points[keys[:, 0]], points[keys[:, 1]], points[keys[:, 2]]
        n = np.cross(b - a, c - a)
        # a quad's corners sorted by id are not in cyclic order: its diagonals' cross product
        if quad.any():
            q = keys[quad]
            p = points[q]
            d = np.stack([np.cross(p[:, i] - p[:, j], p[:, k] - p[:, m])
                          for i, j, k, m in ((0, 1, 2, 3), (0, 2, 1, 3), (0, 3, 1, 2))])
            n[quad] = d[np.argmax(np.linalg.norm(d, axis=2), axis=0), np.arange(len(q))]
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def tearing_pairs(model, u, threshold: float, box=None, tol: float = 0.0) -> np.ndarray:
    """Cell pairs whose shared face the body stretches across by more than 1 + threshold: |F n| with n the
    face's rest normal and F the mean of the two cells' volume-averaged deformation gradients."""
    from .topology import _face_rows, _shared_faces
    mesh = model.mesh
    F = _mean_gradients(model, u)
    stretch = np.sqrt(np.linalg.eigvalsh(np.einsum("eji,ejk->eik", F, F))[:, -1])
    hot = np.flatnonzero(stretch >= 1.0 + threshold)
    if box is not None and hot.size:
        hot = np.intersect1d(hot, box_cells(mesh, box, tol))
    if not hot.size:
        return np.zeros((0, 2), np.int64)
    inc = incidence(mesh)
    from .topology import _cell_nodes
    nodes = np.unique(np.concatenate(_cell_nodes(mesh, hot)))
    _, around, _ = inc.of(nodes)
    keys, owner = _face_rows(mesh, np.unique(around))
    order = np.lexsort(keys.T[::-1])
    k, o = keys[order], owner[order]
    same = np.flatnonzero(np.all(k[1:] == k[:-1], axis=1))
    pairs, faces = np.stack([o[same], o[same + 1]], axis=1), k[same]
    is_hot = np.zeros(mesh.n_cells, bool)
    is_hot[hot] = True
    keep = is_hot[pairs].any(axis=1)
    pairs, faces = pairs[keep], faces[keep]
    if not len(pairs):
        return pairs
    n = _face_normals(mesh.points, faces)
    Fm = (F[pairs[:, 0]] + F[pairs[:, 1]]) / 2
    across = np.linalg.norm(np.einsum("eij,ej->ei", Fm, n), axis=1)
    return pairs[across >= 1.0 + threshold]


def pieces(mesh) -> tuple:
    """(count, piece of every cell): the connected pieces of a mesh, cells joined by shared nodes."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    rows, cols, start = [], [], 0
    for b in mesh.blocks:
        n, k = b.cells.shape
        rows.append(np.repeat(start + np.arange(n), k))
        cols.append(b.cells.ravel())
        start += n
    A = sp.csr_matrix((np.ones(sum(r.size for r in rows)), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(start, mesh.n_points))
    return connected_components(A @ A.T, directed=False)


def _refuse_floating(model, label, step) -> None:
    """A static run has no equilibrium for a piece that no [[fixed]] entry holds: say so."""
    count, piece = pieces(model.mesh)
    if count == 1:
        return
    held = np.zeros(model.n_points, dtype=bool)
    held[np.unique(model.fixed_dofs // model.dofs_per_node)] = True
    cells = np.concatenate([b.cells for b in model.mesh.blocks]) if len(model.mesh.blocks) == 1 else None
    for p in range(count):
        ids = np.flatnonzero(piece == p)
        nodes = np.concatenate([c.ravel() for c in _cells_of(model.mesh, ids)]) if cells is None else cells[ids].ravel()
        if not held[nodes].any():
            raise TopologyError(f"{label} after step {step} leaves a piece of {ids.size} cell(s) that nothing holds: "
                                "a static run has no equilibrium for it; use a dynamic solver.kind (the piece falls "
                                "or floats free) or a [[fixed]] entry on it")


def _cells_of(mesh, ids):
    from .topology import _cell_nodes
    return _cell_nodes(mesh, ids)
