"""The resolution levels of a scene whose mesh is a file, for `tensormass report accuracy SCENE`.

A generated bar is refined by scaling mesh.cells; a mesh file is refined by runtime.mesh.uniform:

* triangle / tetra files: level k is the file's mesh after k passes of red refinement (every edge
  halved: 4^k / 8^k times the cells); swept as the file's element and, raised, as its quadratic
  counterpart (triangle6 / tetra10 with straight-sided midside nodes shared between cells).
  Default elements: both.
* triangle6 / tetra10 files (curved sides allowed): level k refines through each cell's quadratic
  map (curved boundaries stay where the file put them); swept as read, or with --elements
  tetra / triangle on the corners only (the faceted geometry).  Default: as read.
* any other file (hexahedra, wedges, pyramids, quads, mixed types): no refinement; the laws and
  quadratures are swept on the mesh as read (one level; --levels above 1 is refused with what is
  supported).

Materials whose region names the file's cell type follow the element (region = "tetra" becomes
"tetra10" when the mesh is raised).  Meshes are built once per (element, level) and shared by
every law / quadrature combination.
"""
from __future__ import annotations

import copy

from ... import elements as _types
from ...runtime.scene import resources
from ...runtime.base.errors import TensormassError
from ...runtime.scene.scene import Scene
from ...runtime.mesh.uniform import LINEAR_OF, QUADRATIC_OF, refine_uniform, to_linear, to_quadratic

__all__ = ["FileLevels"]


class FileLevels:
    """Elements and meshes of the sweep of a mesh-file scene (see the module doc)."""

    def __init__(self, base: Scene, path, elements=None, levels=None, default_levels: int = 3):
        self.path = path
        self.mesh0 = base.load_mesh()
        types = self.solid_types(self.mesh0)
        # lower-dimensional simplices (boundary faces kept from the file) are refined with the cells
        lower = [t for t in self.mesh0.cell_types() if t not in types]
        self.file = base.mesh.file
        counts = ", ".join(f"{sum(len(b) for b in self.mesh0.blocks if b.type == t)} {t}" for t in types)
        self.kind = None                                   # "linear" / "quadratic" simplices, or None
        if len(types) == 1 and types[0] in QUADRATIC_OF and all(t in QUADRATIC_OF for t in lower):
            self.kind, self.linear, self.quadratic = "linear", types[0], QUADRATIC_OF[types[0]]
        elif len(types) == 1 and types[0] in LINEAR_OF and all(t in LINEAR_OF for t in lower):
            self.kind, self.linear, self.quadratic = "quadratic", LINEAR_OF[types[0]], types[0]
        wanted = list(dict.fromkeys(elements or []))
        if self.kind is None:
            own = types[0] if len(types) == 1 else None
            if wanted and wanted != [own]:
                raise TensormassError(
                    f"{path}: the mesh file {self.file} has {counts} cells: a mesh file is refined and raised to "
                    "quadratic only when it is all triangle or all tetra cells (or triangle6 / tetra10); "
                    f"this one is swept as read, so --elements can only be {own or 'left out'}")
            if levels is not None and levels > 1:
                raise TensormassError(
                    f"{path}: --levels {levels}: the mesh file {self.file} has {counts} cells, and uniform "
                    "refinement of a mesh file is supported for triangle and tetra meshes (and triangle6 / tetra10) "
                    "only; use --levels 1 to sweep laws and quadratures on the mesh as read, or mesh the body "
                    "with tetrahedra")
            self.elements, self.n_levels = [None], 1
            self.note = (f"mesh file {self.file} ({counts} cells) swept as read: uniform refinement is supported for "
                         "triangle / tetra (and triangle6 / tetra10) meshes only, so there is one level")
            return
        allowed = [self.linear, self.quadratic]
        bad = [e for e in wanted if e not in allowed]
        if bad:
            raise TensormassError(f"{path}: --elements {bad[0]}: the mesh file {self.file} has {counts} cells; it "
                                  f"can be swept as {self.linear} or {self.quadratic}")
        self.elements = wanted or (allowed if self.kind == "linear" else [self.quadratic])
        self.n_levels = levels if levels is not None else default_levels
        how = {"linear": f"{self.quadratic}: raised from {self.linear}, straight-sided midside nodes",
               "quadratic": f"{self.linear}: the corners of the {self.quadratic} cells (faceted geometry)"}[self.kind]
        self.note = (f"mesh file {self.file} ({counts} cells); level k = k passes of uniform (red) refinement, "
                     f"every edge halved ({2 ** self.mesh0.dim}^k times the cells"
                     + ("" if self.kind == "linear" else ", new nodes on each cell's quadratic map")
                     + f"); elements {', '.join(self.elements)}"
                     + (f" ({how})" if any(e != types[0] for e in self.elements) else ""))
        self._cache = {}

    @staticmethod
    def solid_types(mesh) -> list:
        """The cell types of the body (topological dimension = the mesh's), in block order."""
        return [t for t in mesh.cell_types() if _types.get(t).dim == mesh.dim]

    def mesh(self, element, level: int):
        """The mesh of one element at one level (built once)."""
        if self.kind is None:
            return self.mesh0
        key = (element, level)
        if key not in self._cache:
            own = self.linear if self.kind == "linear" else self.quadratic
            if level == 0:
                base = self.mesh0
            else:
                base = self._cache.get((own, level))
                if base is None:
                    base = refine_uniform(self.mesh(own, level - 1))
                    self._cache[(own, level)] = base
            self._cache[key] = base if element == own else (
                to_quadratic(base) if element == self.quadratic else to_linear(base))
        return self._cache[key]

    def data(self, data: dict, element) -> dict:
        """The scene dict for one element: material regions naming the file's type follow it."""
        d = copy.deepcopy(data)
        if self.kind is None or element is None:
            return d
        other = {self.linear: self.quadratic, self.quadratic: self.linear}
        for m in d.get("material", []) if isinstance(d.get("material"), list) else []:
            if m.get("region") in other and m.get("region") != element:
                m["region"] = element
        return d

    def scene(self, data: dict, element, level: int, base_dir) -> Scene:
        """A validated Scene of `data` on the mesh of (element, level): parsed, the memory estimate
        checked, then checked against the mesh like any scene (Scene.validate)."""
        mesh = self.mesh(element, level)
        scene = Scene.from_dict(self.data(data, element), base_dir=base_dir, load_mesh=False)
        est = resources.estimate(resources.MeshCounts.of_mesh(mesh), materials=scene.materials, solver=scene.solver,
                                 adapt=scene.adapt)
        resources.check(est, scene.max_memory, what=f"scene {scene.name!r} at level {level}")
        scene._mesh, scene._estimate = mesh, est        # what Scene.load_mesh caches (runtime.scene.mesh_source)
        scene.validate(mesh)
        return scene
