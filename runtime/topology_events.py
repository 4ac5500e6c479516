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

__all__ = ["TopologyEvents"]


def _event_step(event, solver) -> int:
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
        """Apply every event to the rest mesh in order: refuse what would fail during the run."""
        for i in np.argsort(self.steps, kind="stable"):
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
            if pairs is not None and self.steps[j] >= self.steps[i] and j != i and self.events[j].kind == "cut":
                mapped = gone.new_ids[pairs]
                self.pairs[j] = mapped[(mapped >= 0).all(axis=1)]

    def due(self, step: int) -> list:
        return [i for i, s in enumerate(self.steps) if s == step]

    def apply(self, model, step: int, t: float, u: np.ndarray, v: np.ndarray):
        """Apply the events due after `step`: (model, u, v) afterwards, or None when none is due."""
        due = self.due(step)
        if not due:
            return None
        for i in due:
            model, u, v = self._apply_one(model, i, step, t, u, v)
        return model, u, v

    def _apply_one(self, model, i, step, t, u, v):
        e = self.events[i]
        start = time.perf_counter()
        dpn = model.dofs_per_node
        if e.kind == "cut":
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
        done = time.perf_counter()
        self.records.append({"step": step, "time": t, "kind": e.kind, "name": _label(e, i), **counts,
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
