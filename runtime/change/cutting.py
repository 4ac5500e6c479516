"""A running model after a topology change (runtime.mesh.topology): rebuilt only where the mesh changed.

    new_model = separated(model, split)        # nodes duplicated along a cut (runtime.mesh.topology.Split)
    new_model = removed(model, removal)        # cells taken out (runtime.mesh.topology.Removal)

Both return a new Model and leave the old one untouched (nothing anybody still holds changes
under them; caches keyed on the model object see a new one).  What is carried over and what is
recomputed:

- per-element constants, rest volumes, densities, kernels: kept (a cut changes no cell's rest
  geometry); the rows of removed cells are dropped;
- connectivity and dof tables: only the rows of the renumbered cells change;
- lumped masses and body forces (gravity): recomputed for the touched nodes only (the parents,
  the new nodes, the nodes of removed cells), from the cells around them; the total mass and the
  momentum (the new nodes take their parent's velocity) are conserved to rounding;
- constraints: a new node inherits its parent's [[fixed]] entry and value (a cut through a
  clamp leaves both lips clamped); nodes a removal leaves without a cell are pinned (no mass,
  no stiffness);
- loads on faces (tractions, pressures): faces owned by a renumbered cell follow it; nodal
  forces stay on the nodes that carried them;
- point probes follow their cell; region probes keep their nodes;
- consistent masses (solver.mass = "consistent") are rebuilt whole (not local).

Refused (TopologyError naming the reason): shells and other lower-dimensional cells, locking-free
formulations (their couplings widen the pattern), [[adapt]] rules together with topology events.
"""
from __future__ import annotations

import copy

import numpy as np

from ... import laws
from ... import elements as _types
from ..assembly import loads as _loads
from ..base.dofs import node_dofs
from ..assembly.mass import MassMatrix
from ..assembly.pressure import FollowerPressure
from ..base.errors import TensormassError
from ..model.model import LawGroup, Part
from ..physics.motion import Motion
from ..mesh.probes import PointProbe
from ..mesh.topology import Removal, Split, TopologyError, face_owners, incidence

__all__ = ["separated", "removed", "check_model", "touched_node_mask"]


def check_model(model) -> None:
    """Refuse models whose topology cannot change during a run (see the module docstring)."""
    if any(_flat(model, b.type) for b in model.mesh.blocks):
        raise TopologyError("only solid meshes can change topology here (shells, bars and springs "
                            "cannot be cut yet)")
    springs = sorted({p.law for p in model.parts if laws.is_discrete(p.law)})
    if springs:
        raise TopologyError(f"spring models (law {', '.join(map(repr, springs))}) cannot be cut, removed or refined "
                            "yet: their lattice springs are not split with the cells; use a continuum law there")
    if getattr(model, "couplings", None):
        raise TopologyError("locking-free formulations (material formulation) cannot be combined "
                            "with topology changes yet; use formulation = \"displacement\"")
    if model.adapt:
        raise TopologyError("[[adapt]] rules cannot be combined with [[cut]] / [[remove]] / [[refine]] "
                            "events yet")


def _flat(model, cell_type) -> bool:
    return _types.get(cell_type).dim != model.dim


def touched_node_mask(n_points: int, nodes) -> np.ndarray:
    mask = np.zeros(n_points, dtype=bool)
    mask[np.asarray(nodes, dtype=np.int64)] = True
    return mask


# --------------------------------------------------------------------------- the two operations


def separated(model, split: Split):
    """The model after `split` (runtime.mesh.topology.separate on model.mesh)."""
    check_model(model)
    _keep_incidence(model, split)
    mesh = split.apply(model.mesh)
    new = _start(model, mesh)
    new.parts = _renumbered_parts(model, split)
    new.groups = [LawGroup(list(g.parts), list(g.laws), g.current.copy(), g.previous.copy()) for g in model.groups]
    parents = split.parents
    touched = split.touched_nodes
    _constraints(model, new, parents, orphans=np.zeros(0, np.int64))
    _masses_and_body_forces(model, new, parents, touched)
    _face_loads(model, new, split)
    _probes(model, new, lambda cell: cell)
    new.motion = Motion(new, list(new._specs[0]), new.amplitudes)
    new._incidence = None
    return new


def removed(model, removal: Removal):
    """The model after `removal` (runtime.mesh.topology.removal on model.mesh)."""
    check_model(model)
    mesh = removal.apply(model.mesh)
    new = _start(model, mesh)
    keep_rows = []
    parts = []
    for part in model.parts:
        keep = removal.new_ids[part.cell_ids] >= 0
        keep_rows.append(keep)
        parts.append(_part(part, cells=part.cells[keep], cell_ids=removal.new_ids[part.cell_ids[keep]],
                           D=part.D[keep], volume=part.volume[keep], dofs=part.dofs[keep], density=part.density[keep],
                           active=part.active[keep],
                           rotary=None if part.rotary is None else np.asarray(part.rotary)[keep],
                           cell_masses=_rows(part.cell_masses, keep), cell_shares=_rows(part.cell_shares, keep),
                           branches=None if part.branches is None else tuple(b[keep] for b in part.branches),
                           fibres=_rows(part.fibres, keep), origin_rows=np.flatnonzero(keep)))
    _share_dof_tables(model.parts, parts)
    new.parts = parts
    new.groups = []
    for g in model.groups:
        keep = keep_rows[g.parts[0]]
        new.groups.append(LawGroup(list(g.parts), list(g.laws), g.current[keep].copy(), g.previous[keep].copy()))
    touched = removal.touched
    _constraints(model, new, np.zeros(0, np.int64), orphans=removal.orphans)
    _masses_and_body_forces(model, new, np.zeros(0, np.int64), touched)
    _face_loads_after_removal(model, new, removal)
    _probes(model, new, lambda cell: int(removal.new_ids[cell]))
    new.motion = Motion(new, list(new._specs[0]), new.amplitudes)
    new._incidence = None
    return new


# --------------------------------------------------------------------------- pieces


def _start(model, mesh):
    """A shallow copy of the model on the new mesh; every array that changes is replaced, never edited."""
    new = copy.copy(model)
    new.mesh = mesh
    new.n_points = mesh.n_points
    new.n_dofs = mesh.n_points * model.dofs_per_node
    new.scene = model.scene
    return new


def _part(part: Part, **changes) -> Part:
    fields = dict(element=part.element, law=part.law, quadrature=part.quadrature, kernel=part.kernel,
                  cells=part.cells, cell_ids=part.cell_ids, D=part.D, volume=part.volume, dofs=part.dofs,
                  density=part.density, active=part.active.copy(), rotary=part.rotary,
                  cell_masses=part.cell_masses, cell_shares=part.cell_shares, branches=part.branches,
                  fibres=part.fibres, origin_rows=np.arange(len(part.cells)))
    fields.update(changes)
    return Part(**fields)


def descend(model, new, cell_parent) -> None:
    """Each part of `new` (a refined model, built anew) learns where its cells come from in the part
    of `model` at the same index: Part.origin_rows and origin_split (cell_parent: the old id of
    every new cell's parent, itself when not split)."""
    split_count = np.bincount(cell_parent, minlength=model.mesh.n_cells)
    for old, part in zip(model.parts, new.parts):
        if old.key != part.key:
            raise TensormassError(f"a refined model's parts differ from the model's ({old.key} / {part.key})")
        row_of = np.full(model.mesh.n_cells, -1, dtype=np.int64)
        row_of[old.cell_ids] = np.arange(len(old.cell_ids))
        parents = cell_parent[part.cell_ids]
        part.origin_rows = row_of[parents]
        part.origin_split = split_count[parents] > 1


def _rows(array, keep):
    return None if array is None else array[keep]


def _share_dof_tables(old_parts, new_parts) -> None:
    """Parts of a switchable group share one dof table (the assembler sorts it once): keep that."""
    seen = {}
    for old, new in zip(old_parts, new_parts):
        if id(old.dofs) in seen:
            new.dofs = seen[id(old.dofs)]
            new._refresh()
        else:
            seen[id(old.dofs)] = new.dofs


def _renumbered_parts(model, split: Split) -> list:
    """Parts with the split's renumberings applied to their rows (constants untouched)."""
    dpn = model.dofs_per_node
    n_cells = model.mesh.n_cells
    parts, tables = [], {}
    for part in model.parts:
        row_of = np.full(n_cells, -1, dtype=np.int64)
        row_of[part.cell_ids] = np.arange(len(part.cell_ids))
        rows = row_of[split.cells]
        mine = rows >= 0
        cells = part.cells
        if mine.any():
            cells = part.cells.copy()
            cells[rows[mine], split.local[mine]] = split.node[mine]
        key = id(part.dofs)
        if key not in tables:
            dofs = part.dofs
            if mine.any():
                changed = np.unique(rows[mine])
                dofs = part.dofs.copy()
                dofs[changed] = node_dofs(cells[changed], dpn)
            tables[key] = dofs
        parts.append(_part(part, cells=cells, dofs=tables[key]))
    return parts


def _removed_cells(model, removal: Removal) -> list:
    out = []
    for part in model.parts:
        gone = removal.new_ids[part.cell_ids] < 0
        if gone.any():
            out.append(part.cells[gone].ravel())
    return out or [np.zeros(0, np.int64)]


def _constraints(model, new, parents, orphans) -> None:
    """Fixed dofs: new nodes inherit their parent's entry and value; orphans are pinned at zero."""
    dpn = model.dofs_per_node
    value = np.full(model.n_dofs, np.nan)
    value[model.fixed_dofs] = model.prescribed
    value = value.reshape(model.n_points, dpn)
    owner = np.asarray(model.fixed_owner).reshape(model.n_points, dpn)
    value = np.vstack([value, value[parents]])
    owner = np.vstack([owner, owner[parents]])
    if orphans.size:
        free = np.isnan(value[orphans])
        value[orphans] = np.where(free, 0.0, value[orphans])
    new.fixed_owner = owner
    flat = value.ravel()
    new.fixed_dofs = np.flatnonzero(~np.isnan(flat))
    new.prescribed = flat[new.fixed_dofs]
    new.n_user_fixed = int(np.count_nonzero(owner.ravel()[new.fixed_dofs] >= 0))
    new.free_dofs = np.setdiff1d(np.arange(new.n_dofs), new.fixed_dofs)


def _masses_and_body_forces(model, new, parents, touched) -> None:
    """Lumped masses and gravity of the touched nodes, summed again from the per-cell contributions the
    model kept since its build (Part.cell_masses, Part.cell_shares): nothing is integrated again."""
    dpn = model.dofs_per_node
    g = np.asarray(model.loads.gravity, float).reshape(-1)[:model.n_load] if np.any(model.loads.gravity) else None
    if model.mass_matrix.kind != "lumped":
        new._lumped_mass()                    # consistent masses: the whole matrix again (documented)
        new.mass_matrix = new._mass_matrix
    node_mass = np.concatenate([model.mass[::dpn], model.mass[::dpn][parents]])
    mask = touched_node_mask(new.n_points, touched)
    node_mass[mask] = 0.0
    body = np.vstack([model._body, model._body[parents]])
    body[mask] = 0.0
    for part in new.parts:
        rows = np.flatnonzero(part.active & mask[part.cells].any(axis=1))
        if not rows.size:
            continue
        cells = part.cells[rows]
        hit = mask[cells]
        np.add.at(node_mass, cells[hit], part.cell_masses[rows][hit])
        if g is not None:
            np.add.at(body, cells[hit], part.cell_shares[rows][hit][:, None] * g)
    if model.mass_matrix.kind == "lumped":
        new.mass = np.repeat(node_mass, dpn)
        new.mass_matrix = MassMatrix("lumped", dpn, new.n_dofs, new.mass)
    else:
        new.mass = new.mass_matrix.lumped
    other = _other_loads(model)
    f = np.zeros(new.n_dofs)
    F = f.reshape(new.n_points, dpn)
    F[:model.n_points] = other
    F[:, :model.n_load] += body
    new.f_ext = f
    new._body = body


def _other_loads(model) -> np.ndarray:
    """(n_points, dpn) of model.f_ext without gravity: nodal forces, moments, tractions."""
    F = model.f_ext.reshape(model.n_points, model.dofs_per_node).copy()
    F[:, :model.n_load] -= model._body
    return F


def _owners(model, faces: np.ndarray) -> np.ndarray:
    """The cell owning each boundary face (runtime.mesh.topology.face_owners), the incidence kept on the model."""
    inc = getattr(model, "_incidence", None)
    if inc is None:
        inc = model._incidence = incidence(model.mesh)
    return face_owners(model.mesh, faces, inc)


def _keep_incidence(model, split) -> None:
    """The split's incidence is the old mesh's: face owners for the loads need no second pass."""
    if getattr(split, "incidence", None) is not None and getattr(model, "_incidence", None) is None:
        model._incidence = split.incidence


def _face_loads(model, new, split: Split) -> None:
    """Tractions and pressures on faces owned by renumbered cells: moved to the new node ids."""
    mask = touched_node_mask(model.n_points, split.parents)
    moved = np.zeros(new.n_dofs)
    for faces, traction in getattr(model, "_tractions", ()):
        for name, f in faces.items():
            hit = mask[f].any(axis=1)
            if not hit.any():
                continue
            old = f[hit]
            mapped = split.map_faces(old, _owners(model, old))
            before = _loads.traction(model.mesh.points, {name: old}, traction)
            after = _loads.traction(new.mesh.points, {name: mapped}, traction)
            M = moved.reshape(new.n_points, model.dofs_per_node)
            M[:model.n_points, :model.n_load] -= before
            M[:, :model.n_load] += after
    new.f_ext = new.f_ext + moved
    new._tractions = [({name: _mapped(model, split, mask, f) for name, f in faces.items()}, t)
                      for faces, t in getattr(model, "_tractions", ())]
    if model.pressure is not None:
        new.pressure = _pressure_on(model, new, lambda name, f: _mapped(model, split, mask, f))


def _mapped(model, split, mask, f):
    hit = mask[f].any(axis=1)
    if not hit.any():
        return f
    f = f.copy()
    f[hit] = split.map_faces(f[hit], _owners(model, f[hit]))
    return f


def _pressure_on(model, new, remap):
    """A FollowerPressure like the model's with its faces passed through remap(name, faces)."""
    old = model.pressure
    loads = []
    for name, (faces, _) in old.groups.items():
        base, which = old._base[name]
        for w in np.unique(which):
            for value in np.unique(base[which == w]):
                sel = (which == w) & (base == value)
                amplitude = None if w == 0 else old.amplitude_names[w - 1]
                faces_w = remap(name, faces[sel])
                if len(faces_w):
                    loads.append(({name: faces_w}, float(value), amplitude))
    pressure = FollowerPressure(new.mesh.points, loads, new.dim, new.dofs_per_node)
    pressure.symmetric = old.symmetric
    return pressure


def _face_loads_after_removal(model, new, removal: Removal) -> None:
    """Loaded faces of removed cells go with them (their share of f_ext too)."""
    gone = np.zeros(model.n_points, dtype=bool)
    for c in _removed_cells(model, removal):
        gone[c] = True
    F = new.f_ext.reshape(new.n_points, model.dofs_per_node)
    kept_tractions = []
    for faces, traction in getattr(model, "_tractions", ()):
        keep = {}
        for name, f in faces.items():
            hit = gone[f].any(axis=1)
            if hit.any():
                owners = _owners(model, f[hit])
                dead = removal.new_ids[owners] < 0
                if dead.any():
                    F[:, :model.n_load] -= _loads.traction(model.mesh.points, {name: f[hit][dead]}, traction)
                    alive = np.ones(len(f), bool)
                    alive[np.flatnonzero(hit)[dead]] = False
                    f = f[alive]
            keep[name] = f
        kept_tractions.append((keep, traction))
    new._tractions = kept_tractions
    if model.pressure is not None:
        def alive(name, f):
            hit = gone[f].any(axis=1)
            if not hit.any():
                return f
            keep = np.ones(len(f), bool)
            keep[np.flatnonzero(hit)[removal.new_ids[_owners(model, f[hit])] < 0]] = False
            return f[keep]
        new.pressure = _pressure_on(model, new, alive)


def _probes(model, new, new_cell) -> None:
    """Point probes read the nodes of their cell in the new mesh; region probes keep their nodes."""
    off = np.concatenate([[0], np.cumsum([len(b) for b in new.mesh.blocks])])
    probes = {}
    for name, p in model.probes.items():
        if p.point is None or p.cell < 0:
            probes[name] = p
            continue
        cell = new_cell(p.cell)
        if cell < 0:                 # its cell was removed: it keeps reading the nodes it had
            probes[name] = p
            continue
        b = int(np.searchsorted(off, cell, side="right") - 1)
        nodes = new.mesh.blocks[b].cells[cell - off[b]]
        probes[name] = PointProbe(p.name, p.point, cell, nodes, p.weights, p.xi, p.distance)
    new.probes = probes
