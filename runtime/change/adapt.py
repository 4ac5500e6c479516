"""Dynamic adaptation (thesis §4.6): per-element criteria, and rules that switch laws or refine.

    adapter = Adapter(model)                     # the model's [[adapt]] rules
    change = adapter.update(ctx, step)           # after a step: act where a criterion fires
    values = criteria(model, u, ("R_L", "rotation"), asm)   # one value per mesh cell

Criteria (vectorised over the elements of each kernel part, current state x = X + u):

- R_L   edge stretch, max over the element's edges of |l0 - l| / l0;
- R_A   volume (area in 2D) change |S0 - S| / S0, S = sum_q w_q det J_q det F_q;
- R_M   quality S / (c l_mean^d): 1 for the regular element of its type (c: the
        measure of that element with unit edges, ElementType.regular_measure in
        tensormass.elements), smaller when it degenerates;
- R_HM  quality S H / (c l_mean^(d-1)), H the mean of inverse edge lengths (the
        thesis prints l_mean^3 in the denominator, which is not dimensionless: a typo);
- R_S   stress criterion (1/S) sum_q w_q sum_j |N_j(g_q) f_j| = sum_j (int N_j / S) |f_j|
        with f_j the element's internal force at node j.  The nodal weights
        int N_j / S are taken as the equal split 1/k the lumped masses use (exact
        for linear simplices), times S0/S;
- rotation  the angle (degrees) of R in the polar decomposition F = R U of the
        element's volume-averaged deformation gradient, from a batched SVD
        (F = A S B^T, R = A B^T with the sign fixed so that det R = 1).  Exact for
        the average F, costs one 3x3 SVD per element; evaluated only on steps a
        rule is due.

Actions: `switch_law` flips which of the preloaded law parts models a cell (state,
mesh and sparsity pattern untouched); `refine` bisects triangles/tetrahedra
(runtime.mesh.refine) and returns a rebuilt model with the state interpolated.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ... import elements as _types
from ..base.errors import TensormassError
from ..mesh.regions import switch_applies
from ..mesh.refine import refine

__all__ = ["CRITERIA", "Adapter", "Change", "criteria", "part_criteria", "mean_deformation_gradients"]

CRITERIA = ("R_L", "R_A", "R_M", "R_HM", "R_S", "rotation")

# A static load step is re-solved after adapting until nothing changes, at most this often.
MAX_STATIC_PASSES = 10


# --------------------------------------------------------------------------- criteria


def _geometry(part):
    """(v, G): per integration point weights (n, q) and shape gradients (n, q, k, dim) of active cells."""
    k = part.kernel
    if k.recompute:
        raise TensormassError(f"{k}: adaptation criteria need precomputed shape gradients (constants='precompute')")
    return k.point_volumes(part.D_active), k.point_gradients(part.D_active)   # layout: the kernel's metadata


@njit(cache=True)
def _polar_angles_3d(F, out):
    """Rotation angle (degrees) of F = R U by Newton's polar iteration X <- (X + X^-T) / 2.

    X^-T is the cofactor matrix over det X; the iteration converges quadratically from
    any F with det F > 0 (the others are left NaN for the SVD path).  ~20x faster than
    numpy's batched SVD on 3x3 matrices.
    """
    for e in range(F.shape[0]):
        X = F[e].copy()
        out[e] = np.nan
        for _ in range(40):
            c00 = X[1, 1] * X[2, 2] - X[1, 2] * X[2, 1]
            c01 = X[1, 2] * X[2, 0] - X[1, 0] * X[2, 2]
            c02 = X[1, 0] * X[2, 1] - X[1, 1] * X[2, 0]
            det = X[0, 0] * c00 + X[0, 1] * c01 + X[0, 2] * c02
            if not det > 0.0:
                break
            C = np.empty((3, 3))
            C[0, 0], C[0, 1], C[0, 2] = c00, c01, c02
            C[1, 0] = X[0, 2] * X[2, 1] - X[0, 1] * X[2, 2]
            C[1, 1] = X[0, 0] * X[2, 2] - X[0, 2] * X[2, 0]
            C[1, 2] = X[0, 1] * X[2, 0] - X[0, 0] * X[2, 1]
            C[2, 0] = X[0, 1] * X[1, 2] - X[0, 2] * X[1, 1]
            C[2, 1] = X[0, 2] * X[1, 0] - X[0, 0] * X[1, 2]
            C[2, 2] = X[0, 0] * X[1, 1] - X[0, 1] * X[1, 0]
            change = 0.0
            for i in range(3):
                for j in range(3):
                    y = 0.5 * (X[i, j] + C[i, j] / det)
                    change = max(change, abs(y - X[i, j]))
                    X[i, j] = y
            if change < 1e-14:
                cos = min(1.0, max(-1.0, 0.5 * (X[0, 0] + X[1, 1] + X[2, 2] - 1.0)))
                out[e] = np.degrees(np.arccos(cos))
                break


def _rotation_degrees(F: np.ndarray) -> np.ndarray:
    """Angle of the rotation in the polar decomposition of each F (n, d, d), in degrees."""
    if F.shape[1] == 2:        # 2D has a closed form: R turns by atan2(F10 - F01, F00 + F11)
        angle = np.degrees(np.abs(np.arctan2(F[:, 1, 0] - F[:, 0, 1], F[:, 0, 0] + F[:, 1, 1])))
        if np.all(np.linalg.det(F) > 0):
            return angle
    else:
        angle = np.empty(len(F))
        _polar_angles_3d(np.ascontiguousarray(F), angle)
        if not np.isnan(angle).any():
            return angle
    hard = ~(np.linalg.det(F) > 0) if F.shape[1] == 2 else np.isnan(angle)
    angle[hard] = _rotation_degrees_svd(F[hard])
    return angle


def _rotation_degrees_svd(F: np.ndarray) -> np.ndarray:
    """The same through an SVD, for inverted or degenerate F (the rotation closest to F)."""
    A, _, Bt = np.linalg.svd(F)
    R = A @ Bt
    flip = np.linalg.det(R) < 0                   # reflections: flip the smallest singular direction
    if flip.any():
        A[flip, :, -1] *= -1
        R[flip] = A[flip] @ Bt[flip]
    if F.shape[1] == 2:
        return np.degrees(np.abs(np.arctan2(R[:, 1, 0], R[:, 0, 0])))
    cos = np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def _mean_F(v, G, ue) -> np.ndarray:
    """(n, dim, dim) volume average of F = I + sum_i u_i (x) (average gradient of N_i): one small product."""
    Gbar = np.einsum("eq,eqib->eib", v, G, optimize=True) / v.sum(axis=1)[:, None, None]
    return np.eye(ue.shape[2]) + np.einsum("eia,eib->eab", ue, Gbar, optimize=True)


def mean_deformation_gradients(model, u: np.ndarray) -> np.ndarray:
    """(n_cells, dim, dim) volume-averaged deformation gradient of every cell, global order (I where no
    material models it): what the rotation criterion and tearing (runtime.change.events) read."""
    dim = model.dim
    F = np.broadcast_to(np.eye(dim), (model.mesh.n_cells, dim, dim)).copy()
    for part in model.parts:
        if part.n_active:
            v, G = _geometry(part)
            F[part.cell_ids_active] = _mean_F(v, G, model.element_displacements(part, u)[:, :, :dim])
    return F


def part_criteria(model, part, u: np.ndarray, names, asm=None) -> dict:
    """Criteria of a part's active cells: name -> (n_active,) array."""
    names = set(names)
    out = {}
    if part.n_active == 0:
        return {name: np.zeros(0) for name in names}
    X = model.mesh.points[part.cells_active]
    ue = model.element_displacements(part, u)
    dim = model.dim
    el = _types.get(part.element)              # corner edges and the regular element's measure
    edges = np.asarray(el.edges)
    S0 = part.volume if part.index is None else part.volume[part.index]
    if names & {"R_A", "R_M", "R_HM", "R_S", "rotation"}:
        v, G = _geometry(part)
    if names & {"R_A", "R_M", "R_HM", "R_S"}:
        F = np.eye(dim) + np.einsum("eia,eqib->eqab", ue, G, optimize=True)
        S = np.einsum("eq,eq->e", v, np.linalg.det(F))
    if names & {"R_L", "R_M", "R_HM"}:
        x = X + ue
        l0 = np.linalg.norm(X[:, edges[:, 1]] - X[:, edges[:, 0]], axis=2)
        lt = np.linalg.norm(x[:, edges[:, 1]] - x[:, edges[:, 0]], axis=2)
        if "R_L" in names:
            out["R_L"] = np.max(np.abs(l0 - lt) / l0, axis=1)
        c, mean = el.regular_measure, lt.mean(axis=1)
        if "R_M" in names:
            out["R_M"] = S / (c * mean**el.dim)
        if "R_HM" in names:
            out["R_HM"] = S * np.mean(1.0 / lt, axis=1) / (c * mean ** (el.dim - 1))
    if "R_A" in names:
        out["R_A"] = np.abs(S0 - S) / S0
    if "rotation" in names:
        out["rotation"] = _rotation_degrees(_mean_F(v, G, ue))
    if "R_S" in names:
        if asm is None:
            raise TensormassError("criterion R_S needs the assembler (element forces)")
        fe = asm.element_forces(part, u).reshape(part.n_active, -1, dim)
        out["R_S"] = np.linalg.norm(fe, axis=2).mean(axis=1) * S0 / S
    return out


def criteria(model, u: np.ndarray, names, asm=None) -> dict:
    """Criteria of every cell: name -> (n_cells,) in global cell order (NaN: no material)."""
    unknown = sorted(set(names) - set(CRITERIA))
    if unknown:
        raise TensormassError(f"unknown criterion {unknown[0]!r}; known: {', '.join(CRITERIA)}")
    out = {name: np.full(model.mesh.n_cells, np.nan) for name in names}
    for part in model.parts:
        if part.n_active == 0:
            continue
        for name, values in part_criteria(model, part, u, names, asm).items():
            out[name][part.cell_ids_active] = values
    return out


# --------------------------------------------------------------------------- the adapter


@dataclass
class Change:
    """What one update did; `model` and `parents` are set when the mesh was refined."""
    switched: int = 0
    split: int = 0
    model: object = None
    parents: np.ndarray | None = None

    def __bool__(self) -> bool:
        return bool(self.switched or self.split)


@dataclass
class _Tally:
    switched: int = 0
    switched_back: int = 0
    split: int = 0
    time: float = 0.0
    events: list = field(default_factory=list)


class Adapter:
    """Applies a model's [[adapt]] rules after each step (see the module docstring)."""

    def __init__(self, model):
        self.rules = list(model.adapt)
        self.rounds = [0] * len(self.rules)
        self.tally = _Tally()

    def due(self, step: int) -> list:
        return [r for r, rule in enumerate(self.rules)
                if step % rule.every == 0 and (rule.action != "refine" or self.rounds[r] < rule.rounds)]

    def update(self, ctx, step: int) -> Change:
        """Evaluate the rules due at this step and act; the state (ctx.u, ctx.v) is never changed."""
        start = time.perf_counter()
        due = self.due(step)
        change = Change()
        if due:
            names = sorted({self.rules[r].criterion for r in due})
            values = criteria(ctx.model, ctx.u, names, ctx.asm)
            change.switched = self._switch(ctx, step, [r for r in due if self.rules[r].action == "switch_law"], values)
            refine_rules = [r for r in due if self.rules[r].action == "refine"]
            if refine_rules:
                self._refine(ctx, step, refine_rules, values, change)
        self.tally.time += time.perf_counter() - start
        return change

    # -- switch_law -----------------------------------------------------------------------------
    def _fires(self, rule, vals, level):
        return vals < level if rule.below else vals > level

    def _level(self, rule, values, value):
        if not rule.relative:
            return value
        finite = values[rule.criterion][np.isfinite(values[rule.criterion])]
        return value * (finite.max() if finite.size else 0.0)

    def _switch(self, ctx, step, rules, values) -> int:
        model, total = ctx.model, 0
        for group in model.groups:
            ids = model.parts[group.parts[0]].cell_ids
            moved = np.zeros(len(ids), dtype=bool)
            for r in rules:
                rule = self.rules[r]
                vals = values[rule.criterion][ids]
                applies = np.array([switch_applies(rule, law) for law in group.laws], dtype=bool)
                eligible = applies[group.current]
                up = np.flatnonzero(eligible & ~moved & self._fires(rule, vals, self._level(rule, values, rule.threshold)))
                if up.size:
                    n = group.switch(model, up, rule.law)
                    moved[up] = True
                    total += n
                    self.tally.switched += n
                    self._event(ctx, step, r, "switch_law", n, law=rule.law)
                if rule.back is None:
                    continue
                at_target = group.current == group.laws.index(rule.law)
                came = applies[group.previous]
                back = self._level(rule, values, rule.back)
                calm = vals > back if rule.below else vals < back
                down = np.flatnonzero(at_target & came & ~moved & calm)
                for target in np.unique(group.previous[down]):
                    cells = down[group.previous[down] == target]
                    n = group.switch(model, cells, group.laws[target])
                    moved[cells] = True
                    total += n
                    self.tally.switched_back += n
                    self._event(ctx, step, r, "switch_back", n, law=group.laws[target])
        if total:
            ctx.asm.refresh()
        return total

    # -- refine ---------------------------------------------------------------------------------
    def _refine(self, ctx, step, rules, values, change: Change) -> None:
        model = ctx.model
        marked = np.zeros(model.mesh.n_cells, dtype=bool)
        for r in rules:
            rule = self.rules[r]
            vals = np.nan_to_num(values[rule.criterion], nan=np.inf if rule.below else -np.inf)
            marked |= self._fires(rule, vals, self._level(rule, values, rule.threshold))
            self.rounds[r] += 1
        if not marked.any():
            return
        result = refine(model.mesh, marked, propagate=True)      # Rivara: quality stays bounded
        laws_now, came_from = _cell_law_names(model)
        new = model.rebuilt(result.mesh)
        new.set_cell_laws(laws_now[result.cell_parent])
        for group in new.groups:                                  # children keep their parent's hysteresis
            parent = result.cell_parent[new.parts[group.parts[0]].cell_ids]
            group.previous = np.array([group.laws.index(law) for law in came_from[parent]], dtype=np.int64)
        change.split, change.model, change.parents = result.n_split, new, result.parents
        self.tally.split += result.n_split
        self._event(ctx, step, rules[0], "refine", result.n_split, cells=int(new.mesh.n_cells))

    def _event(self, ctx, step, rule, action, count, **extra):
        self.tally.events.append({"step": int(step), "time": float(ctx.t), "rule": int(rule), "action": action,
                                  "count": int(count), **extra})

    # -- reporting ------------------------------------------------------------------------------
    def summary(self, model) -> dict:
        per_law: dict = {}
        for p in model.parts:
            per_law[p.law] = per_law.get(p.law, 0) + p.n_active
        return {"rules": len(self.rules), "switched": self.tally.switched,
                "switched_back": self.tally.switched_back, "split": self.tally.split,
                "elements_per_law": dict(sorted(per_law.items())), "law_ids": model.law_names(),
                "time": self.tally.time, "events": list(self.tally.events)}

    def cell_fields(self, ctx) -> dict:
        """A cell field per criterion, plus `law_id` (index into model.law_names(); -1: no material)."""
        values = {name: np.where(np.isfinite(v), v, -1.0)          # -1: undefined (e.g. collapsed)
                  for name, v in criteria(ctx.model, ctx.u, CRITERIA, ctx.asm).items()}
        values["law_id"] = ctx.model.cell_law().astype(float)
        return values


def _cell_law_names(model) -> tuple:
    """(current law, law it came from) of every cell, by name, in global cell order."""
    names = model.cell_laws()
    came_from = names.copy()
    for group in model.groups:
        came_from[model.parts[group.parts[0]].cell_ids] = np.asarray(group.laws, dtype=object)[group.previous]
    return names, came_from
