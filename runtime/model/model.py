"""The discrete model: a mesh cut into kernel "parts", masses, constraints and loads.

    model = Model.from_scene(scene)           # or Model(mesh, materials, fixed=..., loads=...)
    model.parts[0].kernel, model.parts[0].D   # one (element, law, quadrature) group each

Dofs are node-major: dof = node * dofs_per_node + component (runtime.base.dofs: dofs_per_node is
the space dimension for solids, the element table's count for bars, springs, shells; the
first dim dofs of a node are its displacement where it has that many).  Everything here is built
once; the integrators only read it.  Only the kernels a scene needs are loaded
(`Model.required_kernels`), and only the outputs its integrator declares
(`runtime.physics.integrators`, e.g. `Static.outputs`) are compiled (`Model.warm_up`).
Which material models each cell and which nodes a box holds come from runtime.mesh.regions.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ... import elements as _element_types
from ... import laws
from ..kernels import custom_kernels as _custom
from ..mesh import fibres as _fibres
from ..kernels import kernels as _kernels
from ..scene import resources
from ..base.dofs import dofs_per_node as _dofs_per_node
from ..base.dofs import node_dofs, split_nodal
from ..base import integrator_kinds
from ..base.errors import ElementError, TensormassError
from ..assembly import loads as _loads
from ..physics.integrators import outputs_for
from ..assembly.mass import MassMatrix
from ..assembly.pressure import FollowerPressure
from ..mesh.container import Mesh, block_offsets
from ..mesh.checks import check_mesh
from ..physics.motion import Motion
from ..mesh.probes import PointProbe, locate_point
from ..mesh.regions import (assign_materials as _assign, box_contains, box_tolerance, find_group, material_groups,
    prescribed_values, reachable_laws, region_faces, selection_nodes, switch_parameters)
from ..scene.types import Loads, Output, Solver
from ..scene.formulation_check import check_element as _check_formulation_element, formulation_name
from ..assembly.volumetric import VolumetricCoupling, volumetric_functions
from ..assembly.mixed import MixedCoupling
from ..scene.mesh_source import build_mesh, scene_mesh
from ..kernels.corotational import CorotationalShell
from ..physics.hanging import HangingNodes
from ..physics.volume_constraint import VolumeConstraint

# outputs_for (runtime.physics.integrators), build_mesh and scene_mesh (runtime.scene.mesh_source) are kept
# importable from here.
__all__ = ["Model", "Part", "LawGroup", "outputs_for", "build_mesh", "scene_mesh", "assign_materials"]


@dataclass
class Part:
    """All cells sharing one (element, law, quadrature) kernel."""
    element: str
    law: str
    quadrature: str
    kernel: object               # runtime.kernels.kernels.Kernel
    cells: np.ndarray            # (n, k) node ids
    cell_ids: np.ndarray         # (n,) global cell ids, for messages
    D: np.ndarray                # (n, n_constants) per-element constants
    volume: np.ndarray           # (n,) rest volumes (areas in 2D)
    dofs: np.ndarray             # (n, k * dofs_per_node) global dofs, node-major
    density: np.ndarray          # (n,) mass density of each cell
    active: np.ndarray | None = None   # (n,) bool: cells this law currently models (None: all)
    rotary: np.ndarray | None = None   # (n,) rotary inertia per unit mass (m^2) of nodes with rotations (shells)
    # viscous parts (laws/viscous.py): (tau, beta), each (n, n_branches), of their Prony branches
    branches: tuple | None = None
    fibres: np.ndarray | None = None   # (n, 3) unit fibre direction of a law with directions (laws/hgo.py)
    # per cell and node: its lumped mass and its share of the body force integral int N_a rho dV
    # (zero rows for inactive cells), kept so a topology change re-sums nodes locally (runtime.change.cutting)
    cell_masses: np.ndarray | None = None
    cell_shares: np.ndarray | None = None
    # after a cut, a removal or a refinement (runtime.change): the row each cell had (or its parent
    # had: origin_split) in the part before, so that per-cell state (the viscous history) follows it;
    # None: a part built from the scene
    origin_rows: np.ndarray | None = None
    origin_split: np.ndarray | None = None     # (n,) bool: the cell is a child of a split cell

    def __post_init__(self):
        if self.active is None:
            self.active = np.ones(len(self.cells), dtype=bool)
        self._refresh()

    def _refresh(self):
        self.n_active = int(np.count_nonzero(self.active))
        everything = self.n_active == len(self.cells)
        # None when every cell is active: the common case pays no gather
        self.index = None if everything else np.flatnonzero(self.active)
        self.D_active = self.D if everything else self.D[self.index]
        self.cells_active = self.cells if everything else self.cells[self.index]
        self.dofs_active = self.dofs if everything else self.dofs[self.index]
        self.cell_ids_active = self.cell_ids if everything else self.cell_ids[self.index]

    def set_active(self, mask: np.ndarray) -> None:
        """Change which cells this part's law models (law switching); constants are kept for all."""
        self.active = np.asarray(mask, dtype=bool).copy()
        self._refresh()

    @property
    def key(self) -> tuple:
        return (self.element, self.law, self.quadrature)

    def __len__(self) -> int:
        return len(self.cells)


@dataclass
class LawGroup:
    """Parts that share the same cells under different laws; each cell is active in exactly one.

    Built for the cells a switch_law rule can reach: parts[0] is the material's own law.
    `current[c]` indexes `laws` (and `parts`) for cell c of the group; `previous[c]` is the
    law it had before its last switch (where a switch-back returns it).
    """
    parts: list                  # indices into Model.parts
    laws: list                   # law name of each of those parts
    current: np.ndarray          # (n,) int
    previous: np.ndarray | None = None

    def __post_init__(self):
        if self.previous is None:
            self.previous = self.current.copy()

    def switch(self, model, cells: np.ndarray, law: str) -> int:
        """Move the given group-local cells to `law`; returns how many changed."""
        target = self.laws.index(law)
        changed = cells[self.current[cells] != target]
        if changed.size:
            self.previous[changed] = self.current[changed]
            self.current[changed] = target
            for k, i in enumerate(self.parts):
                model.parts[i].set_active(self.current == k)
        return int(changed.size)


@dataclass
class _Formulated:
    """Cells of a part under a locking-free formulation, until their coupling is built."""
    formulation: str
    rows: np.ndarray             # part-local cell indices
    materials: np.ndarray        # material index of each of those cells
    law: str
    part: int = -1               # its part's index in Model.parts
    full_params: dict | None = None   # the law's parameters per cell of the part (U needs the bulk one)

    def deviatoric(self, params: dict) -> dict:
        """The part's parameters with the bulk one set to 0 on these cells: the kernel then integrates W_dev."""
        bulk = volumetric_functions(self.law)[0]
        out = dict(params)
        out[bulk] = np.array(params[bulk], dtype=float, copy=True)
        out[bulk][self.rows] = 0.0
        return out


def _check_incompressible(law: str, values: dict, m: int) -> None:
    """At nu = 0.5 only the bulk parameter of the law's volumetric split may be infinite: the mixed
    formulation replaces that part; a law whose other parameters blow up cannot be incompressible."""
    infinite = [p for p, v in values.items() if np.any(np.isinf(v))]
    if not infinite:
        return
    bulk = volumetric_functions(law)[0]
    if infinite != [bulk]:
        raise TensormassError(f"material {m}: law {law!r} at nu = 0.5 makes {', '.join(p for p in infinite if p != bulk)} "
                              f"infinite, not only its bulk parameter {bulk!r}: it cannot be made incompressible")


# --------------------------------------------------------------------------- mesh and materials


def _element_dim(cell_type: str) -> int:
    return _element_types.get(cell_type).dim


def _size(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) else 1.0


def _material_kernels(mesh, materials, adapt, index) -> set:
    """(element, law, quadrature) of every kernel the materials need on this mesh: each law that adapt
    rules can switch a group to, and the volume measure of a material under a locking-free formulation."""
    triples = set()
    for (element, law, quad), members in material_groups(mesh, materials, index).items():
        if _viscous_members(materials, members):
            law = laws.kernel_law(law + _VISCOUS).name
        triples.update((element, reach, quad) for reach in reachable_laws(law, adapt))
        if any(getattr(materials[m], "formulation", "displacement") != "displacement" for _, _, m in members):
            triples.add((element, volumetric_functions(law)[1], quad))
    return triples


def _first_direction(law: str, params: dict):
    """(n, 3) the first fibre direction of a law with directions, per cell (the fibre_stretch field)."""
    names = laws.get(law).directions
    return np.column_stack([params[f"{names[0]}_{c}"] for c in "xyz"]) if names else None


_VISCOUS = "_viscous"                 # laws/viscous.py: NAME_viscous


def _viscous_members(materials, members) -> bool:
    """Whether a material of these cells has Prony branches ([[material]] viscous)."""
    return any(getattr(materials[m], "viscous", None) for _, _, m in members)


def _shell_kernel(kernel, law: str, flags: list):
    """The co-rotational wrapper around a linear shell kernel (runtime.kernels.corotational) where the
    materials ask for it (option corotational = 1, the default); corotational = 0: the kernel itself."""
    flag = np.asarray(flags, float)
    if np.any(flag != flag.flat[0]):
        raise TensormassError(f"law {law!r}: materials of the same cells mix corotational = 0 and 1; "
                              "give every shell material the same value")
    if flag.flat[0] == 0:
        return kernel
    return CorotationalShell(kernel)


def assign_materials(mesh: Mesh, materials) -> list:
    """Per block, the index of the first matching material of every cell; cells without one are refused."""
    return _assign(mesh, materials, complete=True)


# --------------------------------------------------------------------------- the model


class Model:
    """Everything an integrator needs: parts with kernels and constants, masses, constraints, loads."""

    def __init__(self, mesh: Mesh, materials, fixed=(), loads: Loads | None = None, probes=(),
                 solver: Solver | None = None, output: Output | None = None, name: str = "model",
                 check: bool = True, adapt=(), max_memory=None, amplitudes=()):
        start = time.perf_counter()
        materials, adapt = list(materials), list(adapt)
        self.solver = solver if solver is not None else Solver()
        self.max_memory = max_memory
        # before anything scales with the mesh (check_mesh's face tables, constants, pattern)
        self.estimate = resources.estimate(resources.MeshCounts.of_mesh(mesh), materials=materials,
                                           solver=self.solver, adapt=adapt, refinement=False)
        resources.check(self.estimate, max_memory, what=f"model {name!r}")
        if check:
            check_mesh(mesh)
        self.mesh, self.name = mesh, name
        self.materials = materials
        self._specs = (list(fixed), list(probes))          # kept for rebuilt()
        self.output = output if output is not None else Output()
        self.loads = loads if loads is not None else Loads()
        self.dim, self.n_points = mesh.dim, mesh.n_points
        self.dofs_per_node = _dofs_per_node(mesh)
        self.n_dofs = self.n_points * self.dofs_per_node
        # components of a load or prescribed-displacement vector: the displacement dofs
        self.n_load = min(self.dim, self.dofs_per_node)
        self._check_dof_loads(adapt)
        self._check_discrete(materials, adapt)
        self.size = _size(mesh.points)
        self.box_tol = box_tolerance(mesh.points)
        self.outputs = outputs_for(self.solver.kind)
        self.adapt = adapt
        self.groups: list = []                     # LawGroup per set of switchable cells
        self._pending_couplings: list = []
        self.parts = self._build_parts()
        # locking-free formulations: the volumetric energy of formulated cells (runtime.assembly.volumetric)
        self.couplings = self._build_couplings()
        self.mass = self._lumped_mass()
        self.mass_matrix = self._mass_matrix      # runtime.assembly.mass.MassMatrix (solver.mass)
        self.fixed_dofs, self.prescribed = self._constraints(list(fixed))
        # hanging nodes of a locally refined hexahedral mesh (runtime.physics.hanging): neither free nor fixed
        self.hanging = self._hanging_nodes()
        unknown = self.fixed_dofs if self.hanging is None else np.union1d(self.fixed_dofs, self.hanging.slave_dofs)
        self.free_dofs = np.setdiff1d(np.arange(self.n_dofs), unknown)
        self.f_ext = self._external_forces()
        self.pressure = self._pressure_loads()    # runtime.assembly.pressure.FollowerPressure or None
        self.volume_constraint = self._volume_constraint()   # (VolumeConstraint, free node mask) or None
        # prescribed displacements and loads over time: amplitudes, rigid motions (runtime.physics.motion)
        self.amplitudes = list(amplitudes)
        self.motion = Motion(self, list(fixed), self.amplitudes)
        self.probes = {p.name: self._probe(p, i) for i, p in enumerate(probes)}   # runtime.mesh.probes.PointProbe
        self.scene = None
        self.contact = None                 # runtime.contact: IPC or penalty contact (Model.from_scene)
        self.build_time = time.perf_counter() - start

    @classmethod
    def from_scene(cls, scene, mesh: Mesh | None = None) -> "Model":
        """Build the mesh (unless given) and the model of a Scene."""
        built = mesh is None                       # scene_mesh has checked it already
        mesh = scene_mesh(scene) if built else mesh
        model = cls(mesh, scene.materials, scene.fixed, scene.loads, scene.probes, scene.solver,
                    scene.output, scene.name, check=not built, adapt=getattr(scene, "adapt", ()),
                    max_memory=getattr(scene, "max_memory", None), amplitudes=getattr(scene, "amplitudes", ()))
        # the scene's estimate covers the whole run (refinement included) when it has one
        model.estimate = getattr(scene, "estimate", None) or model.estimate
        model.scene = scene
        # [contact] / [[obstacle]] (runtime.contact): refused here, before the first step, when the body
        # starts intersecting an obstacle or the solver does not take the method
        from ..contact.build import build_contact
        model.contact = build_contact(model)
        return model

    def rebuilt(self, mesh: Mesh, check: bool = True) -> "Model":
        """The same scene on another mesh (after refinement): parts, masses, constraints and loads anew.
        check=False: the mesh is known valid (a 1:8 refinement's hanging nodes, which check_mesh refuses)."""
        fixed, probes = self._specs
        model = Model(mesh, self.materials, fixed, self.loads, probes, self.solver, self.output, self.name,
                      adapt=self.adapt, max_memory=self.max_memory, amplitudes=self.amplitudes, check=check)
        model.scene = self.scene
        return model

    def set_cell_laws(self, names) -> None:
        """Put every cell of a switchable group under the law named for it (global cell order)."""
        for group in self.groups:
            want = np.asarray(names)[self.parts[group.parts[0]].cell_ids]
            for k, law in enumerate(group.laws):
                cells = np.flatnonzero(want == law)
                if cells.size:
                    group.switch(self, cells, law)

    @staticmethod
    def required_kernels(scene, mesh: Mesh | None = None) -> set:
        """The exact set of (element, law, quadrature, outputs) a scene needs (loads nothing)."""
        mesh = scene_mesh(scene) if mesh is None else mesh
        index = assign_materials(mesh, scene.materials)
        outputs = outputs_for(scene.solver.kind)
        return {(*triple, outputs) for triple in _material_kernels(mesh, scene.materials, getattr(scene, "adapt", ()), index)}

    # -- parts ---------------------------------------------------------------------------------
    def _build_parts(self) -> list:
        index = assign_materials(self.mesh, self.materials)
        self._prepare_kernels(index)
        offsets = np.concatenate([[0], np.cumsum([len(b) for b in self.mesh.blocks])])
        parts = []
        for (element, law, quad), members in material_groups(self.mesh, self.materials, index).items():
            cells = np.vstack([self.mesh.blocks[b].cells[ids] for b, ids, _ in members])
            cell_ids = np.concatenate([offsets[b] + ids for b, ids, _ in members])
            dofs = node_dofs(cells, self.dofs_per_node, self._element_dofs(element))
            rho = np.concatenate([np.full(len(ids), float(self.materials[m].density)) for _, ids, m in members])
            branches = None
            if _viscous_members(self.materials, members):   # laws/viscous.py: the step energy's kernel
                branches = self._branches(law, members)
                law = laws.kernel_law(law + _VISCOUS).name
            reach = reachable_laws(law, self.adapt)
            if branches is not None and len(reach) > 1:
                raise TensormassError(f"law {law!r}: viscous materials cannot switch laws ([[adapt]] switch_law)")
            first = len(parts)
            formulated = self._formulated(element, law, members, reach)
            for k, name in enumerate(reach):
                # a module attribute lookup, so tests can spy on which kernels get loaded
                kernel = _custom.registered_kernel(element, name, quad)
                if kernel is None:
                    kernel = _kernels.load_kernel(element, name, quad, backend=self.solver.backend)
                self._check_kernel_dofs(kernel, element, cells)
                params = self._parameters(name, members)
                if laws.is_shell(name):
                    flags = [float(dict(self.materials[m].params).get("corotational", 1.0)) for _, _, m in members]
                    kernel = _shell_kernel(kernel, name, flags)
                if formulated is not None:
                    formulated.part, formulated.full_params = len(parts), params
                    params = formulated.deviatoric(params)
                D = self._constants(kernel, cells, cell_ids, params)
                volume = kernel.point_volumes(D).sum(axis=1)       # the layout from the kernel's metadata
                active = np.full(len(cells), k == 0)
                # a shell node's rotary inertia per unit mass: h^2 / 12 (runtime.assembly.mass)
                rotary = params["thickness"] ** 2 / 12 if laws.is_shell(name) else None
                parts.append(Part(element, name, quad, kernel, cells, cell_ids, D, volume, dofs, rho, active,
                                  rotary=rotary, branches=branches, fibres=_first_direction(name, params)))
            if len(reach) > 1:
                self.groups.append(LawGroup(list(range(first, len(parts))), list(reach),
                                            np.zeros(len(cells), dtype=np.int64)))
            if formulated is not None:
                self._pending_couplings.append(formulated)
        return parts

    def _prepare_kernels(self, index) -> None:
        """Get the generated kernels the parts will load ready at once (C: the missing libraries
        compiled in parallel, one compiler per core), the formulations' measure kernels included."""
        triples = [t for t in _material_kernels(self.mesh, self.materials, self.adapt, index)
                   if _custom.registered_kernel(*t) is None]
        _kernels.prepare_kernels(triples, self.solver.backend)

    def _formulated(self, element, law, members, reach):
        """The cells of this part a locking-free formulation models (runtime.assembly.volumetric), or None."""
        rows, start, names, mats = [], 0, set(), []
        for _, ids, m in members:
            key = f"material[{m}].formulation"
            name = formulation_name(getattr(self.materials[m], "formulation", "displacement"), key)
            if name != "displacement":
                _check_formulation_element(key, name, element)      # the scene's check, for Models built directly
                if self.shells:
                    raise TensormassError(f"{key} = {name!r}: the locking-free formulations are not available for "
                                          "solids beside shells (their volumetric terms read 3 dofs a node); use "
                                          "formulation = \"displacement\" there")
                rows.append(np.arange(start, start + len(ids)))
                mats.append(np.full(len(ids), m))
                names.add(name)
            start += len(ids)
        if not rows:
            return None
        if "mixed" in names and len(names) > 1:
            raise TensormassError(f"law {law!r} on {element}: formulation 'mixed' and {sorted(names - {'mixed'})[0]!r} "
                                  "in one part (materials of one law and element): give them the same formulation")
        if len(reach) > 1:
            raise TensormassError(f"law {law!r} on {element}: the formulation {sorted(names)[0]!r} cannot be "
                                  "combined with [[adapt]] switch_law rules (not supported yet)")
        return _Formulated(sorted(names)[0], np.concatenate(rows), np.concatenate(mats), law)

    def _build_couplings(self) -> list:
        pending, self._pending_couplings = self._pending_couplings, []
        return [MixedCoupling(self, p.part, p.rows, p.full_params, p.materials) if p.formulation == "mixed" else
                VolumetricCoupling(self, p.part, p.rows, p.formulation, p.full_params, p.materials) for p in pending]

    def _parameters(self, law: str, members) -> dict:
        """Native law parameters, one value per cell (materials may differ within a part)."""
        columns: dict = {}
        for b, ids, m in members:
            mat = self.materials[m]
            try:
                if law in (mat.law, mat.law + _VISCOUS):     # its own law, or its viscous step energy
                    mixed = getattr(mat, "formulation", "") == "mixed" and mat.nu is not None
                    extra = {"incompressible": True} if mixed else {}
                    values = laws.get(law).native_parameters(E=mat.E, nu=mat.nu, **extra, **dict(mat.params))
                    _check_incompressible(law, values, m)
                else:                              # a law a switch_law rule can reach
                    values = switch_parameters(mat, law)
            except (laws.LawError, TensormassError) as exc:
                raise TensormassError(f"material {m} ({law}): {exc}") from None
            values.update(self._fibre_inputs(law, mat, m, b, ids))
            for p, v in values.items():
                columns.setdefault(p, []).append(np.broadcast_to(v, (len(ids),)))
        return {p: np.concatenate(v) for p, v in columns.items()}

    def _branches(self, law: str, members) -> tuple:
        """(tau, beta), each (n_cells, n_branches), of the Prony branches of these cells' materials
        (a material without them, or with fewer: beta = 0, no viscosity)."""
        specs = [tuple(getattr(self.materials[m], "viscous", None) or ()) for _, _, m in members]
        n_branches = max(len(spec) for spec in specs)
        tau, beta = [], []
        for (_, ids, _), spec in zip(members, specs):
            padded = list(spec) + [(1.0, 0.0)] * (n_branches - len(spec))
            tau.append(np.tile([t for t, _ in padded], (len(ids), 1)))
            beta.append(np.tile([b for _, b in padded], (len(ids), 1)))
        return np.vstack(tau).astype(float), np.vstack(beta).astype(float)

    def _fibre_inputs(self, law: str, mat, m: int, block: int, ids) -> dict:
        """The direction components a law with fibres receives (runtime.mesh.fibres), per cell."""
        names = laws.get(law).directions
        if not names:
            return {}
        entries = getattr(mat, "fibres", None) or ()
        if len(entries) != len(names):
            raise TensormassError(f"material {m} ({law}): needs {len(names)} fibre direction(s) "
                                  f"({', '.join(names)}): [[material]] fibres")
        cells = self.mesh.blocks[block].cells[ids]
        centroids = self.mesh.points[cells].mean(axis=1)
        cell_ids = sum(len(b) for b in self.mesh.blocks[:block]) + np.asarray(ids)
        out = {}
        for name, entry in zip(names, entries):
            a = _fibres.directions(entry, centroids, f"material[{m}].fibres ({name})", cell_ids,
                                   getattr(self.mesh, "cell_data", None))
            out.update({f"{name}_{c}": a[:, k] for k, c in enumerate("xyz")})
        return out

    def _constants(self, kernel, cells, cell_ids, params) -> np.ndarray:
        try:
            return kernel.constants(self.mesh.points[cells], **params)
        except ElementError as exc:
            # report global cell ids, not the part-local ones the kernel saw
            message = str(exc).rsplit(": element(s)", 1)[0]
            raise type(exc)(message, cell_ids[exc.elements]) from None

    # -- masses, constraints, loads ------------------------------------------------------------
    def _lumped_mass(self) -> np.ndarray:
        """Per-dof lumped mass (runtime.assembly.mass): row sums of the consistent element masses for
        linear elements (the equal split on simplices), HRZ for quadratic ones; every cell once."""
        kind = getattr(self.solver, "mass", "lumped")
        self._mass_matrix = MassMatrix.build(self.mesh.points, self.parts, self.dofs_per_node, kind)
        return self._mass_matrix.lumped

    def _nodes_in(self, box, what: str) -> np.ndarray:
        nodes = np.flatnonzero(box_contains(box, self.mesh.points, self.box_tol))
        if nodes.size == 0:
            raise TensormassError(f"{what}: no node inside box {box!r}")
        return nodes

    def _vector(self, value, what: str, n: int | None = None) -> np.ndarray:
        n = self.n_load if n is None else n
        v = np.asarray(value, dtype=float).reshape(-1)
        if v.size < n or not np.all(np.isfinite(v)):
            raise TensormassError(f"{what} must be a finite vector of {n} components, got {value!r}")
        return v[:n]

    def _constraints(self, fixed) -> tuple:
        """Sorted fixed dofs and the full prescribed displacement of each (at load factor 1)."""
        for i, fx in enumerate(fixed):
            if getattr(fx, "region", None) is not None:     # a mesh group: runtime.mesh.regions
                selection_nodes(self.mesh, fx, f"fixed[{i}]", self.box_tol)
            else:
                self._nodes_in(fx.box, f"fixed[{i}]")
            n = self.dofs_per_node
            comps = np.arange(n) if fx.components is None else np.asarray(fx.components, dtype=int)
            if comps.size == 0 or comps.min() < 0 or comps.max() >= n:
                raise TensormassError(f"fixed[{i}].components must be in 0..{n - 1}, got {fx.components!r}")
            if fx.displacement is not None:
                # shells: the displacement's 3 components; their prescribed rotations are zero
                need = self.n_load if self.shells else max(self.n_load, int(comps.max()) + 1)
                self._vector(fx.displacement, f"fixed[{i}].displacement", need)
        # entries that give one dof different values are refused there (the order would decide)
        value, self.fixed_owner = prescribed_values(fixed, self.mesh.points, self.box_tol, self.dofs_per_node,
                                                    mesh=self.mesh)
        target = value.ravel()
        self.n_user_fixed = int(np.count_nonzero(~np.isnan(target)))
        # dofs no cell uses (the nodes of no cell; a solid node's rotations beside shells) carry no
        # mass and no stiffness: pin them so systems stay regular
        used = np.zeros(self.n_dofs, bool)
        for part in self.parts:
            used[part.dofs.ravel()] = True
        orphan = np.flatnonzero(~used)
        target[orphan] = np.where(np.isnan(target[orphan]), 0.0, target[orphan])
        dofs = np.flatnonzero(~np.isnan(target))
        return dofs, target[dofs]

    def _hanging_nodes(self):
        """The hanging-node constraints of a refined mesh (runtime.physics.hanging), or None."""
        if getattr(self.mesh, "midpoints", None) is None:
            return None
        hanging = HangingNodes.of(self.mesh, self.dofs_per_node, self.fixed_dofs)
        if hanging is not None and not integrator_kinds.get(self.solver.kind).hanging_nodes:
            raise TensormassError(f"solver.kind = {self.solver.kind!r}: a mesh with hanging nodes (hexahedra "
                                  "refined 1:8 next to whole ones) needs implicit_euler, backward_euler or static "
                                  "(its mass is not diagonal on the constrained dofs)")
        if hanging is not None and getattr(self, "couplings", None):
            raise TensormassError("hanging nodes cannot be combined with a locking-free formulation yet")
        return hanging

    def _external_forces(self) -> np.ndarray:
        """Consistent loads (runtime.assembly.loads): gravity f_a = int N_a rho g dV, tractions int N_a t dA."""
        g = self._vector(self.loads.gravity, "loads.gravity")
        f = np.zeros(self.n_dofs)
        # gravity's share and the loaded faces, kept for local updates after a topology change (runtime.change.cutting)
        self._body = np.zeros((self.n_points, self.n_load))
        self._tractions = []
        if np.any(g):
            for part in self.parts:          # every cell once: in the part whose law models it
                rows = np.flatnonzero(part.active)
                shares = _loads.volume_shares(self.mesh.points, part.element, part.cells[rows], part.density[rows],
                                              measure=part.volume[rows])
                np.add.at(self._body, part.cells[rows], shares[:, :, None] * g)
                part.cell_shares = np.zeros(part.cells.shape)
                part.cell_shares[rows] = shares
            self._loaded(f)[:] += self._body
        for i, load in enumerate(self.loads.nodal):
            force = self._vector(load.force, f"loads.nodal[{i}].force")
            if load.kind == "moment":
                self._add_moment(f, load, force, i)
                continue
            if getattr(load, "region", None) is not None:   # a mesh group (and box): runtime.mesh.regions
                self._add_region_load(self._loaded(f), load, force, i)
                continue
            if load.kind == "force":
                nodes = self._nodes_in(load.box, f"loads.nodal[{i}]")
                self._loaded(f)[nodes] += force / nodes.size
            elif load.kind == "traction":
                self._add_traction(self._loaded(f), load.box, force, i)
            else:
                raise TensormassError(f"loads.nodal[{i}].kind must be 'force' or 'traction', got {load.kind!r}")
        return f

    def _add_moment(self, f, load, moment, i):
        """A total moment split evenly over the selected nodes' rotation dofs (shells: dofs 3..5)."""
        if self.dofs_per_node != 2 * self.dim:
            raise TensormassError(f"loads.moment: the nodes carry no rotations ({self.dofs_per_node} dofs per node); "
                                  "moments load shells (element = \"shell\")")
        nodes = selection_nodes(self.mesh, load, f"loads.moment[{i}]", self.box_tol) \
            if getattr(load, "region", None) is not None else self._nodes_in(load.box, f"loads.moment[{i}]")
        f.reshape(self.n_points, self.dofs_per_node)[nodes, self.dim:] += moment / nodes.size

    def _add_traction(self, f, box, traction, i):
        """Traction per unit area on the boundary faces inside the box: f_a = int N_a t dA (consistent)."""
        faces = self._faces_in(box)
        if not faces:
            raise TensormassError(f"loads.nodal[{i}] (traction): no boundary face inside box {box!r}")
        f += _loads.traction(self.mesh.points, faces, traction)
        self._tractions.append((faces, traction))

    def _faces_in(self, box) -> dict:
        """{face type: (n, k)} boundary faces whose nodes all lie inside the box (runtime.assembly.loads)."""
        return region_faces(self.mesh, box=box, tol=self.box_tol)      # boundary cached on the mesh

    def _pressure_loads(self):
        """Follower pressures ([[loads.pressure]]) on the boundary faces in their boxes, or None."""
        loads = []
        for i, load in enumerate(getattr(self.loads, "pressure", ())):
            value = float(load.value)
            if not np.isfinite(value):
                raise TensormassError(f"loads.pressure[{i}].value must be a finite number, got {load.value!r}")
            faces = self._pressure_faces(load, f"loads.pressure[{i}]")
            if not faces:
                where = f"in region {load.region!r}" if getattr(load, "region", None) is not None else f"inside box {load.box!r}"
                raise TensormassError(f"loads.pressure[{i}]: no boundary face {where}")
            amplitude = getattr(load, "amplitude", None)
            if amplitude is not None and not integrator_kinds.get(self.solver.kind).dynamic:
                raise TensormassError(f"loads.pressure[{i}].amplitude: a static run ramps its pressures with the load "
                                      "factor; amplitudes over time need a dynamic solver.kind")
            loads.append((faces, value, amplitude))
        if not loads:
            return None
        pressure = FollowerPressure(self.mesh.points, loads, self.dim, self.dofs_per_node)
        # open surfaces: the full (non-symmetric) stiffness unless CG (symmetric only) solves
        pressure.symmetric = pressure.closed or self.solver.linear in ("cg", "amg")
        return pressure

    def _volume_constraint(self):
        """solver.preserve_volume: the closed shell surface's exact volume projection
        (runtime.physics.volume_constraint), with the nodes whose displacement is prescribed left in place."""
        if not getattr(self.solver, "preserve_volume", False):
            return None
        if not self.shells:
            raise TensormassError("solver.preserve_volume: needs a closed shell surface (element = \"shell\"); "
                                  "a solid keeps its volume through its law (nu -> 0.5, a formulation)")
        cells = np.vstack([b.cells for b in self.mesh.blocks if b.type == "shell"])
        try:
            constraint = VolumeConstraint(cells, self.mesh.points)
        except ValueError as exc:
            raise TensormassError(f"solver.preserve_volume: {exc}") from None
        held = np.zeros((self.n_points, self.dofs_per_node), dtype=bool)
        held.reshape(-1)[self.fixed_dofs] = True
        free = (~held[:, :self.dim]).astype(float)           # per node and component: 0 where prescribed
        return constraint, free

    @property
    def shells(self) -> bool:
        """A shell mesh: its triangles are the surface (pressure acts on them, against their normal)."""
        return any(b.type == "shell" for b in self.mesh.blocks)

    @property
    def solids(self) -> bool:
        """The mesh has cells other than shells (alone, or beside shells: runtime.mesh.shells_and_solids)."""
        return any(b.type != "shell" for b in self.mesh.blocks)

    def _pressure_faces(self, load, key) -> dict:
        """{face type: faces} a pressure acts on: shell triangles (of a shell group; every one in the box),
        the solid's boundary faces (of a boundary or volume group; every one in the box), or, with no
        region beside solids, both."""
        region = getattr(load, "region", None)
        whole = region in (None, "all")
        group = None if whole or not self.shells else self._shell_group(region, f"{key}.region")
        on_shells = self.shells and (whole or group is not None)
        faces = self._shells_in(load, group) if on_shells else {}
        if self.solids and (whole or not on_shells):
            solid = region_faces(self.mesh, None if whole else region, load.box, key=f"{key}.region",
                                 tol=self.box_tol, what="a pressure")
            for kind, rows in solid.items():
                faces[kind] = np.vstack([faces[kind], rows]) if kind in faces else rows
        return faces

    def _shell_group(self, region, key):
        """The shell group a region names (refused when it names none on a shell mesh), or None beside
        solids when the region is one of the solid's."""
        if not self.solids:
            return find_group(self.mesh, region, key, dims=(2,), what="a shell load")
        group = find_group(self.mesh, region, key)
        return group if group.dim == 2 and group.cell_ids.size else None

    def _shells_in(self, load, group) -> dict:
        """{"triangle": the shell cells of a group (None: all) whose nodes are all inside the load's box
        (all of them without one)}."""
        i = next(i for i, b in enumerate(self.mesh.blocks) if b.type == "shell")   # one shell block
        cells = self.mesh.blocks[i].cells
        if group is not None:
            ids = group.cell_ids - block_offsets(self.mesh)[i]
            cells = cells[ids[(ids >= 0) & (ids < len(cells))]]
        if load.box is not None:
            inside = box_contains(load.box, self.mesh.points, self.box_tol)
            cells = cells[inside[cells].all(axis=1)]
        return {"triangle": cells} if len(cells) else {}

    def _add_region_load(self, f, load, value, i):
        """A force (split evenly over the region's nodes) or a traction (f_a = int N_a t dA over the
        region's boundary faces, runtime.assembly.loads) on a mesh region (and box)."""
        key = f"loads.nodal[{i}]"
        if load.kind == "force":
            nodes = selection_nodes(self.mesh, load, key, self.box_tol)
            f[nodes] += value / nodes.size
            return
        faces = region_faces(self.mesh, load.region, load.box, key=f"{key}.region", tol=self.box_tol,
                             what="a traction")
        if not faces:
            raise TensormassError(f"{key} (traction): region {load.region!r} has no boundary face")
        f += _loads.traction(self.mesh.points, faces, value)
        self._tractions.append((faces, value))

    def _probe(self, probe, i: int) -> PointProbe:
        """A point probe: the cell holding the point and its shape functions there; a region/box
        probe: the mean of its nodes (the same nodes/weights form, runtime.mesh.probes)."""
        if getattr(probe, "point", None) is not None:
            return locate_point(self.mesh, self._vector(probe.point, f"probe {probe.name!r} point", self.dim),
                                probe.name)
        nodes = selection_nodes(self.mesh, probe, f"probe[{i}]", self.box_tol)
        return PointProbe(probe.name, None, -1, nodes, np.full(nodes.size, 1.0 / nodes.size), np.zeros(0), 0.0)

    # -- helpers for the integrators ------------------------------------------------------------
    def element_displacements(self, part: Part, u: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """(n_active, k, dofs_per_node) nodal dofs of a part's active elements (pair with part.D_active).

        out: a preallocated (n_active, k, dofs_per_node) float64 array to gather into (no allocation)."""
        U = self.part_nodal(part, u)
        if out is None:
            return U[part.cells_active]
        return np.take(U, part.cells_active, axis=0, out=out, mode="clip")   # "clip": unbuffered

    def part_nodal(self, part: Part, u: np.ndarray) -> np.ndarray:
        """(n_points, w) the nodal dofs a part's cells read: all dofs_per_node, or beside shells a
        solid's displacement only (a view: a kernel reading it whole takes a copy)."""
        U = u.reshape(self.n_points, self.dofs_per_node)
        width = part.dofs.shape[1] // part.cells.shape[1]
        return U if width == self.dofs_per_node else U[:, :width]

    def warm_up(self, outputs=None) -> None:
        """Compile (or load from numba's cache) the kernel outputs the solver will call: outputs, or
        warm_up_outputs(part) of each part (numba compiles each output on its first call, 6 to 40 s
        cold; a C kernel is compiled whole when loaded, so this only loads it)."""
        for part in self.parts:
            D, u = part.D[:1], np.zeros((1, part.kernel.n_nodes, part.kernel.n_dofs // part.kernel.n_nodes))
            for name in outputs or self.warm_up_outputs(part):
                getattr(part.kernel, name)(D, u)
        for c in self.couplings:                  # the formulations' measure kernels (energy: every call)
            D, u = c.D[:1], np.zeros((1, c.kernel.n_nodes, self.dofs_per_node))
            for name in sorted({"energy", *(outputs or self.outputs)}):
                getattr(c.kernel, name)(D, u)

    def warm_up_outputs(self, part) -> tuple:
        """The kernel outputs a run calls on this part: the solver's outputs, except for a law
        quadratic in grad u under a solver that assembles K: the assembly builds its constant K once
        (runtime.assembly.assembly, Assembly.constant) and takes its energy and forces from K, so
        only its stiffness runs."""
        if "stiffness" in self.outputs and getattr(part.kernel, "quadratic_energy", False):
            return ("stiffness",)
        return tuple(self.outputs)

    @property
    def n_elements(self) -> int:
        """Cells of the mesh that carry a material (switchable cells counted once)."""
        return sum(p.n_active for p in self.parts)

    def kernel_info(self) -> list:
        """Kernels loaded; `elements` is how many cells each models now (0: reachable by switching)."""
        info = [{"element": p.element, "law": p.law, "quadrature": p.quadrature,
                 "backend": p.kernel.backend, "outputs": list(self.outputs), "elements": p.n_active}
                for p in self.parts]
        for c in self.couplings:           # a formulation's volume measure: the cells it covers
            p = self.parts[c.part_index]
            info.append({"element": p.element, "law": c.measure, "quadrature": p.quadrature,
                         "backend": c.kernel.backend, "outputs": list(self.outputs), "elements": len(c.rows),
                         "formulation": c.formulation, "of_law": c.law})
        return info

    def law_names(self) -> list:
        """Sorted names of the laws the parts carry: what a `law_id` indexes."""
        return sorted({p.law for p in self.parts})

    def cell_laws(self) -> np.ndarray:
        """The law name modelling every cell (object array, None where no material), global order."""
        out = np.full(self.mesh.n_cells, None, dtype=object)
        for p in self.parts:
            out[p.cell_ids_active] = p.law
        return out

    def cell_law(self) -> np.ndarray:
        """Law id of every cell: index into law_names(), -1 where no material."""
        ids = {law: i for i, law in enumerate(self.law_names())}
        return np.array([ids.get(law, -1) for law in self.cell_laws()], dtype=np.int64)

    def probe_values(self, u: np.ndarray) -> dict:
        """Each probe's interpolated displacement (the nodal values where nodes carry fewer dofs)."""
        U = self.nodal(u)
        U = U[:, :self.dim] if U.shape[1] > self.dim else U        # a shell's rotations: not probed
        return {name: probe.value(U).tolist() for name, probe in self.probes.items()}

    def probe_info(self) -> dict:
        """How each probe reads the body (for the summary): its point and cell, or its nodes."""
        out = {}
        for name, probe in self.probes.items():
            if probe.point is None:
                out[name] = {"how": f"mean of the {probe.nodes.size} nodes of its region/box"}
            else:
                out[name] = {"point": np.asarray(probe.point).tolist(), "cell": int(probe.cell),
                             "distance_outside": float(probe.distance),
                             "how": "interpolated at the point with the shape functions of the cell holding it"}
        return out

    # -- dofs that are not (only) displacements: bars, springs, shells (runtime.base.dofs) -------------
    def nodal(self, u: np.ndarray) -> np.ndarray:
        """(n_points, dofs_per_node) view of a global dof vector."""
        return u.reshape(self.n_points, self.dofs_per_node)

    def split_dofs(self, u: np.ndarray) -> tuple:
        """(displacement (n_points, dim), {name: extra point field}) of a global dof vector (runtime.base.dofs)."""
        return split_nodal(self.nodal(u), self.dim)

    def _loaded(self, x: np.ndarray) -> np.ndarray:
        """(n_points, n_load) view of a global dof vector: the dofs loads and gravity act on."""
        X = x.reshape(self.n_points, self.dofs_per_node)
        return X if self.n_load == self.dofs_per_node else X[:, :self.n_load]

    def _check_kernel_dofs(self, kernel, element: str, cells) -> None:
        """A kernel (generated or registered) must fit the element type and the model's dof layout."""
        k, per_node = cells.shape[1], self._element_dofs(element)
        if kernel.n_nodes != k or kernel.n_dofs != k * per_node or kernel.dim != self.dim:
            raise TensormassError(
                f"kernel {kernel!r} for {element}: {kernel.n_nodes} nodes, {kernel.n_dofs} dofs in {kernel.dim}D; "
                f"the model needs {k} nodes, {k * per_node} dofs ({per_node} per node) "
                f"in {self.dim}D")

    def _element_dofs(self, element: str) -> int:
        """Dofs per node an element type's cells use: its own count (a solid's: the dimension), the
        first of the node's dofs_per_node (runtime.base.dofs)."""
        el = _element_types.get(element)
        return el.n_dofs(self.dim) // el.n_nodes

    @staticmethod
    def _check_discrete(materials, adapt) -> None:
        """Discrete laws (springs, lattice cubes) have no integration points: [[adapt]] criteria and
        law switching, which read strains there, are refused with them."""
        discrete = sorted({m.law for m in materials if laws.is_discrete(m.law)}
                          | {r.law for r in adapt if getattr(r, "law", None) and laws.is_discrete(r.law)})
        if adapt and discrete:
            raise TensormassError(f"[[adapt]] rules cannot be used with the discrete law {discrete[0]!r} (a spring "
                                  "model has no integration points for their criteria, no law to switch to); "
                                  "remove the [[adapt]] rules or use a continuum law")

    def _check_dof_loads(self, adapt) -> None:
        """Refuse what a model whose dofs are not a displacement field cannot mean."""
        if self.dofs_per_node < self.dim:
            try:
                g = np.asarray(self.loads.gravity, dtype=float).reshape(-1)
            except (TypeError, ValueError):
                g = np.zeros(0)            # not a vector: _external_forces says so
            if np.any(g != 0):
                raise TensormassError(f"loads.gravity: the nodes carry {self.dofs_per_node} dof(s), not a "
                                      f"{self.dim}D displacement; gravity does not apply (use nodal forces)")
            for i, load in enumerate(self.loads.nodal):
                if load.kind == "traction":
                    raise TensormassError(f"loads.nodal[{i}] (traction): the nodes carry {self.dofs_per_node} "
                                          f"dof(s), not a {self.dim}D displacement; use kind = 'force'")
        solid = all(_element_dim(b.type) == self.dim for b in self.mesh.blocks)
        if adapt and not (solid and self.dofs_per_node == self.dim):
            raise TensormassError("[[adapt]] rules need solid elements (topological dimension = space dimension, "
                                  "dofs per node = dimension)")
