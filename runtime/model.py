"""The discrete model: a mesh cut into kernel "parts", masses, constraints and loads.

    model = Model.from_scene(scene)           # or Model(mesh, materials, fixed=..., loads=...)
    model.parts[0].kernel, model.parts[0].D   # one (element, law, quadrature) group each

Dofs are node-major: dof = node * dim + component.  Everything here is built
once; the integrators only read it.  Only the kernels a scene needs are loaded
(`Model.required_kernels`), and only the outputs its integrator declares
(`runtime.integrators`, e.g. `Static.outputs`) are compiled (`Model.warm_up`).
Which material models each cell and which nodes a box holds come from runtime.regions.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .. import laws
from . import kernels as _kernels
from . import resources
from .errors import ElementError, TensormassError
from .integrators import outputs_for
from .mesh import Mesh, boundary_faces, check_mesh
from .mesh import face_measure as _face_measure  # face types: the element table
from .regions import (assign_materials as _assign, box_contains, box_tolerance, material_groups,
                      prescribed_values, reachable_laws, switch_parameters)
from .scene import Loads, Output, Solver
from .scene_mesh import build_mesh, scene_mesh

# outputs_for (runtime.integrators), build_mesh and scene_mesh (runtime.scene_mesh) are kept
# importable from here.
__all__ = ["Model", "Part", "LawGroup", "outputs_for", "build_mesh", "scene_mesh", "assign_materials"]


@dataclass
class Part:
    """All cells sharing one (element, law, quadrature) kernel."""
    element: str
    law: str
    quadrature: str
    kernel: object               # runtime.kernels.Kernel
    cells: np.ndarray            # (n, k) node ids
    cell_ids: np.ndarray         # (n,) global cell ids, for messages
    D: np.ndarray                # (n, n_constants) per-element constants
    volume: np.ndarray           # (n,) rest volumes (areas in 2D)
    dofs: np.ndarray             # (n, k * dim) global dofs, node-major
    density: np.ndarray          # (n,) mass density of each cell
    active: np.ndarray | None = None   # (n,) bool: cells this law currently models (None: all)

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


# --------------------------------------------------------------------------- mesh and materials


def _size(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) else 1.0


def assign_materials(mesh: Mesh, materials) -> list:
    """Per block, the index of the first matching material of every cell; cells without one are refused."""
    return _assign(mesh, materials, complete=True)


# --------------------------------------------------------------------------- the model


class Model:
    """Everything an integrator needs: parts with kernels and constants, masses, constraints, loads."""

    def __init__(self, mesh: Mesh, materials, fixed=(), loads: Loads | None = None, probes=(),
                 solver: Solver | None = None, output: Output | None = None, name: str = "model",
                 check: bool = True, adapt=(), max_memory=None):
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
        self.n_dofs = self.n_points * self.dim
        self.size = _size(mesh.points)
        self.box_tol = box_tolerance(mesh.points)
        self.outputs = outputs_for(self.solver.kind)
        self.adapt = adapt
        self.groups: list = []                     # LawGroup per set of switchable cells
        self.parts = self._build_parts()
        self.mass = self._lumped_mass()
        self.fixed_dofs, self.prescribed = self._constraints(list(fixed))
        self.free_dofs = np.setdiff1d(np.arange(self.n_dofs), self.fixed_dofs)
        self.f_ext = self._external_forces()
        self.probes = {p.name: self._nearest_node(p.point) for p in probes}
        self.scene = None
        self.build_time = time.perf_counter() - start

    @classmethod
    def from_scene(cls, scene, mesh: Mesh | None = None) -> "Model":
        """Build the mesh (unless given) and the model of a Scene."""
        built = mesh is None                       # scene_mesh has checked it already
        mesh = scene_mesh(scene) if built else mesh
        model = cls(mesh, scene.materials, scene.fixed, scene.loads, scene.probes, scene.solver,
                    scene.output, scene.name, check=not built, adapt=getattr(scene, "adapt", ()),
                    max_memory=getattr(scene, "max_memory", None))
        # the scene's estimate covers the whole run (refinement included) when it has one
        model.estimate = getattr(scene, "estimate", None) or model.estimate
        model.scene = scene
        return model

    def rebuilt(self, mesh: Mesh) -> "Model":
        """The same scene on another mesh (after refinement): parts, masses, constraints and loads anew."""
        fixed, probes = self._specs
        model = Model(mesh, self.materials, fixed, self.loads, probes, self.solver, self.output, self.name,
                      adapt=self.adapt, max_memory=self.max_memory)
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
        keys = set()
        for (element, law, quad) in material_groups(mesh, scene.materials, index):
            for reach in reachable_laws(law, getattr(scene, "adapt", ())):
                keys.add((element, reach, quad, outputs))
        return keys

    # -- parts ---------------------------------------------------------------------------------
    def _build_parts(self) -> list:
        index = assign_materials(self.mesh, self.materials)
        offsets = np.concatenate([[0], np.cumsum([len(b) for b in self.mesh.blocks])])
        parts = []
        for (element, law, quad), members in material_groups(self.mesh, self.materials, index).items():
            cells = np.vstack([self.mesh.blocks[b].cells[ids] for b, ids, _ in members])
            cell_ids = np.concatenate([offsets[b] + ids for b, ids, _ in members])
            dofs = (cells[:, :, None] * self.dim + np.arange(self.dim)).reshape(len(cells), -1)
            rho = np.concatenate([np.full(len(ids), float(self.materials[m].density)) for _, ids, m in members])
            reach = reachable_laws(law, self.adapt)
            first = len(parts)
            for k, name in enumerate(reach):
                # a module attribute lookup, so tests can spy on which kernels get loaded
                kernel = _kernels.load_kernel(element, name, quad, backend=self.solver.backend)
                D = self._constants(kernel, cells, cell_ids, self._parameters(name, members))
                volume = kernel.point_volumes(D).sum(axis=1)       # the layout from the kernel's metadata
                active = np.full(len(cells), k == 0)
                parts.append(Part(element, name, quad, kernel, cells, cell_ids, D, volume, dofs, rho, active))
            if len(reach) > 1:
                self.groups.append(LawGroup(list(range(first, len(parts))), list(reach),
                                            np.zeros(len(cells), dtype=np.int64)))
        return parts

    def _parameters(self, law: str, members) -> dict:
        """Native law parameters, one value per cell (materials may differ within a part)."""
        columns: dict = {}
        for _, ids, m in members:
            mat = self.materials[m]
            try:
                if law == mat.law:
                    values = laws.get(law).native_parameters(E=mat.E, nu=mat.nu, **dict(mat.params))
                else:                              # a law a switch_law rule can reach
                    values = switch_parameters(mat, law)
            except (laws.LawError, TensormassError) as exc:
                raise TensormassError(f"material {m} ({law}): {exc}") from None
            for p, v in values.items():
                columns.setdefault(p, []).append(np.broadcast_to(v, (len(ids),)))
        return {p: np.concatenate(v) for p, v in columns.items()}

    def _constants(self, kernel, cells, cell_ids, params) -> np.ndarray:
        try:
            return kernel.constants(self.mesh.points[cells], **params)
        except ElementError as exc:
            # report global cell ids, not the part-local ones the kernel saw
            message = str(exc).rsplit(": element(s)", 1)[0]
            raise type(exc)(message, cell_ids[exc.elements]) from None

    # -- masses, constraints, loads ------------------------------------------------------------
    def _lumped_mass(self) -> np.ndarray:
        """Per-dof lumped mass: density x volume split equally over each element's nodes."""
        node_mass = np.zeros(self.n_points)
        for part in self.parts:
            share = np.where(part.active, part.density * part.volume / part.cells.shape[1], 0.0)
            np.add.at(node_mass, part.cells, np.broadcast_to(share[:, None], part.cells.shape))
        if np.any(node_mass < 0):
            raise TensormassError("negative density gives negative nodal masses")
        return np.repeat(node_mass, self.dim)

    def _nodes_in(self, box, what: str) -> np.ndarray:
        nodes = np.flatnonzero(box_contains(box, self.mesh.points, self.box_tol))
        if nodes.size == 0:
            raise TensormassError(f"{what}: no node inside box {box!r}")
        return nodes

    def _vector(self, value, what: str) -> np.ndarray:
        v = np.asarray(value, dtype=float).reshape(-1)
        if v.size < self.dim or not np.all(np.isfinite(v)):
            raise TensormassError(f"{what} must be a finite vector of {self.dim} components, got {value!r}")
        return v[:self.dim]

    def _constraints(self, fixed) -> tuple:
        """Sorted fixed dofs and the full prescribed displacement of each (at load factor 1)."""
        for i, fx in enumerate(fixed):
            self._nodes_in(fx.box, f"fixed[{i}]")
            comps = np.arange(self.dim) if fx.components is None else np.asarray(fx.components, dtype=int)
            if comps.size == 0 or comps.min() < 0 or comps.max() >= self.dim:
                raise TensormassError(f"fixed[{i}].components must be in 0..{self.dim - 1}, got {fx.components!r}")
            if fx.displacement is not None:
                self._vector(fx.displacement, f"fixed[{i}].displacement")
        # entries that give one dof different values are refused there (the order would decide)
        target = prescribed_values(fixed, self.mesh.points, self.box_tol)[0].ravel()
        self.n_user_fixed = int(np.count_nonzero(~np.isnan(target)))
        # nodes no cell uses carry no mass and no stiffness: pin them so systems stay regular
        used = np.zeros(self.n_points, bool)
        for part in self.parts:
            used[part.cells.ravel()] = True
        orphan = (np.flatnonzero(~used)[:, None] * self.dim + np.arange(self.dim)).ravel()
        target[orphan] = np.where(np.isnan(target[orphan]), 0.0, target[orphan])
        dofs = np.flatnonzero(~np.isnan(target))
        return dofs, target[dofs]

    def _external_forces(self) -> np.ndarray:
        f = (self.mass.reshape(-1, self.dim) * self._vector(self.loads.gravity, "loads.gravity")).ravel()
        for i, load in enumerate(self.loads.nodal):
            force = self._vector(load.force, f"loads.nodal[{i}].force")
            if load.kind == "force":
                nodes = self._nodes_in(load.box, f"loads.nodal[{i}]")
                f.reshape(-1, self.dim)[nodes] += force / nodes.size
            elif load.kind == "traction":
                self._add_traction(f.reshape(-1, self.dim), load.box, force, i)
            else:
                raise TensormassError(f"loads.nodal[{i}].kind must be 'force' or 'traction', got {load.kind!r}")
        return f

    def _add_traction(self, f, box, traction, i):
        """Traction per unit area on boundary faces inside the box, area-split equally over face nodes."""
        inside = box_contains(box, self.mesh.points, self.box_tol)
        hit = False
        for _, _, nodes in boundary_faces(self.mesh):
            nodes = np.asarray(nodes)
            if not inside[nodes].all():
                continue
            f[nodes] += traction * _face_measure(self.mesh.points, nodes, self.dim) / nodes.size
            hit = True
        if not hit:
            raise TensormassError(f"loads.nodal[{i}] (traction): no boundary face inside box {box!r}")

    def _nearest_node(self, point) -> int:
        p = self._vector(point, "probe point")
        return int(np.argmin(np.sum((self.mesh.points - p) ** 2, axis=1)))

    # -- helpers for the integrators ------------------------------------------------------------
    def element_displacements(self, part: Part, u: np.ndarray) -> np.ndarray:
        """(n_active, k, dim) nodal displacements of a part's active elements (pair with part.D_active)."""
        return u.reshape(self.n_points, self.dim)[part.cells_active]

    def warm_up(self, outputs=None) -> None:
        """Compile (or load from numba's cache) the kernel outputs the solver will call."""
        for part in self.parts:
            D, u = part.D[:1], np.zeros((1, part.kernel.n_nodes, self.dim))
            for name in outputs or self.outputs:
                getattr(part.kernel, name)(D, u)

    @property
    def n_elements(self) -> int:
        """Cells of the mesh that carry a material (switchable cells counted once)."""
        return sum(p.n_active for p in self.parts)

    def kernel_info(self) -> list:
        """Kernels loaded; `elements` is how many cells each models now (0: reachable by switching)."""
        return [{"element": p.element, "law": p.law, "quadrature": p.quadrature,
                 "backend": p.kernel.backend, "outputs": list(self.outputs), "elements": p.n_active}
                for p in self.parts]

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
        U = u.reshape(self.n_points, self.dim)
        return {name: U[node].tolist() for name, node in self.probes.items()}
