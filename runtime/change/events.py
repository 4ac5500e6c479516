"""The scene's [[cut]] and [[remove]] events during a run (runtime.mesh.topology, runtime.change.cutting).

    events = TopologyEvents(model, scene.topology)     # checked on the rest mesh at setup
    new_model, u, v, record = events.apply(model, step, u, v)   # after a step; None when nothing is due

Cuts are resolved at setup into the cell pairs whose shared face opens (cell ids survive cuts;
removals renumber them and the pairs follow), and every event is rehearsed on the rest mesh in
order, so a cut that opens nothing or a removal that selects no cell is refused before step 1.
The state carries over exactly: a new node takes its parent's displacement and velocity (so the
momentum is unchanged), nodes a removal leaves alone are set at rest and pinned.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .cutting import check_model, descend, removed, separated
from .adapt import mean_deformation_gradients
from ..assembly.pattern import SparsePattern
from ..base import integrator_kinds
from ..mesh.regions import box_tolerance, region_cell_masks
from ..mesh.topology import (TopologyError, nodes_of_cells, face_rows, shared_faces, box_cells, check_topology,
    incidence, plane_pairs, refine_hexahedra, removal, separate)

__all__ = ["TopologyEvents", "tearing_pairs", "blade_fractions", "pieces"]


def _step_at(time: float, solver) -> int:
    """The step after which something at `time` happens: the first whose end time reaches it."""
    return max(1, math.ceil(time / float(solver.dt) - 1e-9))


def _label(event, index) -> str:
    return event.name or f"{event.kind}[{index}]"


def _key(event, index) -> str:
    return f"{event.kind}[{index}]" if event.name is None else f"{event.kind} {event.name!r}"


@dataclass
class _Action:
    """One thing to do after a step: event `event`'s cut of `pairs` (cell pairs, current ids) or its
    removal (cells selected when applied); step None: a tearing rule, checked every `every` steps."""
    step: int | None
    event: int
    pairs: np.ndarray | None = None
    partial: bool = False         # a blade's step: its faces may open nothing yet (they wait)


def blade_fractions(centres: np.ndarray, box, sweep) -> np.ndarray:
    """For each point, the smallest fraction s in [0, 1] of the sweep at which the box moved by s x sweep
    has covered it at some moment (inf: never): per axis, lo <= c - sigma d <= hi bounds sigma."""
    lo, hi = (np.asarray(c, float) for c in box)
    d = np.asarray(sweep, float)
    start = np.zeros(len(centres))
    stop = np.ones(len(centres))
    for i in range(centres.shape[1]):
        c = centres[:, i]
        if d[i] == 0.0:
            out = (c < lo[i]) | (c > hi[i])
            stop[out] = -np.inf
            continue
        a, b = (c - hi[i]) / d[i], (c - lo[i]) / d[i]
        start = np.maximum(start, np.minimum(a, b))
        stop = np.minimum(stop, np.maximum(a, b))
    return np.where(start <= stop, start, np.inf)


class TopologyEvents:
    """The events of a scene, as actions after given steps, and the record of what each changed."""

    def __init__(self, model, events):
        self.events = list(events)
        self.tol = box_tolerance(model.mesh.points)
        self.records: list = []
        self.last_count = 0
        self.actions: list = []
        if not self.events:
            return
        try:
            check_model(model)
        except TopologyError as exc:
            raise TopologyError(f"{self.events[0].kind}: {exc}") from None
        self._plan(model)
        self._rehearse(model.mesh, {name: (p.cell, p.nodes) for name, p in model.probes.items()})
        if any(e.kind == "cut" for e in self.events):
            SparsePattern.warm_up_growth()

    # -- setup ----------------------------------------------------------------------------------
    def _plan(self, model) -> None:
        mesh, solver = model.mesh, model.solver
        for i, e in enumerate(self.events):
            if e.kind == "refine" and not integrator_kinds.get(solver.kind).hanging_nodes:
                raise TopologyError(f"{_key(e, i)}: splitting hexahedra leaves hanging nodes, which need "
                                    f"solver.kind implicit_euler, backward_euler or static (not {solver.kind!r})")
            if e.criterion is not None:
                if e.box is not None and not box_cells(mesh, e.box, self.tol).size:
                    raise TopologyError(f"{_key(e, i)}.box: no cell has its centroid inside it")
                self.actions.append(_Action(None, i))
            elif e.kind in ("remove", "refine"):
                self.actions.append(_Action(_step(e, solver), i))
            elif e.sweep is None:
                self.actions.append(_Action(_step(e, solver), i, self._plane_pairs(mesh, i, e.box)))
            else:
                self.actions.extend(self._blade(mesh, solver, i))
        # in time order; at one step, the file's order (cuts before removals, as the scene lists them)
        self.actions.sort(key=lambda a: (-1 if a.step is None else a.step))

    def _plane_pairs(self, mesh, i, box):
        e = self.events[i]
        pairs = plane_pairs(mesh, e.point, e.normal, box, tol=self.tol)
        if not len(pairs):
            raise TopologyError(f"{_key(e, i)}: the plane meets no interior face" + (" inside the box" if box else ""))
        return pairs

    def _blade(self, mesh, solver, i) -> list:
        """A blade path: the box moves by `sweep` from `time` over `duration`; after every step of that
        span, the faces it has reached so far (their centroids) open."""
        e = self.events[i]
        lo, hi = (np.asarray(c, float) for c in e.box)
        moved = lo + np.asarray(e.sweep), hi + np.asarray(e.sweep)
        hull = (np.minimum(lo, moved[0]), np.maximum(hi, moved[1]))
        pairs = self._plane_pairs(mesh, i, hull)
        centres = np.array([mesh.points[np.intersect1d(a, b)].mean(axis=0) for a, b in
                            zip(nodes_of_cells(mesh, pairs[:, 0]), nodes_of_cells(mesh, pairs[:, 1]))])
        s = blade_fractions(centres, e.box, e.sweep)
        pairs, s = pairs[np.isfinite(s)], s[np.isfinite(s)]
        first, last = _step_at(e.time, solver), _step_at(e.time + e.duration, solver)
        actions = []
        for k in range(first, last + 1):
            # the blade's position after step k, as a fraction of its path
            reach = min(1.0, max(0.0, (k * float(solver.dt) - e.time) / e.duration)) if k < last else 1.0
            now = pairs[s <= reach + 1e-12]
            if len(now) and (not actions or len(now) > len(actions[-1].pairs)):
                actions.append(_Action(k, i, now, partial=True))
        if not actions:
            raise TopologyError(f"{_key(e, i)}: the blade's path meets no interior face of the plane")
        return actions

    def _select_cells(self, mesh, i) -> np.ndarray:
        """The cells a removal takes out (rest centroids in its box, in its region)."""
        e = self.events[i]
        cells = box_cells(mesh, e.box, self.tol) if e.box is not None else np.arange(mesh.n_cells)
        if e.region is not None:
            masks = region_cell_masks(mesh, e.region, f"{_key(e, i)}.region")
            cells = np.intersect1d(cells, np.flatnonzero(np.concatenate(masks)))
        if not cells.size:
            raise TopologyError(f"{_key(e, i)}: " + ("no cell has its centroid inside the box" if e.region is None
                                                     else "no cell of the region inside the box"))
        return cells

    def _rehearse(self, mesh, probes=None) -> None:
        """Apply the timed actions to the rest mesh in order: refuse what would fail during the run,
        and a removal that takes away what a probe reads (it would report zeros from then on)."""
        probes = dict(probes or {})
        opened = set()
        for n, action in enumerate(self.actions):
            if action.step is None:
                continue
            e = self.events[action.event]
            try:
                if e.kind == "cut":
                    split = self._split(mesh, action)
                    if split is not None:
                        opened.add(action.event)
                        mesh = split.apply(mesh)
                elif e.kind == "refine":
                    mesh = refine_hexahedra(mesh, self._select_cells(mesh, action.event)).mesh
                else:
                    gone = removal(mesh, self._select_cells(mesh, action.event))
                    self._renumber(n, gone)
                    probes = _probes_after(probes, gone, _selection(e))
                    mesh = gone.apply(mesh)
            except TopologyError as exc:
                message = str(exc).split(": ", 1)[-1] if str(exc).startswith(("cut:", "remove:")) else str(exc)
                raise TopologyError(f"{_key(e, action.event)}: {message}") from None
        for i, e in enumerate(self.events):
            if e.kind == "cut" and e.sweep is not None and i not in opened:
                raise TopologyError(f"{_key(e, i)}: the faces the blade reaches separate nothing (every node of "
                                    "them stays on the cut's front); make the path reach the surface")
        check_topology(mesh)

    def _split(self, mesh, action, inc=None):
        """The Split of a cut action (None: a blade step whose faces open nothing yet)."""
        pairs = _still_joined(mesh, action.pairs)
        if action.partial and not len(pairs):
            return None
        try:
            return separate(mesh, pairs, inc)
        except TopologyError:
            if action.partial:
                return None
            raise

    def _renumber(self, n, gone) -> None:
        """Cell pairs of the later cut actions follow a removal (pairs losing a cell are dropped)."""
        for action in self.actions[n + 1:]:
            if action.pairs is not None:
                mapped = gone.new_ids[action.pairs]
                action.pairs = mapped[(mapped >= 0).all(axis=1)]

    # -- during the run ---------------------------------------------------------------------------
    def due(self, step: int) -> list:
        return [n for n, a in enumerate(self.actions)
                if a.step == step or (a.step is None and step % self.events[a.event].every == 0)]

    def apply(self, model, step: int, t: float, u: np.ndarray, v: np.ndarray):
        """Apply the actions due after `step`: (model, u, v) afterwards, or None when nothing changed
        (none due, a tearing rule that found nothing to open, a blade whose faces wait)."""
        before = len(self.records)
        for n in self.due(step):
            model, u, v = self._apply_one(model, n, step, t, u, v)
        self.last_count = len(self.records) - before          # records of this call
        return None if self.last_count == 0 else (model, u, v)

    def _apply_one(self, model, n, step, t, u, v):
        action = self.actions[n]
        i, e = action.event, self.events[action.event]
        start = time.perf_counter()
        dpn = model.dofs_per_node
        if e.kind == "cut":
            inc = incidence(model.mesh)
            if e.criterion is not None:
                pairs = tearing_pairs(model, u, e.threshold, e.box, self.tol)
                split = self._split(model.mesh, _Action(step, i, pairs, partial=True), inc) if len(pairs) else None
            else:
                split = self._split(model.mesh, action, inc)
            if split is None:
                return model, u, v
            topo = time.perf_counter()
            new = separated(model, split)
            U, V = u.reshape(-1, dpn), v.reshape(-1, dpn)
            u = np.vstack([U, U[split.parents]]).ravel()
            v = np.vstack([V, V[split.parents]]).ravel()
            counts = {"faces": split.faces, "nodes_added": split.n_new, "cells_changed": int(split.changed_cells.size)}
        elif e.kind == "refine":
            refinement = refine_hexahedra(model.mesh, self._select_cells(model.mesh, i))
            topo = time.perf_counter()
            # a refinement changes constants, masses and the pattern of its cells: the model is built
            # anew on the refined mesh (check_mesh would refuse its hanging nodes: runtime.physics.hanging)
            new = model.rebuilt(refinement.mesh, check=False)
            check_topology(new.mesh)
            descend(model, new, refinement.cell_parent)
            u = refinement.interpolate(u.reshape(-1, dpn), model.n_points).ravel()
            v = refinement.interpolate(v.reshape(-1, dpn), model.n_points).ravel()
            counts = {"cells_refined": int(refinement.refined.size), "nodes_added": len(refinement.parents),
                      "hanging_nodes": 0 if new.hanging is None else int(new.hanging.slaves.size)}
        else:
            gone = removal(model.mesh, self._select_cells(model.mesh, i), incidence(model.mesh))
            self._renumber(n, gone)
            topo = time.perf_counter()
            new = removed(model, gone)
            u, v = u.copy(), v.copy()
            for x in (u, v):
                x.reshape(-1, dpn)[gone.orphans] = 0.0
            counts = {"cells_removed": int(gone.removed.size), "nodes_orphaned": int(gone.orphans.size)}
        if not integrator_kinds.get(model.solver.kind).dynamic:
            _refuse_floating(new, _label(e, i), step)
        done = time.perf_counter()
        rule = {} if e.criterion is None else {"criterion": e.criterion, "threshold": e.threshold}
        self.records.append({"step": step, "time": t, "kind": e.kind, "name": _label(e, i), **rule, **counts,
                             "n_points": new.n_points, "n_cells": new.mesh.n_cells,
                             "seconds": {"topology": topo - start, "model": done - topo}})
        return new, u, v

    def summary(self) -> list:
        return list(self.records)


def _selection(event) -> str:
    """What selects a removal's cells, as its messages name it: "box", "region 'tumour'" or both."""
    region = None if event.region is None else f"region {event.region!r}"
    if region is not None and event.box is not None:
        return f"{region} and its box"
    return region or "box"


def _probes_after(probes: dict, gone, selection: str = "box") -> dict:
    """Probes' (cell, nodes) after a removal; TopologyError when one loses its cell or a node it reads.
    selection: what chose the removed cells (_selection), named in the message."""
    orphans = set(gone.orphans.tolist())
    out = {}
    for name, (cell, nodes) in probes.items():
        if cell is not None and cell >= 0:
            cell = int(gone.new_ids[cell])
            if cell < 0:
                raise TopologyError(f"the cells it removes hold probe {name!r}, which would read nothing from "
                                    f"then on; move the probe or narrow the removal's {selection}")
        elif orphans & set(np.asarray(nodes).tolist()):
            raise TopologyError(f"it leaves nodes probe {name!r} averages without a cell, which would read zero "
                                f"from then on; narrow the probe's region/box or the removal's {selection}")
        out[name] = (cell, nodes)
    return out


def _step(event, solver) -> int:
    return int(event.step) if event.step is not None else _step_at(event.time, solver)


def _still_joined(mesh, pairs) -> np.ndarray:
    """The pairs that still share a face (an earlier cut may have opened some of them already)."""
    if not len(pairs):
        return pairs
    keys, owner = face_rows(mesh, np.unique(pairs))
    shared = shared_faces(keys, owner)
    if not len(shared):
        return pairs[:0]
    code = shared[:, 0] * mesh.n_cells + shared[:, 1]
    p = np.sort(pairs, axis=1)
    return pairs[np.isin(p[:, 0] * mesh.n_cells + p[:, 1], code)]


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
    mesh = model.mesh
    F = mean_deformation_gradients(model, u)
    stretch = np.sqrt(np.linalg.eigvalsh(np.einsum("eji,ejk->eik", F, F))[:, -1])
    hot = np.flatnonzero(stretch >= 1.0 + threshold)
    if box is not None and hot.size:
        hot = np.intersect1d(hot, box_cells(mesh, box, tol))
    if not hot.size:
        return np.zeros((0, 2), np.int64)
    inc = incidence(mesh)
    nodes = np.unique(np.concatenate(nodes_of_cells(mesh, hot)))
    _, around, _ = inc.of(nodes)
    keys, owner = face_rows(mesh, np.unique(around))
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
    count, piece = pieces(model.mesh)         # one piece too: a removal may take away what held it
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
    return nodes_of_cells(mesh, ids)
