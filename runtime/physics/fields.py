"""Output fields: stress, strain, energy and ids of every cell (and node) at a state.

    point, cell = evaluate(model, u, ["von_mises", "cauchy_stress"])   # dicts name -> array
    point, cell = evaluate(model, u, ["von_mises@cell", "cauchy_stress@point"])   # the other location
    FIELDS["von_mises"].unit                                             # "Pa"

Every stress and strain field comes from the generated `stress` kernel of each part (one per
element x law x quadrature: mixed meshes, law-switched and refined models alike): per element
and integration point it writes the point volume v = w det J, the energy density W, F and
P = dW/dF (and, for 2D plane strain, P33). The fields follow from these with the same formulas
for every law, so a new law file gets them with no code here:

    sigma = P F^T / J (Cauchy; 2D: the in-plane block and sigma33 = P33 / J, plane strain F33 = 1)
    von Mises = sqrt(3/2 s:s), s = sigma - tr(sigma)/3 I;   pressure = -tr(sigma)/3
    C = F^T F;  principal stretches = sqrt(eig C), largest first;   E = (C - I)/2

Averaging: each field is evaluated at the integration points; the cell value is the
volume-weighted mean over the cell's points (sum_q v_q x_q / sum_q v_q: the quadrature of the
cell's mean), det_F_min the smallest value over them. Nodal (point) values are the
volume-weighted average of the cell values of the cells around the node (sum_c V_c x_c / sum_c V_c
over the cells that hold it; not an L2 projection): smooth for ParaView, exact for homogeneous
states, but averaged across material interfaces. Tensors are written with 9 components, row-major
(xx, xy, xz, yx, yy, yz, zx, zy, zz; ParaView's tensor order, read back by meshio as (n, 9));
2D meshes get full 3x3 tensors (plane strain: F33 = 1, sigma33 from P33, E33 = 0) and 3 stretches.

Where. Each field is written once, at the location FIELDS gives it (Field.where: the tensors,
stretches, energy density and det_F_min as cell data; von Mises and pressure as point data);
"name@cell" / "name@point" in [output] fields asks for a location the field offers (Field.other),
both entries for both. Frames store the stress and strain fields as Float32 (frame_dtype).

Only what a scene asks for is computed: the stress kernels run only when a stress or strain
field is requested, and only the requested fields are derived from their records.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import ElementError, TensormassError
from ..mesh.regions import assign_materials

__all__ = ["Field", "FIELDS", "DEFAULT_FIELDS", "FieldEvaluator", "evaluate", "check_names", "check_available",
           "describe", "resolve", "split_name", "locations", "frame_dtype"]


@dataclass(frozen=True)
class Field:
    """What an output field is: its description, unit, kind (scalar, vector, tensor), where a frame
    writes it by default (where[0]: "cell" or "point") and where else it may be asked for (other:
    "name@point" / "name@cell" in [output] fields), and whether frames store it in single precision."""
    name: str
    description: str
    unit: str
    kind: str                    # scalar | vector | tensor
    where: tuple                 # ("cell",) or ("point",): the default location, written once
    records: bool = True         # computed from the stress kernels' records
    other: str | None = None     # the location available on request, or None
    single: bool = False         # frames store it as Float32 (Simulation.fields() stays float64)


# Where each field is written by default, chosen once per field: the exact per-cell means (tensors,
# stretches, energies: cell data is what a criterion or an integral reads, and a tetra10 mesh has
# fewer cells than nodes) as cell data; the scalars one colours by (von Mises, pressure) as point
# data, smooth in ParaView. The other location costs one more array per frame and is asked for
# with "name@point" / "name@cell". Record fields are stored as Float32 in the frames (7 significant
# digits: what a viewer or a criterion reads; Simulation.fields() gives float64).
_CELL, _POINT = ("cell",), ("point",)
FIELDS = {f.name: f for f in (
    Field("cauchy_stress", "Cauchy (true) stress sigma = P F^T / J, 9 components row-major", "Pa", "tensor", _CELL,
          other="point", single=True),
    Field("von_mises", "von Mises equivalent stress sqrt(3/2 s:s) of the Cauchy stress", "Pa", "scalar", _POINT,
          other="cell", single=True),
    Field("pressure", "pressure -tr(sigma)/3 (positive in compression)", "Pa", "scalar", _POINT, other="cell",
          single=True),
    Field("principal_stretches", "principal stretches sqrt(eig(F^T F)), largest first", "1", "vector", _CELL,
          other="point", single=True),
    Field("green_lagrange", "Green-Lagrange strain E = (F^T F - I)/2, 9 components row-major", "1", "tensor", _CELL,
          other="point", single=True),
    Field("fibre_stretch", "stretch |F a| of the cell's fibre direction a (laws with fibres: hgo; 0 elsewhere)",
          "1", "scalar", _CELL, other="point"),
    Field("viscous_dissipation", "energy the Prony branches dissipated since the start, per unit rest volume "
          "(runtime.physics.viscous; 0 in elastic cells)", "J/m^3", "scalar", _CELL, records=False),
    Field("det_F_min", "smallest det F (volume ratio J) over the cell's integration points", "1", "scalar",
          _CELL, single=True),
    Field("energy_density", "strain energy density W per unit rest volume", "J/m^3", "scalar", _CELL,
          other="point", single=True),
    Field("material", "index of the cell's [[material]] entry (0 = the first)", "1", "scalar", _CELL,
          records=False),
    Field("law", "law id of the cell: index into the run's law names sorted (Model.law_names(), "
          "listed in the summary's fields.law_ids)", "1", "scalar", _CELL, records=False),
    Field("region", "the cell's mesh tag (gmsh physical id), else the id of the mesh volume group that "
          "holds it; -1 where the mesh has neither", "1", "scalar", _CELL, records=False),
    # The nodal reaction force is runtime.physics.reactions'; it reaches
    # evaluate() through `providers` (Simulation.fields passes it), never computed here.
    Field("reaction", "reaction force at constrained nodes (runtime.physics.reactions)", "N", "vector", _POINT,
          records=False),
    # runtime.contact's, through `providers` too: zero off the contact surface
    Field("contact_force", "force the contact (obstacles, other bodies, the body itself) exerts on each node "
          "(runtime.contact)", "N", "vector", _POINT, records=False),
    Field("contact_pressure", "contact force magnitude per unit rest surface area at each surface node "
          "(runtime.contact)", "Pa", "scalar", _POINT, records=False),
)}

# The default of [output] fields: what one looks at first (von Mises: the usual colour map, and
# the picture's default), the full tensor for damage criteria, and det_F_min to see where
# elements are close to inverting. All three come from one stress kernel call per frame.
DEFAULT_FIELDS = ("von_mises", "cauchy_stress", "det_F_min")

# Elements per stress-kernel call when a frame's fields are evaluated (bounds the temporaries:
# ~10 arrays of CHUNK x points x 9 doubles, 20 MB for hexahedra with 27 points).
CHUNK = 1024

# Fields another module computes: name -> what provides it.
PROVIDED = {"reaction": "runtime.physics.reactions", "contact_force": "runtime.contact ([contact] or [[obstacle]])",
            "contact_pressure": "runtime.contact ([contact] or [[obstacle]])",
            "viscous_dissipation": "runtime.physics.viscous (a [[material]] with viscous branches)"}


def split_name(entry: str) -> tuple:
    """(field name, location or None) of an [output] fields entry: "von_mises" -> ("von_mises", None),
    "von_mises@cell" -> ("von_mises", "cell")."""
    name, at, where = entry.partition("@")
    return name, (where if at else None)


def check_names(names, key: str = "output.fields", error=TensormassError) -> tuple:
    """The entries as a tuple, each a known field ("name" at its default location, "name@cell" or
    "name@point" at one it offers) listed once; `error` naming key[i] otherwise."""
    out, seen = [], {}
    for i, entry in enumerate(names):
        if not isinstance(entry, str):
            raise error(f"{key}[{i}]: expected a field name (string), got {type(entry).__name__} {entry!r}")
        name, where = split_name(entry)
        if name not in FIELDS:
            raise error(f"{key}[{i}]: unknown field {name!r}; known fields: {', '.join(FIELDS)}")
        field = FIELDS[name]
        if where is not None and where not in field.where + ((field.other,) if field.other else ()):
            offered = " or ".join(f"{w} data" for w in field.where + ((field.other,) if field.other else ()))
            if where not in ("cell", "point"):
                raise error(f"{key}[{i}]: {entry!r}: the location after @ is cell or point, got {where!r}")
            raise error(f"{key}[{i}]: {entry!r}: {name} is written as {offered} only")
        place = (name, where or field.where[0])
        if place in seen:
            raise error(f"{key}[{i}]: field {name!r} is listed twice as {place[1]} data ({key}[{seen[place]}] "
                        f"is {names[seen[place]]!r})")
        seen[place] = i
        out.append(entry)
    return tuple(out)


def locations(names) -> dict:
    """{field name: [locations]} of checked entries, in the order first listed."""
    out = {}
    for entry in names:
        name, where = split_name(entry)
        places = out.setdefault(name, [])
        place = where or FIELDS[name].where[0]
        if place not in places:
            places.append(place)
    return out


def describe(names) -> dict:
    """{name: {"description", "unit", "kind", "where"}} of the given entries (for summaries; "where":
    the locations written)."""
    return {n: {"description": FIELDS[n].description, "unit": FIELDS[n].unit, "kind": FIELDS[n].kind,
                "where": places} for n, places in locations(names).items()}


def frame_dtype(name: str, values):
    """The dtype a frame stores a field in: float32 for the fields FIELDS marks single, else the
    values' own (arrays a writer is given under other names keep theirs)."""
    field = FIELDS.get(name)
    values = np.asarray(values)
    if field is not None and field.single and values.dtype.kind == "f":
        return np.float32
    return values.dtype


def has_stress(kernel) -> bool:
    """Whether a kernel writes stress records (every generated one; a hand-written one may not)."""
    return callable(getattr(kernel, "stress", None)) and isinstance(getattr(kernel, "stress_record", None), dict)


def resolve(model, names=None) -> tuple:
    """The fields to compute for a model: names (checked), or the scene's [output] fields
    (None there: DEFAULT_FIELDS, less the record fields when a part's kernel cannot give them)."""
    if names is not None:
        return check_names(list(names), "fields")
    chosen = getattr(model.output, "fields", None)
    if chosen is not None:
        return tuple(chosen)
    if all(has_stress(p.kernel) for p in model.parts):
        return DEFAULT_FIELDS
    return tuple(n for n in DEFAULT_FIELDS if not FIELDS[n].records)


FIELDS_REMEDY = "ask only for material, law or region, or set [output] fields = []"


def check_available(model, names, providers=(), key="output.fields", remedy=FIELDS_REMEDY) -> None:
    """Refuse (TensormassError) fields this model cannot give: stress and strain fields need every
    part's kernel to have stress(); provided fields (reaction) need their provider. key names the
    request in the message and remedy says what to ask instead."""
    names = list(locations(check_names(list(names), "fields")))
    asked = [n for n in names if FIELDS[n].records]
    for part in model.parts if asked else ():
        if not has_stress(part.kernel):
            raise _no_stress(part, asked, key, remedy)
    for n in names:
        if n in PROVIDED and n not in providers:
            raise TensormassError(f"{key}: field {n!r} is computed by {PROVIDED[n]}, which this run "
                                  "does not provide")


def _no_stress(part, asked, key="output.fields", remedy=FIELDS_REMEDY) -> TensormassError:
    # kernels without stress(): hand-written ones (runtime.kernels.custom_kernels) and the
    # co-rotational shell wrapper
    return TensormassError(
        f"{key}: {', '.join(asked)} need the stress records of every kernel, and the kernel for "
        f"{part.element}/{part.law}/{part.quadrature} ({part.kernel!r}) has no stress(): {remedy}")


class FieldEvaluator:
    """Fields of one model (Simulation keeps one per model: the ids are computed once)."""

    def __init__(self, model):
        self.model = model
        self._ids = {}

    # -- the pieces ---------------------------------------------------------------------------
    def _records(self, u, asked):
        """Yields (cell ids, v (n, q), W, F3 (n, q, 3, 3), P3, fibre direction (n, 3) or None) of the
        active cells, part by part in chunks of CHUNK elements (the temporaries of a frame stay small
        on big meshes)."""
        model = self.model
        U = model.nodal(np.asarray(u, dtype=float).reshape(-1))
        couplings = {c.part_index: c for c in getattr(model, "couplings", [])}
        for i, part in enumerate(model.parts):
            if part.n_active == 0:
                continue
            coupling = couplings.get(i)
            if coupling is not None:          # a locking-free formulation: add its volumetric part
                pressure, density = coupling.cell_terms(U)
                row_of = coupling.part_rows(len(part.cells))
            kernel = part.kernel
            if not has_stress(kernel):
                raise _no_stress(part, asked)
            layout, d = kernel.stress_record["offsets"], kernel.dim
            fibres = getattr(part, "fibres", None)
            if fibres is not None and part.index is not None:
                fibres = fibres[part.index]
            for start in range(0, part.n_active, CHUNK):
                rows = slice(start, start + CHUNK)
                ids = part.cell_ids_active[rows]
                try:
                    S = kernel.stress(part.D_active[rows], U[part.cells_active[rows]])
                except ElementError as exc:           # global cell ids, not the part-local ones
                    message = str(exc).rsplit(": element(s)", 1)[0]
                    raise type(exc)(f"output fields: {message}", ids[exc.elements]) from None
                F3, P3 = _tensor(S, layout, "F", d, 1.0), _tensor(S, layout, "P", d)
                W = S[..., layout["W"]]
                if coupling is not None:
                    self._add_volumetric(coupling, row_of[start:start + len(ids)], pressure, density, U, W, P3)
                yield ids, S[..., layout["v"]], W, F3, P3, None if fibres is None else fibres[rows]

    @staticmethod
    def _add_volumetric(coupling, rows, pressure, density, U, W, P3):
        """P += p_e dtheta/dF and W += u_e on the formulated cells of a chunk (runtime.assembly.volumetric)."""
        mine = np.flatnonzero(rows >= 0)
        if not mine.size:
            return
        r = rows[mine]
        k = coupling.kernel
        Sm = k.stress(coupling.D[r], np.ascontiguousarray(U[coupling.cells[r]]))
        P3[mine] += pressure[r][:, None, None, None] * _tensor(Sm, k.stress_record["offsets"], "P", k.dim)
        W[mine] += density[r][:, None]

    def _ids_of(self, name: str) -> np.ndarray:
        """material, law or region of every cell (global order); law switching changes `law`."""
        model = self.model
        if name == "law":
            return model.cell_law().astype(np.int64)
        if name not in self._ids:
            if name == "material":
                values = np.concatenate(list(assign_materials(model.mesh, model.materials)) + [np.zeros(0)])
            else:
                values = cell_regions(model.mesh)
            self._ids[name] = np.asarray(values, dtype=np.int64)
        return self._ids[name].copy()

    # -- evaluation ---------------------------------------------------------------------------
    def evaluate(self, u, names, providers=None) -> tuple:
        """(point fields, cell fields) of the named fields at displacement u (dicts name -> array)."""
        places = locations(check_names(list(names), "fields"))
        providers = providers or {}
        model = self.model
        n_cells = model.mesh.n_cells
        point, cell = {}, {}
        wanted = [n for n in places if FIELDS[n].records]
        if wanted:
            volume = np.zeros(n_cells)
            values = {n: None for n in wanted}
            for ids, v, W, F, P, a in self._records(u, wanted):
                per_point = _derive(wanted, W, F, P, a)
                weight = v.sum(axis=1)
                volume[ids] = weight
                for n in wanted:
                    x = per_point[n]
                    if values[n] is None:
                        values[n] = np.zeros((n_cells,) + x.shape[2:])
                    if n == "det_F_min":
                        values[n][ids] = x.min(axis=1)
                    else:
                        w = v.reshape(v.shape + (1,) * (x.ndim - 2))
                        values[n][ids] = (w * x).sum(axis=1) / weight.reshape((-1,) + (1,) * (x.ndim - 2))
            for n in wanted:
                x = values[n] if values[n] is not None else np.zeros(n_cells)
                if x.ndim == 3:
                    x = x.reshape(n_cells, 9)
                if "cell" in places[n]:
                    cell[n] = x
                if "point" in places[n]:
                    point[n] = self._nodal(x, volume)
        for n in places:
            if FIELDS[n].records:
                continue
            if n in PROVIDED:
                check_available(model, (n,), providers)
                (cell if FIELDS[n].where == _CELL else point)[n] = np.asarray(providers[n]())
            else:
                cell[n] = self._ids_of(n)
        return point, cell

    def _nodal(self, x: np.ndarray, volume: np.ndarray) -> np.ndarray:
        """Volume-weighted average of the cell values x (n_cells, ...) at the nodes of the cells
        (sums in a fixed order: the same state gives the same bits)."""
        n = self.model.n_points
        flat = x.reshape(len(x), -1)
        total = np.zeros((n, flat.shape[1]))
        weight = np.zeros(n)
        start = 0
        for block in self.model.mesh.blocks:
            stop = start + len(block)
            if stop > start:
                nodes = block.cells.ravel()
                k = block.cells.shape[1]
                V = np.repeat(volume[start:stop], k)
                weight += np.bincount(nodes, weights=V, minlength=n)
                for c in range(flat.shape[1]):
                    total[:, c] += np.bincount(nodes, weights=V * np.repeat(flat[start:stop, c], k), minlength=n)
            start = stop
        used = weight > 0
        total[used] /= weight[used, None]
        return total.reshape((n,) + x.shape[1:])         # nodes no cell holds: 0


def _tensor(S, layout, name: str, d: int, out_of_plane: float | None = None) -> np.ndarray:
    """The 3x3 tensor `name` (F or P) of stress records S (n, q, size): 2D records are plane strain,
    their 33 entry is `out_of_plane` (F33 = 1) or, for P, the record's P33."""
    shape = S.shape[:2]
    T = np.zeros(shape + (3, 3))
    T[..., :d, :d] = S[..., layout[name]:layout[name] + d * d].reshape(shape + (d, d))
    if d == 2:
        T[..., 2, 2] = out_of_plane if out_of_plane is not None else S[..., layout["P33"]]
    return T


def _derive(names, W, F, P, a=None) -> dict:
    """The requested fields at every point from W (n, q), F and P (n, q, 3, 3) (and the cells' fibre
    directions a (n, 3), or None)."""
    out = {}
    if "fibre_stretch" in names:
        out["fibre_stretch"] = (np.zeros(W.shape) if a is None else
                                np.linalg.norm(np.einsum("nqab,nb->nqa", F, a), axis=-1))
    J = np.linalg.det(F)
    if "det_F_min" in names:
        out["det_F_min"] = J
    if "energy_density" in names:
        out["energy_density"] = W
    if {"cauchy_stress", "von_mises", "pressure"} & set(names):
        with np.errstate(divide="ignore", invalid="ignore"):     # J = 0: undefined, NaN (the caller decides)
            sigma = np.einsum("nqab,nqcb->nqac", P, F) / J[..., None, None]
        trace = np.trace(sigma, axis1=-2, axis2=-1)
        if "cauchy_stress" in names:
            out["cauchy_stress"] = sigma
        if "pressure" in names:
            out["pressure"] = -trace / 3.0
        if "von_mises" in names:
            s = sigma - trace[..., None, None] / 3.0 * np.eye(3)
            out["von_mises"] = np.sqrt(1.5 * np.einsum("nqab,nqab->nq", s, s))
    if {"principal_stretches", "green_lagrange"} & set(names):
        C = np.einsum("nqba,nqbc->nqac", F, F)
        if "principal_stretches" in names:
            eig = np.linalg.eigvalsh(C)[..., ::-1]          # ascending -> largest first
            out["principal_stretches"] = np.sqrt(np.maximum(eig, 0.0))
        if "green_lagrange" in names:
            out["green_lagrange"] = 0.5 * (C - np.eye(3))
    return out


def cell_regions(mesh) -> np.ndarray:
    """Per cell (global order): its block's tag, else the id of the first mesh volume group that
    holds it, else -1."""
    out = np.full(mesh.n_cells, -1, dtype=np.int64)
    start, tagged = 0, np.zeros(mesh.n_cells, bool)
    for block in mesh.blocks:
        stop = start + len(block)
        if block.tags is not None:
            out[start:stop] = block.tags
            tagged[start:stop] = True
        start = stop
    for group in getattr(mesh, "groups", ()):
        if group.dim != mesh.dim or group.id is None or not len(group.cell_ids):
            continue
        ids = np.asarray(group.cell_ids, dtype=np.int64)
        free = ids[(~tagged[ids]) & (out[ids] < 0)]
        out[free] = group.id
    return out


def evaluate(model, u, names=None, providers=None) -> tuple:
    """(point fields, cell fields) of a model at displacement u; names None: the scene's
    [output] fields (see resolve). A one-off evaluation (Simulation keeps a FieldEvaluator)."""
    return FieldEvaluator(model).evaluate(u, resolve(model, names), providers)
