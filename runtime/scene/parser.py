"""The scene schema and its parser: every table and key a scene file may hold, and the checks of
its values (E and nu by the laws, once). Scene.from_dict calls Parser(base_dir).scene_fields(data)."""
from __future__ import annotations

import math
from pathlib import Path

from ... import elements as _element_types
from ... import laws
from ...backends import BACKENDS
from ..kernels import catalogue
from ..base.errors import SceneError, TensormassError
from ..mesh import fibres as _fibres
from ..base import integrator_kinds
from ..base.paths import scene_path
from ..mesh.bars import BAR_ELEMENTS
from ..mesh.container import COORD_MAX
from ..physics.fields import FIELDS, check_names as check_field_names
from ..physics.motion import check_amplitude_use, parse_amplitude, parse_rotation
from . import formulation_check as _formulation
from .mesh_source import catalogue_check as _catalogue_check
from .values import ValueParser, format_value, type_name
from .types import Adapt, Fixed, Loads, Material, MeshSpec, NodalLoad, Output, PressureLoad, Probe, Solver, TopologyEvent


# ============================================================================== parsing


def _event_step(time: float, solver) -> int:
    """The step after which an event at `time` happens: the first whose end time reaches it."""
    return max(1, math.ceil(time / float(solver.dt) - 1e-9))

_TOP = ("name", "description", "mesh", "material", "fixed", "loads", "solver", "probe", "output", "adapt",
        "amplitude", "cut", "remove", "refine", "contact", "obstacle")
_CUT = ("time", "step", "plane", "box", "name", "criterion", "threshold", "every", "sweep", "duration")
TEAR_CRITERIA = ("stretch",)
_REMOVE = ("time", "step", "box", "region", "name")
_REFINE = ("time", "step", "box", "name")
_MESH = ("generate", "file", "size", "cells", "element", "origin", "radius", "subdivisions", "divisions")
_MATERIAL = ("region", "box", "law", "law_file", "quadrature", "E", "nu", "density", "formulation", "fibres",
             "viscous")
_FIXED = ("box", "displacement", "components", "amplitude", "rotation", "translation", "region", "name",
          "moment_about")
_LOADS = ("gravity", "force", "traction", "moment", "pressure", "gravity_amplitude")
_LOAD = ("box", "value", "region")
_LOAD_OPTIONAL = ("amplitude",)
_SOLVER = ("kind", "dt", "steps", "linear", "cg_tolerance", "cg_max_iterations", "mode", "stiffness_every",
           "stiffness_tolerance", "factor_tolerance", "newton_tolerance",
           "newton_max_iterations", "rayleigh", "project_psd", "backend", "health_monitor", "max_energy_growth",
           "max_displacement", "on_inversion", "mass", "rho_inf", "threads", "preserve_volume", "device")
_PROBE = ("name", "point", "region", "box")
_OUTPUT = ("dir", "every", "fields", "picture", "plot", "view", "clip")
_ADAPT = ("criterion", "threshold", "action", "law", "from", "back", "relative", "below", "every", "rounds")
ADAPT_CRITERIA = ("R_L", "R_A", "R_M", "R_HM", "R_S", "rotation")
ADAPT_ACTIONS = ("switch_law", "refine")

SOLVER_KINDS = integrator_kinds.NAMES
# The cheapest step there is (explicit, one hexahedron) takes ~35 us on the benchmark
# machine: 1e8 steps are an hour for a single cell and days for any real mesh (static
# load steps cost a Newton solve each).  More is a typo (1e12, an extra 000), refused
# before the run rather than discovered hours into it.
MAX_STEPS = 100_000_000
_MAX_STEPS_WHY = "1e8 steps already take an hour on a single explicit cell, days on a real mesh"
# runtime.solve.solvers.METHODS (not imported here: it loads numba; a test checks they agree)
LINEAR_SOLVERS = ("auto", "direct", "cg", "amg", "band", "pardiso", "lu")
INVERSION_ACTIONS = ("warn", "stop")
# runtime.solve.device.DEVICES (not imported here: it loads numba; a test checks they agree)
DEVICES = ("cpu", "cuda")
# solver.mode: presets of the budgeted step's keys (docs/guide/interactive.md measures them); keys given
# beside the mode win
SOLVER_MODES = {"exact": {},
                "interactive": {"stiffness_every": 50, "stiffness_tolerance": 5e-3, "factor_tolerance": 1e-4}}
MASS_KINDS = ("lumped", "consistent")       # runtime/assembly/mass.py
GENERATORS = ("bar", "plate", "sphere", "ball")   # plate, sphere: shell surfaces (runtime.mesh.surfaces);
                                                  # ball: a tetrahedral solid ball (runtime.mesh.solids)
ELEMENTS_3D = BAR_ELEMENTS[3]           # what generate_bar builds (runtime.mesh.bars)
ELEMENTS_2D = BAR_ELEMENTS[2]
CELL_TYPES = _element_types.names()     # every registered element type (tensormass.elements)


class Parser(ValueParser):
    """The tables of a scene (the values' checks: runtime.scene.values)."""

    # -- tables -----------------------------------------------------------------------------
    def scene_fields(self, data) -> dict:
        """The checked fields of a Scene from plain data (what tomllib returns)."""
        data = self.table(data, "scene")
        self.keys(data, "", _TOP)
        if "mesh" not in data:
            raise SceneError("mesh: missing [mesh] table (generate = \"bar\" or file = \"...\")")
        if "material" not in data or not data["material"]:
            raise SceneError("material: no [[material]] given (at least one, e.g. region = \"all\")")
        mesh = self.mesh(self.table(data["mesh"], "mesh"))
        materials = [self.material(t, f"material[{i}]")
                     for i, t in enumerate(self.tables(data["material"], "material"))]
        fixed = [self.fixed(t, f"fixed[{i}]") for i, t in enumerate(self.tables(data.get("fixed", []), "fixed"))]
        reaction_names = [f.name if f.name is not None else f"fixed[{i}]" for i, f in enumerate(fixed)]
        dup = next((i for i, n in enumerate(reaction_names) if reaction_names.index(n) != i), None)
        if dup is not None:
            raise SceneError(f"fixed[{dup}].name: duplicate reaction name {reaction_names[dup]!r} "
                             f"(fixed[{reaction_names.index(reaction_names[dup])}] has it too)")
        loads = self.loads(self.table(data.get("loads", {}), "loads"))
        contact, obstacles = self.contact(data)
        amplitudes = self.amplitudes(data.get("amplitude", []), fixed, loads, obstacles)
        solver = self.solver(self.table(data.get("solver", {}), "solver"))
        probes = [self.probe(t, f"probe[{i}]", i) for i, t in enumerate(self.tables(data.get("probe", []), "probe"))]
        names = [p.name for p in probes]
        dup = next((n for n in names if names.count(n) > 1), None)
        if dup is not None:
            raise SceneError(f"probe[{names.index(dup, names.index(dup) + 1)}].name: duplicate probe name {dup!r}")
        output = self.output(self.table(data.get("output", {}), "output"))
        adapt = [self.adapt(t, f"adapt[{i}]") for i, t in enumerate(self.tables(data.get("adapt", []), "adapt"))]
        _formulation.check_adapt(materials, adapt)
        name = self.string(data.get("name", "scene"), "name")
        description = self.string(data.get("description", ""), "description")
        if not integrator_kinds.get(solver.kind).dynamic and not fixed:
            raise SceneError("fixed: a static scene needs at least one [[fixed]] box "
                             "(without constraints the stiffness matrix is singular)")
        topology = [self.topology_event(t, kind, f"{kind}[{i}]", solver)
                    for kind in ("cut", "remove", "refine") for i, t in enumerate(self.tables(data.get(kind, []), kind))]
        kinds = {e.kind for e in topology}
        if "refine" in kinds and kinds & {"cut", "remove"}:
            raise SceneError("refine: [[refine]] events cannot be combined with [[cut]] / [[remove]] yet")
        # in the order they happen (a cut and a removal at the same step: the file's order, cuts first)
        topology.sort(key=lambda e: e.step if e.step is not None else
                      _event_step(e.time, solver) if e.time is not None else 0)
        if topology and adapt:
            raise SceneError(f"{topology[0].kind}: [[cut]] / [[remove]] events cannot be combined with [[adapt]] "
                             "rules yet")
        _check_viscous(materials, solver, topology, adapt)
        _check_mixed(materials, solver, topology, adapt, contact, obstacles)
        _check_device(materials, solver, loads, topology, adapt, contact, obstacles, self.shell)
        _check_cell_data_fibres(materials, topology, adapt)
        if (contact is not None or obstacles) and (topology or any(a.action == "refine" for a in adapt)):
            what = f"[[{topology[0].kind}]]" if topology else "[[adapt]] action = \"refine\""
            raise SceneError(f"contact: cannot be combined with {what} (a contact surface that changes during the "
                             "run is not supported)")
        return dict(mesh=mesh, materials=materials, fixed=fixed, loads=loads, solver=solver, probes=probes,
                    output=output, adapt=adapt, name=name, description=description, amplitudes=amplitudes,
                    topology=topology, contact=contact, obstacles=obstacles)

    def contact(self, data) -> tuple:
        """[contact] and [[obstacle]] (runtime.contact.scene): (ContactSpec or None, [Obstacle])."""
        if "contact" not in data and "obstacle" not in data:
            return None, []
        from ..contact.base import ContactSpec
        from ..contact.scene import check_obstacles, parse_contact, parse_obstacle
        spec = parse_contact(self, data["contact"]) if "contact" in data else ContactSpec()
        obstacles = [parse_obstacle(self, t, f"obstacle[{i}]") for i, t in enumerate(self.tables(data.get("obstacle", []), "obstacle"))]
        check_obstacles(obstacles)
        if not obstacles and not (spec.self_contact or spec.bodies):
            raise SceneError("contact: nothing can touch (no [[obstacle]], self = false and bodies = false)")
        if spec.method == "penalty" and not obstacles:
            raise SceneError("contact.method = \"penalty\": penalty contact acts between the body and [[obstacle]]s; "
                             "give an obstacle, or use method = \"ipc\" for bodies and self-contact")
        return spec, obstacles

    def mesh(self, t) -> MeshSpec:
        self.keys(t, "mesh", _MESH)
        if ("generate" in t) == ("file" in t):
            raise SceneError("mesh: give exactly one of generate = \"bar\" or file = \"...\"")
        if "file" in t:
            extra = [k for k in ("size", "cells", "origin", "radius", "subdivisions", "divisions") if k in t]
            if extra:
                raise SceneError(f"mesh.{extra[0]}: only used with generate = \"bar\", not with mesh.file")
            element = None
            if "element" in t:       # a file's triangles as shells: the only conversion there is
                element = self.string(t["element"], "mesh.element", ("shell",))
            raw = self.string(t["file"], "mesh.file")
            path = Path(scene_path(raw, self.base_dir))
            if not path.is_file():
                raise SceneError(f"mesh.file: mesh file not found: {path} (relative paths are relative to "
                                 "the scene file)")
            self.shell = element == "shell"
            return MeshSpec(generate=None, file=str(path), **({"element": element} if element else {}))
        generator = self.string(t["generate"], "mesh.generate", GENERATORS)
        if generator == "ball":
            return self._ball(t)
        if "divisions" in t:
            raise SceneError("mesh.divisions: only used with generate = \"ball\"")
        if generator != "bar":
            return self._surface(t, generator)
        for k in ("radius", "subdivisions"):
            if k in t:
                raise SceneError(f"mesh.{k}: only used with generate = \"sphere\"")
        element = self.string(t["element"], "mesh.element", tuple(dict.fromkeys(ELEMENTS_3D + ELEMENTS_2D))) \
            if "element" in t else None
        if "size" in t:
            size = self.vector(t["size"], "mesh.size")
        else:
            size = (1.0, 0.2) if element in _element_types.names(dim=2) else (1.0, 0.2, 0.2)
        self.dim = len(size)
        if element is None:                 # default: hexahedron, or quad for a 2D size
            element = "hexahedron" if self.dim == 3 else "quad"
        for i, s in enumerate(size):
            if s <= 0:
                raise SceneError(f"mesh.size[{i}]: must be > 0 (got {format_value(s)})")
        allowed = ELEMENTS_3D if self.dim == 3 else ELEMENTS_2D
        if element not in allowed:
            raise SceneError(f"mesh.element: {element!r} is not a {self.dim}D element; for a {self.dim}D "
                             f"mesh (size has {self.dim} entries) use: {', '.join(allowed)}")
        if "cells" in t:
            cells_raw = t["cells"]
            if not isinstance(cells_raw, list) or len(cells_raw) != self.dim:
                raise SceneError(f"mesh.cells: expected {self.dim} integers (one per entry of mesh.size), "
                                 f"got {format_value(cells_raw)}")
            cells = tuple(self.integer(c, f"mesh.cells[{i}]", 1) for i, c in enumerate(cells_raw))
        else:
            cells = (10, 2, 2)[: self.dim]
        if element == "mixed" and cells[0] < (4 if self.dim == 3 else 2):
            raise SceneError(f"mesh.cells[0]: element = \"mixed\" needs at least {4 if self.dim == 3 else 2} "
                             f"cells along x (got {cells[0]})")
        origin = self.vector(t["origin"], "mesh.origin") if "origin" in t else (0.0,) * self.dim
        _check_bar_extent(size, origin)
        return MeshSpec(generate="bar", file=None, size=size, cells=cells, element=element, origin=origin)

    def _ball(self, t) -> MeshSpec:
        """generate = "ball" (radius, divisions): the solid ball in tetrahedra, a cubed ball with
        6 (n^3 + 6 n^2 round(2n/3)) cells for n = divisions (runtime.mesh.solids.ball_tetrahedra)."""
        for k in ("size", "cells", "subdivisions"):
            if k in t:
                raise SceneError(f"mesh.{k}: not used with generate = \"ball\" (radius, divisions)")
        element = self.string(t.get("element", "tetra"), "mesh.element", ("tetra",))
        self.dim = 3
        origin = self.vector(t["origin"], "mesh.origin", dim=3) if "origin" in t else (0.0, 0.0, 0.0)
        radius = self.number(t.get("radius", 0.5), "mesh.radius", positive=True)
        divisions = self.integer(t.get("divisions", 6), "mesh.divisions", 1)
        if divisions > 40:
            raise SceneError(f"mesh.divisions: at most 40 (2.5 million tetrahedra), got {divisions}")
        return MeshSpec(generate="ball", file=None, size=(), cells=(), element=element, origin=origin,
                        radius=radius, divisions=divisions)

    def _surface(self, t, generator) -> MeshSpec:
        """generate = "plate" (size [a, b], cells [nx, ny], 2 triangles per cell, at z = 0) or
        "sphere" (radius, subdivisions: an icosphere): shell triangles in 3D (runtime.mesh.surfaces)."""
        element = self.string(t.get("element", "shell"), "mesh.element", ("shell",))
        self.dim, self.shell = 3, True
        origin = self.vector(t["origin"], "mesh.origin", dim=3) if "origin" in t else (0.0, 0.0, 0.0)
        if generator == "sphere":
            for k in ("size", "cells"):
                if k in t:
                    raise SceneError(f"mesh.{k}: not used with generate = \"sphere\" (radius, subdivisions)")
            radius = self.number(t.get("radius", 0.5), "mesh.radius", positive=True)
            subdivisions = self.integer(t.get("subdivisions", 3), "mesh.subdivisions", 0)
            if subdivisions > 7:
                raise SceneError(f"mesh.subdivisions: at most 7 (20 x 4^7 = 327 680 triangles), got {subdivisions}")
            return MeshSpec(generate="sphere", file=None, size=(), cells=(), element=element, origin=origin,
                            radius=radius, subdivisions=subdivisions)
        for k in ("radius", "subdivisions"):
            if k in t:
                raise SceneError(f"mesh.{k}: only used with generate = \"sphere\"")
        size = self.vector(t.get("size", [1.0, 1.0]), "mesh.size", dim=2)
        if min(size) <= 0:
            raise SceneError(f"mesh.size: a plate takes 2 positive sizes [a, b], got {format_value(list(size))}")
        cells_raw = t.get("cells", [8, 8])
        if not isinstance(cells_raw, list) or len(cells_raw) != 2:
            raise SceneError(f"mesh.cells: a plate takes 2 integers [nx, ny], got {format_value(cells_raw)}")
        cells = tuple(self.integer(c, f"mesh.cells[{i}]", 1) for i, c in enumerate(cells_raw))
        return MeshSpec(generate="plate", file=None, size=size, cells=cells, element=element, origin=origin)

    def material(self, t, key) -> Material:
        t = self.table(t, key)
        law_name = self.string(t.get("law", "stvk"), f"{key}.law")
        law_file = None
        if "law_file" in t:
            law_file, law_name = self.law_file(t, key)
        try:
            law = laws.get(law_name)
        except laws.LawError as exc:
            raise SceneError(f"{key}.law: {exc}") from None
        self.keys(t, key, _MATERIAL, tuple(law.parameters) + tuple(o for o, _, _ in getattr(law, "options", ())))
        region = t.get("region", "all")
        if isinstance(region, bool) or not isinstance(region, (str, int)):
            raise SceneError(f"{key}.region: expected \"all\", an element type, an integer cell tag or a "
                             f"region (group) name, got {type_name(region)}")
        if isinstance(region, str) and not region.strip():
            raise SceneError(f"{key}.region: must not be empty; use \"all\", an element type "
                             f"({', '.join(CELL_TYPES)}), an integer cell tag, a region (group) name of the mesh, "
                             "or box = [[...], [...]]")
        if isinstance(region, str) and region not in ("all",) + CELL_TYPES and self.dim is not None:
            raise SceneError(f"{key}.region: unknown region {region!r}; a generated mesh has no named regions: "
                             f"use \"all\", an element type ({', '.join(CELL_TYPES)}), an integer cell tag, "
                             "or box = [[...], [...]]")
        box = self.box(t["box"], f"{key}.box") if "box" in t else None
        # a discrete law (springs, lattice cubes) has one kernel per element: quadrature "discrete"
        default = {"discrete": "discrete", "shell": "exact"}.get(law.kind, "gauss2")
        quadrature = self.string(t.get("quadrature", default), f"{key}.quadrature")
        self._check_combination(key, region, law_name, quadrature)
        formulation = _formulation.formulation_name(t.get("formulation", "displacement"), f"{key}.formulation")
        if isinstance(region, str) and region in CELL_TYPES:    # validate() repeats it per cell type of the mesh
            _formulation.check_element(f"{key}.formulation", formulation, region)
        density = self.number(t.get("density", 1000.0), f"{key}.density")
        if density <= 0:
            raise SceneError(f"{key}.density: must be > 0 (got {format_value(density)})")
        for extra in ("viscous", "fibres"):
            if extra in t and law.kind != "continuum":
                raise SceneError(f"{key}.{extra}: law {law_name!r} has no energy density W(F) (a {law.kind} "
                                 f"model); {extra} applies to the laws of the finite elements")
        if law.kind in ("discrete", "shell"):
            mat = self._discrete_material(t, key, law, region, box, quadrature, formulation, density)
            mat.law_file = law_file
            return mat
        native = {p: self.number(t[p], f"{key}.{p}") for p in law.parameters if p in t}
        E = nu = None
        if native and ("E" in t or "nu" in t):
            raise SceneError(f"{key}: give either E and nu or the native parameters of law {law_name!r} "
                             f"({', '.join(law.parameters)}), not both")
        if native:
            missing = [p for p in law.parameters if p not in native]
            if missing:
                raise SceneError(f"{key}.{missing[0]}: missing; law {law_name!r} takes "
                                 f"{', '.join(law.parameters)} (or E and nu)")
            _check_native(key, law_name, native, self.dim)
        else:
            if "E" not in t and "nu" not in t:
                raise SceneError(f"{key}: needs E and nu, or the native parameters of law {law_name!r} "
                                 f"({', '.join(law.parameters)})")
            if "E" not in t or "nu" not in t:
                missing = "E" if "E" not in t else "nu"
                raise SceneError(f"{key}.{missing}: missing (E and nu go together)")
            E = self.number(t["E"], f"{key}.E")
            nu = self.number(t["nu"], f"{key}.nu")
        options = {o: self.number(t[o], f"{key}.{o}") for o in law.option_names if o in t}
        mat = Material(region=region, box=box, law=law_name, quadrature=quadrature, E=E, nu=nu,
                       params={**native, **options}, density=density, formulation=formulation,
                       law_file=law_file, fibres=self.fibres(t, key, law), viscous=self.viscous(t, key))
        try:                              # E and nu are validated here, once, by laws (validate_E_nu)
            values = mat.native_parameters()
        except laws.LawError as exc:
            raise SceneError(_law_error(key, E, nu, exc)) from None
        bad = [p for p, v in values.items() if not math.isfinite(v) and not (formulation == "mixed" and v == math.inf)]
        if bad:
            raise SceneError(f"{key}: parameter {bad[0]} of law {law_name!r} is not finite")
        return mat

    def viscous(self, t, key) -> tuple | None:
        """A [[material]]'s Prony branches ((tau, beta), ...) (laws/viscous.py), or None."""
        if "viscous" not in t:
            return None
        raw = t["viscous"]
        if not isinstance(raw, list) or not raw or not all(isinstance(b, dict) for b in raw):
            raise SceneError(f"{key}.viscous: expected an array of tables [{{tau = 0.1, beta = 0.5}}, ...] "
                             f"(one per Prony branch), got {type_name(raw)}")
        if len(raw) > MAX_BRANCHES:
            raise SceneError(f"{key}.viscous: at most {MAX_BRANCHES} Prony branches, got {len(raw)}")
        branches = []
        for i, b in enumerate(raw):
            where = f"{key}.viscous[{i}]"
            self.keys(b, where, ("tau", "beta"))
            for name in ("tau", "beta"):
                if name not in b:
                    raise SceneError(f"{where}.{name}: missing (a branch is {{tau = relaxation time in s, "
                                     "beta = its stiffness over the relaxed one}})")
            tau = self.number(b["tau"], f"{where}.tau", positive=True)
            beta = self.number(b["beta"], f"{where}.beta")
            if not beta >= 0:
                raise SceneError(f"{where}.beta: must be >= 0 (got {format_value(beta)})")
            branches.append((tau, beta))
        return tuple(branches)

    def fibres(self, t, key, law) -> tuple | None:
        """A [[material]]'s fibres: one entry per direction of its law (runtime.mesh.fibres)."""
        count = len(law.directions)
        if "fibres" not in t:
            if count:
                raise SceneError(f"{key}.fibres: missing; law {law.name!r} needs {count} fibre direction"
                                 f"{'s' if count > 1 else ''} per cell: a vector such as [1, 0, 0], "
                                 "\"FILE.py:FUNCTION\" (a function of the cells' centroids) or \"NAME\" (the "
                                 "mesh file's cell data)")
            return None
        if not count:
            raise SceneError(f"{key}.fibres: law {law.name!r} has no fibre directions; remove fibres")
        raw = t["fibres"]
        nested = isinstance(raw, list) and raw and all(isinstance(r, (list, str)) for r in raw)
        entries = raw if nested else [raw]
        if len(entries) != count:
            raise SceneError(f"{key}.fibres: law {law.name!r} has {count} fibre direction"
                             f"{'s' if count > 1 else ''} ({', '.join(law.directions)}), got {len(entries)}")
        try:
            return tuple(_fibres.parse_entry(e, f"{key}.fibres", self.base_dir) for e in entries)
        except TensormassError as exc:
            raise SceneError(str(exc)) from None

    def law_file(self, t, key) -> tuple:
        """A [[material]]'s law_file: a law file outside the package (relative to the scene file),
        loaded and registered (laws.load_file); law, when given too, must be the name it defines.
        Returns the file's resolved path and the name of its law."""
        raw = self.string(t["law_file"], f"{key}.law_file")
        path = Path(scene_path(raw, self.base_dir))
        if not path.is_file():
            raise SceneError(f"{key}.law_file: law file not found: {path} (relative paths are relative to "
                             "the scene file)")
        try:
            law = laws.load_file(path)
        except laws.LawError as exc:
            raise SceneError(f"{key}.law_file: {exc}") from None
        if "law" in t and t["law"] != law.name:
            raise SceneError(f"{key}.law: {t['law']!r}, but {key}.law_file {raw!r} defines law {law.name!r}; "
                             f"leave law out or give law = {law.name!r}")
        return str(path.resolve()), law.name

    def _discrete_material(self, t, key, law, region, box, quadrature, formulation, density) -> Material:
        """A discrete law's material: E and nu (what its stiffness rule converts) and its options (A)."""
        if formulation != "displacement":
            what = {"discrete": "discrete model (springs)", "shell": "shell model"}.get(law.kind, law.kind)
            raise SceneError(f"{key}.formulation: law {law.name!r} is a {what}, it has no "
                             f"locking-free formulation; remove formulation = {formulation!r}")
        for name in ("E", "nu"):
            if name not in t:
                raise SceneError(f"{key}.{name}: missing; law {law.name!r} takes E and nu"
                                 + "".join(f", optionally {o}" for o, _, _ in law.options))
        E, nu = self.number(t["E"], f"{key}.E"), self.number(t["nu"], f"{key}.nu")
        options = {o: self.number(t[o], f"{key}.{o}") for o, _, _ in law.options if o in t}
        mat = Material(region=region, box=box, law=law.name, quadrature=quadrature, E=E, nu=nu,
                       params=options, density=density, formulation=formulation)
        try:
            mat.native_parameters()
        except laws.LawError as exc:
            raise SceneError(_law_error(key, E, nu, exc)) from None
        return mat

    @staticmethod
    def _check_combination(key, region, law, quadrature):
        """Early check of (element, law, quadrature); validate() repeats it per cell type of the mesh."""
        if isinstance(region, str) and region in CELL_TYPES:
            _catalogue_check(f"{key}.quadrature", region, law, quadrature)
            return
        try:
            catalogue.check(None, law, quadrature)
        except ValueError as exc:
            raise SceneError(f"{key}.quadrature: {exc}") from None

    def fixed(self, t, key) -> Fixed:
        t = self.table(t, key)
        self.keys(t, key, _FIXED)
        if "box" not in t and "region" not in t:
            raise SceneError(f"{key}.box: missing (nodes inside the box are constrained; or give "
                             "region = \"<group name or id>\")")
        box = self.box(t["box"], f"{key}.box") if "box" in t else None
        region = self.region(t["region"], f"{key}.region") if "region" in t else None
        bdim = len(box[0]) if box is not None else self.dim
        disp = self.vector(t["displacement"], f"{key}.displacement", dim=bdim) if "displacement" in t else None
        comps = None
        if "components" in t:
            raw = t["components"]
            if not isinstance(raw, list) or not raw:
                raise SceneError(f"{key}.components: expected a non-empty array of component indices")
            dim = bdim or 3
            comps = tuple(self.integer(c, f"{key}.components[{i}]", 0) for i, c in enumerate(raw))
            if self.shell and max(comps) < 2 * dim:
                pass                     # shells: 0..2 the displacement, 3..5 the rotation
            elif max(comps) >= dim:
                raise SceneError(f"{key}.components: component {max(comps)} does not exist in {dim}D "
                                 f"(use 0..{dim - 1}; shells: 0..{2 * dim - 1}, 3..5 the rotations)")
            if len(set(comps)) != len(comps):
                raise SceneError(f"{key}.components: repeated component in {list(comps)}")
        fixed = Fixed(box=box, displacement=disp, components=comps, region=region)
        self.motion(t, key, fixed, len(box[0]) if box is not None else (self.dim or 3))
        self.reaction(t, key, fixed, bdim)
        return fixed

    def reaction(self, t, key, fixed, dim) -> None:
        """name and moment_about of a [[fixed]] entry (runtime.physics.reactions)."""
        if "name" in t:
            fixed.name = self.string(t["name"], f"{key}.name")
            if not fixed.name.strip():
                raise SceneError(f"{key}.name: must not be empty")
        if "moment_about" in t:
            fixed.moment_about = self.vector(t["moment_about"], f"{key}.moment_about", dim=dim)

    def motion(self, t, key, fixed, dim) -> None:
        """amplitude, rotation and translation of a [[fixed]] entry (runtime.physics.motion)."""
        if "amplitude" in t:
            fixed.amplitude = self.string(t["amplitude"], f"{key}.amplitude")
        if "rotation" in t:
            fixed.rotation = parse_rotation(self, t["rotation"], f"{key}.rotation", dim)
        if "translation" in t:
            fixed.translation = self.vector(t["translation"], f"{key}.translation", dim=dim)
        if fixed.displacement is not None and (fixed.rotation is not None or fixed.translation is not None):
            raise SceneError(f"{key}.displacement: not with rotation/translation (a rigid motion); "
                             "give the displacement as translation = [...]")

    def amplitudes(self, raw, fixed, loads, obstacles=()) -> list:
        """[[amplitude]] tables; every name used exists and every table is used."""
        amps = [parse_amplitude(self, t, f"amplitude[{i}]") for i, t in enumerate(self.tables(raw, "amplitude"))]
        names = [a.name for a in amps]
        dup = next((n for n in names if names.count(n) > 1), None)
        if dup is not None:
            raise SceneError(f"amplitude[{names.index(dup, names.index(dup) + 1)}].name: duplicate amplitude name {dup!r}")
        check_amplitude_use(amps, fixed, loads, obstacles)
        return amps

    def loads(self, t) -> Loads:
        self.keys(t, "loads", _LOADS)
        gravity = self.vector(t["gravity"], "loads.gravity") if "gravity" in t else None
        nodal = []
        for kind in ("force", "traction", "moment"):       # moment: shells (nodes with rotations)
            for i, lt in enumerate(self.tables(t.get(kind, []), f"loads.{kind}")):
                key = f"loads.{kind}[{i}]"
                self.keys(lt, key, _LOAD, _LOAD_OPTIONAL)
                for k in ("box", "value"):
                    if k not in lt and not (k == "box" and "region" in lt):
                        raise SceneError(f"{key}.{k}: missing" + (" (or give region = \"<group>\")" if k == "box" else ""))
                box = self.box(lt["box"], f"{key}.box") if "box" in lt else None
                region = self.region(lt["region"], f"{key}.region") if "region" in lt else None
                value = self.vector(lt["value"], f"{key}.value", dim=len(box[0]) if box is not None else None)
                nodal.append(NodalLoad(box=box, force=value, kind=kind, region=region))
                if "amplitude" in lt:
                    nodal[-1].amplitude = self.string(lt["amplitude"], f"{key}.amplitude")
        pressure = []
        for i, lt in enumerate(self.tables(t.get("pressure", []), "loads.pressure")):
            key = f"loads.pressure[{i}]"
            self.keys(lt, key, _LOAD, _LOAD_OPTIONAL)
            for k in ("box", "value"):
                if k not in lt and not (k == "box" and "region" in lt):
                    raise SceneError(f"{key}.{k}: missing" + (" (or give region = \"<group>\")" if k == "box" else ""))
            pressure.append(PressureLoad(box=self.box(lt["box"], f"{key}.box") if "box" in lt else None,
                                         value=self.number(lt["value"], f"{key}.value"),
                                         region=self.region(lt["region"], f"{key}.region") if "region" in lt else None))
            if "amplitude" in lt:
                pressure[-1].amplitude = self.string(lt["amplitude"], f"{key}.amplitude")
        if gravity is None:
            gravity = (0.0,) * (self.dim or 3)
        out = Loads(gravity=gravity, nodal=nodal, pressure=pressure)
        if "gravity_amplitude" in t:
            out.gravity_amplitude = self.string(t["gravity_amplitude"], "loads.gravity_amplitude")
        return out

    def budget(self, t, s: Solver) -> None:
        """solver.mode and the budgeted step's keys: the preset's values, then the keys given."""
        if "mode" in t:
            s.mode = self.string(t["mode"], "solver.mode", SOLVER_MODES)
        for k, v in SOLVER_MODES[s.mode].items():
            setattr(s, k, v)
        if "stiffness_every" in t:
            s.stiffness_every = self.integer(t["stiffness_every"], "solver.stiffness_every", 1)
        if "stiffness_tolerance" in t:
            s.stiffness_tolerance = self.number(t["stiffness_tolerance"], "solver.stiffness_tolerance", positive=True,
                                                allow_inf=True)
        if "factor_tolerance" in t:
            s.factor_tolerance = self.number(t["factor_tolerance"], "solver.factor_tolerance", positive=True)
        if s.stiffness_every > 1 and s.kind != "implicit_euler":
            why = "solver.mode = \"interactive\"" if "stiffness_every" not in t else f"solver.stiffness_every = {s.stiffness_every}"
            raise SceneError(f"{why}: only implicit_euler keeps its stiffness between steps (solver.kind is "
                             f"{s.kind!r}); use kind = \"implicit_euler\" or remove the key")

    def solver(self, t) -> Solver:
        self.keys(t, "solver", _SOLVER)
        s = Solver()
        if "kind" in t:
            s.kind = self.string(t["kind"], "solver.kind", SOLVER_KINDS)
        if "dt" in t:
            s.dt = self.number(t["dt"], "solver.dt", positive=True)
        if "steps" in t:
            s.steps = self.integer(t["steps"], "solver.steps", 1, MAX_STEPS, _MAX_STEPS_WHY)
        if "linear" in t:
            s.linear = self.string(t["linear"], "solver.linear", LINEAR_SOLVERS)
        for k in ("cg_tolerance", "newton_tolerance"):
            if k in t:
                setattr(s, k, self.number(t[k], f"solver.{k}", positive=True))
        for k in ("cg_max_iterations", "newton_max_iterations"):
            if k in t:
                setattr(s, k, self.integer(t[k], f"solver.{k}", 1))
        self.budget(t, s)
        if "rayleigh" in t:
            raw = t["rayleigh"]
            if not isinstance(raw, list) or len(raw) != 2:
                raise SceneError(f"solver.rayleigh: expected [alpha, beta] (2 numbers), got {format_value(raw)}")
            s.rayleigh = tuple(self.number(v, f"solver.rayleigh[{i}]", min_value=0.0) for i, v in enumerate(raw))
        if "project_psd" in t:
            s.project_psd = self.boolean(t["project_psd"], "solver.project_psd")
        if "backend" in t:
            s.backend = self.string(t["backend"], "solver.backend", BACKENDS)
        if "device" in t:
            s.device = self.string(t["device"], "solver.device", DEVICES)
        if "health_monitor" in t:
            s.health_monitor = self.boolean(t["health_monitor"], "solver.health_monitor")
        if "preserve_volume" in t:
            s.preserve_volume = self.boolean(t["preserve_volume"], "solver.preserve_volume")
        for k in ("max_energy_growth", "max_displacement"):
            if k in t:
                setattr(s, k, self.number(t[k], f"solver.{k}", positive=True))
        if "on_inversion" in t:
            s.on_inversion = self.string(t["on_inversion"], "solver.on_inversion", INVERSION_ACTIONS)
        if "mass" in t:
            s.mass = self.string(t["mass"], "solver.mass", MASS_KINDS)
            if s.mass == "consistent" and not integrator_kinds.get(s.kind).consistent_mass:
                raise SceneError("solver.mass: 'consistent' needs an implicit solver (implicit_euler, "
                                 "backward_euler, generalized_alpha); explicit integration inverts the lumped (diagonal) mass")
        if "threads" in t:
            s.threads = self.integer(t["threads"], "solver.threads", 1)
        if "rho_inf" in t:
            s.rho_inf = self.number(t["rho_inf"], "solver.rho_inf", min_value=0.0)
            if s.rho_inf > 1.0:
                raise SceneError(f"solver.rho_inf: must be <= 1 (got {format_value(s.rho_inf)}); 1 = no numerical damping, "
                                 "0 = the strongest high-frequency damping")
            if not integrator_kinds.get(s.kind).takes_rho_inf:
                raise SceneError(f"solver.rho_inf: only used by kind = \"generalized_alpha\" (kind is {s.kind!r})")
        return s

    def probe(self, t, key, index) -> Probe:
        t = self.table(t, key)
        self.keys(t, key, _PROBE)
        if "point" not in t and "region" not in t and "box" not in t:
            raise SceneError(f"{key}.point: missing (or give region = \"<group>\" and/or box: the mean "
                             "displacement of their nodes)")
        if "point" in t and ("region" in t or "box" in t):
            extra = "region" if "region" in t else "box"
            raise SceneError(f"{key}.{extra}: give either point (u interpolated there) or region/box (the mean over "
                             "their nodes), not both")
        name = self.string(t.get("name", f"probe{index}"), f"{key}.name")
        if not name:
            raise SceneError(f"{key}.name: must not be empty")
        if "point" not in t:
            return Probe(name=name, point=None,
                         region=self.region(t["region"], f"{key}.region") if "region" in t else None,
                         box=self.box(t["box"], f"{key}.box") if "box" in t else None)
        return Probe(name=name, point=self.vector(t["point"], f"{key}.point"))

    def topology_event(self, t, kind, key, solver) -> TopologyEvent:
        t = self.table(t, key)
        self.keys(t, key, {"cut": _CUT, "remove": _REMOVE, "refine": _REFINE}[kind])
        if "criterion" in t:
            return self.tearing(t, key)
        if ("time" in t) == ("step" in t):
            raise SceneError(f"{key}: give time = ... (dynamic runs) or step = ..., one of them "
                             "(or criterion = \"stretch\" and a threshold: tearing)")
        for k in ("threshold", "every"):
            if k in t:
                raise SceneError(f"{key}.{k}: only used with criterion = \"stretch\" (tearing)")
        event = TopologyEvent(kind=kind, name=self.string(t["name"], f"{key}.name") if "name" in t else None)
        if "time" in t:
            if not integrator_kinds.get(solver.kind).dynamic:
                raise SceneError(f"{key}.time: a static run has load steps, not time; give step = ...")
            event.time = self.number(t["time"], f"{key}.time", min_value=0.0)
            if _event_step(event.time, solver) > solver.steps:
                raise SceneError(f"{key}.time: {format_value(event.time)} is after the run's end "
                                 f"({solver.steps} steps of {format_value(solver.dt)})")
        else:
            event.step = self.integer(t["step"], f"{key}.step", 1, solver.steps,
                                      why=f"the run has {solver.steps} steps")
        if "box" in t:
            event.box = self.box(t["box"], f"{key}.box")
        if kind == "cut":
            if "plane" not in t:
                raise SceneError(f"{key}.plane: missing (plane = [[x, y, z], [nx, ny, nz]]: a point and the normal)")
            plane = t["plane"]
            if not isinstance(plane, list) or len(plane) != 2:
                raise SceneError(f"{key}.plane: expected [[point...], [normal...]], got {format_value(plane)}")
            event.point = self.vector(plane[0], f"{key}.plane[0]")
            event.normal = self.vector(plane[1], f"{key}.plane[1]", dim=len(event.point))
            if not any(event.normal):
                raise SceneError(f"{key}.plane[1]: the normal must not be zero")
            if ("sweep" in t) != ("duration" in t):
                raise SceneError(f"{key}.{'duration' if 'sweep' in t else 'sweep'}: missing (a blade moves its box "
                                 "by sweep = [dx, dy, dz] over duration seconds)")
            if "sweep" in t:
                if event.time is None or event.box is None:
                    raise SceneError(f"{key}.sweep: a blade needs time = ... (dynamic runs) and the box it starts as")
                event.sweep = self.vector(t["sweep"], f"{key}.sweep", dim=len(event.point))
                event.duration = self.number(t["duration"], f"{key}.duration", positive=True)
                if _event_step(event.time + event.duration, solver) > solver.steps:
                    raise SceneError(f"{key}.duration: the blade's path ends after the run's end")
        elif kind == "refine":
            if event.box is None:
                raise SceneError(f"{key}.box: missing (the hexahedra to split 1:8: those whose rest centroid is "
                                 "inside box = [[...], [...]])")
        else:
            if "region" in t:
                event.region = self.region(t["region"], f"{key}.region")
            if event.box is None and event.region is None:
                raise SceneError(f"{key}.box: missing (the cells to remove: box = [[...], [...]] and/or region)")
        return event

    def tearing(self, t, key) -> TopologyEvent:
        """[[cut]] criterion = "stretch": faces open where the stretch across them passes the threshold."""
        event = TopologyEvent(kind="cut", name=self.string(t["name"], f"{key}.name") if "name" in t else None,
                              criterion=self.string(t["criterion"], f"{key}.criterion", TEAR_CRITERIA))
        for k in ("time", "step", "plane"):
            if k in t:
                raise SceneError(f"{key}.{k}: a tearing rule (criterion) acts whenever its threshold is passed; "
                                 "it takes threshold, every and box")
        if "threshold" not in t:
            raise SceneError(f"{key}.threshold: missing (the stretch - 1 across a face at which it tears, e.g. 0.5)")
        event.threshold = self.number(t["threshold"], f"{key}.threshold", positive=True)
        if "every" in t:
            event.every = self.integer(t["every"], f"{key}.every", 1)
        if "box" in t:
            event.box = self.box(t["box"], f"{key}.box")
        return event

    def adapt(self, t, key) -> Adapt:
        t = self.table(t, key)
        self.keys(t, key, _ADAPT)
        for k in ("criterion", "threshold"):
            if k not in t:
                raise SceneError(f"{key}.{k}: missing (an [[adapt]] rule needs criterion and threshold)")
        rule = Adapt(criterion=self.string(t["criterion"], f"{key}.criterion", ADAPT_CRITERIA),
                     threshold=self.number(t["threshold"], f"{key}.threshold", min_value=0.0))
        rule.action = self.string(t.get("action", "switch_law"), f"{key}.action", ADAPT_ACTIONS)
        for k, attr in (("law", "law"), ("from", "from_law")):
            if k in t:
                value = self.string(t[k], f"{key}.{k}")
                if value not in laws.names():
                    raise SceneError(f"{key}.{k}: unknown law {value!r}; known: {', '.join(laws.names())}")
                if laws.is_discrete(value):
                    raise SceneError(f"{key}.{k}: law {value!r} is a discrete model (springs): cells cannot be "
                                     "switched to or from it")
                setattr(rule, attr, value)
        if rule.action == "switch_law":
            if rule.law is None:
                raise SceneError(f"{key}.law: missing (the law elements switch to)")
            if rule.from_law == rule.law:
                raise SceneError(f"{key}.from: same law as {key}.law ({rule.law!r})")
        elif "law" in t or "from" in t or "back" in t:
            extra = next(k for k in ("law", "from", "back") if k in t)
            raise SceneError(f"{key}.{extra}: only used with action = \"switch_law\"")
        for k in ("relative", "below"):
            if k in t:
                setattr(rule, k, self.boolean(t[k], f"{key}.{k}"))
        if "back" in t:
            rule.back = self.number(t["back"], f"{key}.back", min_value=0.0)
            if (rule.back >= rule.threshold) != rule.below or rule.back == rule.threshold:
                side = "above" if rule.below else "below"
                raise SceneError(f"{key}.back: must be {side} the threshold {format_value(rule.threshold)} "
                                 f"(got {format_value(rule.back)}): the gap is the hysteresis")
        if rule.relative and rule.threshold > 1.0:
            raise SceneError(f"{key}.threshold: a relative threshold is a fraction of the maximum, in [0, 1] "
                             f"(got {format_value(rule.threshold)})")
        if "every" in t:
            rule.every = self.integer(t["every"], f"{key}.every", 1)
        if "rounds" in t:
            if rule.action != "refine":
                raise SceneError(f"{key}.rounds: only used with action = \"refine\"")
            rule.rounds = self.integer(t["rounds"], f"{key}.rounds", 1)
        return rule

    def output(self, t) -> Output:
        self.keys(t, "output", _OUTPUT)
        out = Output()
        if "dir" in t:
            out.dir = self.string(t["dir"], "output.dir")
            if not out.dir.strip():
                raise SceneError("output.dir: must not be empty (leave it out for no output)")
            # like mesh.file: relative to the scene file's folder (runtime/base/paths.py: the path rule)
            out.dir = scene_path(out.dir, self.scene_dir)
        if "every" in t:
            out.every = self.integer(t["every"], "output.every", 1)
        if "fields" in t:                 # [] for none; names checked against runtime.physics.fields.FIELDS
            if not isinstance(t["fields"], list):
                raise SceneError(f"output.fields: expected an array of field names, got {type_name(t['fields'])} "
                                 f"(known fields: {', '.join(FIELDS)})")
            out.fields = check_field_names(t["fields"], "output.fields", SceneError)
        if "picture" in t:                # true: von Mises; a field name; false: none (runtime.run.picture)
            set_picture(out, t["picture"], "output.picture")
        if "plot" in t:
            out.plot = self.boolean(t["plot"], "output.plot")
        if "view" in t:                   # the picture's camera (runtime.run.picture)
            out.view = view_angles(t["view"], "output.view")
        if "clip" in t:                   # the picture's cut-away: the cells on one side of a plane
            clip = t["clip"]
            if not isinstance(clip, list) or len(clip) != 2:
                raise SceneError(f"output.clip: expected [[point...], [normal...]] (the picture keeps the cells on "
                                 f"the side the normal points away from), got {format_value(clip)}")
            point = self.vector(clip[0], "output.clip[0]")
            normal = self.vector(clip[1], "output.clip[1]", dim=len(point))
            if not any(normal):
                raise SceneError("output.clip[1]: the normal must not be zero")
            out.clip = (point, normal)
        return out


PICTURE_DEFAULT = "von_mises"

# Named cameras of the picture: (azimuth, elevation) in degrees, matplotlib's angles (the view
# direction from the body to the camera: cos(el) (cos(az), sin(az)), sin(el)). Each keeps an axis up
# or, seen from above or below, x to the right.
VIEWS = {"top": (-90.0, 90.0), "bottom": (-90.0, -90.0), "front": (-90.0, 0.0), "back": (90.0, 0.0),
         "left": (180.0, 0.0), "right": (0.0, 0.0)}
DEFAULT_VIEW = (-60.0, 20.0)            # from the front right, above


def view_angles(value, key: str) -> tuple:
    """[output] view / run --view: a name of VIEWS or [azimuth, elevation] in degrees -> (azimuth, elevation)."""
    if isinstance(value, str):
        if value not in VIEWS:
            raise SceneError(f"{key}: unknown view {value!r}; expected one of {', '.join(VIEWS)} or "
                             "[azimuth, elevation] in degrees")
        return VIEWS[value]
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise SceneError(f"{key}: expected a view name ({', '.join(VIEWS)}) or [azimuth, elevation] in degrees, "
                         f"got {format_value(value)}")
    angles = tuple(Parser.number(v, f"{key}[{i}]") for i, v in enumerate(value))
    if not -90.0 <= angles[1] <= 90.0:
        raise SceneError(f"{key}[1]: the elevation must be within [-90, 90] degrees, got {format_value(angles[1])}")
    return angles


def view_text(text: str, key: str = "--view") -> tuple:
    """run --view: a view name, or "AZIMUTH,ELEVATION" in degrees -> (azimuth, elevation)."""
    if "," not in text and text.strip() in VIEWS:
        return VIEWS[text.strip()]
    try:
        value = [float(p) for p in text.split(",")]
        if len(value) != 2:
            raise ValueError
    except ValueError:
        raise SceneError(f"{key}: expected a view name ({', '.join(VIEWS)}) or AZIMUTH,ELEVATION in degrees, "
                         f"got {text!r}") from None
    return view_angles(value, key)


def set_picture(output, value, key: str) -> None:
    """[output] picture / run --picture into the scene's output: the field, and whether it was named
    (a named field is drawn or refused; the default may fall back to the displacement)."""
    output.picture = picture_field(value, key)
    output.picture_named = isinstance(value, str)


def picture_field(value, key: str) -> str | None:
    """[output] picture / run --picture: true -> von Mises, false -> None, else a field to colour by."""
    if value is True:
        return PICTURE_DEFAULT
    if value is False:
        return None
    known = ("displacement",) + tuple(FIELDS)
    if not isinstance(value, str) or value not in known:
        raise SceneError(f"{key}: expected true, false or a field name, got {value!r} (fields: {', '.join(known)})")
    return value


def _check_bar_extent(size, origin) -> None:
    """A generated bar's coordinates must stay where float64 computes volumes and energies."""
    for i, (s, o) in enumerate(zip(size, origin)):
        far = max(abs(o), abs(o + s))
        if not far <= COORD_MAX:
            key = f"mesh.origin[{i}]" if abs(o) > COORD_MAX else f"mesh.size[{i}]"
            raise SceneError(f"{key}: coordinates too large: the bar reaches {format_value(far)} m along axis {i}, beyond "
                             f"+-{COORD_MAX:g}; element volumes and energies would overflow float64 "
                             "(a unit mix-up? coordinates are in meters)")


def _law_error(key, E, nu, exc) -> str:
    """The scene's message for a LawError of a material: the key of E or nu when laws refused them."""
    if E is not None and not E > 0:
        return f"{key}.E: Young's modulus must be > 0 (got {format_value(E)})"
    if nu is not None and nu > 0.5:
        return f"{key}.nu: Poisson's ratio must be <= 0.5 (got {format_value(nu)})"
    if nu is not None and nu == 0.5:
        return (f"{key}.nu: Poisson's ratio must be < 0.5 (got 0.5) with this formulation; nu = 0.5 (incompressible) "
                "needs formulation = \"mixed\" (the pressure as an unknown; tetra, tetra10, hexahedron)")
    if nu is not None and nu <= -1.0:
        return f"{key}.nu: Poisson's ratio must be > -1 (got {format_value(nu)})"
    return f"{key}: {exc}"


MAX_BRANCHES = 20


def _check_cell_data_fibres(materials, topology, adapt) -> None:
    """Fibres read from the mesh file's cell data stay on the cells of the file: no refinement, no cuts."""
    named = [i for i, m in enumerate(materials) if any(isinstance(e, _fibres.CellData) for e in m.fibres or ())]
    changes = [f"[[{e.kind}]]" for e in topology] + ["[[adapt]] action = \"refine\"" for a in adapt
                                                     if a.action == "refine"]
    if named and changes:
        raise SceneError(f"material[{named[0]}].fibres: fibres from the mesh file's cell data cannot be combined with "
                         f"{changes[0]} (a changed mesh keeps no cell data); give the field as \"FILE.py:FUNCTION\"")


def _check_viscous(materials, solver, topology, adapt) -> None:
    """Viscous materials (laws/viscous.py): the integrators and run features their history supports."""
    viscous = [i for i, m in enumerate(materials) if m.viscous]
    if not viscous:
        return
    key = f"material[{viscous[0]}].viscous"
    if solver.kind in ("explicit", "generalized_alpha"):
        raise SceneError(f"{key}: viscous materials run with kind = \"static\" (each load step lasting "
                         f"solver.dt), \"implicit_euler\" or \"backward_euler\", not {solver.kind!r}")
    if adapt:
        raise SceneError(f"{key}: viscous materials cannot be combined with [[adapt]] yet (their history is not "
                         "carried through its refinement or law switches; [[cut]], [[remove]] and [[refine]] keep it)")


def _check_device(materials, solver, loads, topology, adapt, contact, obstacles, shell) -> None:
    """solver.device = "cuda" (runtime.physics.device_euler): the step it runs and what that step holds."""
    if solver.device == "cpu":
        return
    why = None
    if solver.kind != "implicit_euler":
        why = f"runs kind = \"implicit_euler\" (solver.kind is {solver.kind!r})"
    elif solver.stiffness_every != 1:
        why = "solves every step exactly: remove solver.stiffness_every (and mode = \"interactive\")"
    elif solver.linear not in ("auto", "cg"):
        why = f"solves with its own Jacobi-preconditioned CG: solver.linear = {solver.linear!r} does not apply (use \"auto\")"
    elif solver.project_psd:
        why = "takes the kernels' stiffness as it is: remove solver.project_psd"
    elif shell:
        why = "steps solids: shells run on the CPU"
    elif loads.pressure:
        why = "takes no follower pressure ([[loads.pressure]]) yet"
    elif contact is not None or obstacles:
        why = "takes no contact yet"
    elif topology or adapt:
        why = f"takes no {'[[' + topology[0].kind + ']]' if topology else '[[adapt]]'} (its matrix is built once)"
    else:
        for i, m in enumerate(materials):
            if getattr(m, "formulation", "displacement") != "displacement" or getattr(m, "viscous", None):
                why = (f"runs the displacement formulation without viscous branches (material[{i}] has "
                       f"{'formulation = ' + repr(m.formulation) if m.formulation != 'displacement' else 'viscous'})")
                break
    if why is not None:
        raise SceneError(f"solver.device: \"{solver.device}\" {why}")


def _check_mixed(materials, solver, topology, adapt, contact, obstacles) -> None:
    """formulation = "mixed" (runtime.assembly.mixed): what its saddle-point Newton (runtime.physics.saddle) runs with."""
    mixed = [i for i, m in enumerate(materials) if getattr(m, "formulation", "") == "mixed"]
    if not mixed:
        return
    key = f"material[{mixed[0]}].formulation"
    if solver.kind not in ("static", "implicit_euler", "backward_euler"):
        raise SceneError(f"{key}: \"mixed\" (pressure unknowns) runs with kind = \"static\", \"implicit_euler\" or "
                         f"\"backward_euler\", not {solver.kind!r} (an explicit or generalized-alpha step has no "
                         "equation for a massless pressure)")
    if solver.stiffness_every != 1:
        raise SceneError(f"{key}: \"mixed\" solves every step exactly: remove solver.stiffness_every "
                         "(and mode = \"interactive\")")
    if solver.linear not in ("auto", "direct", "lu", "pardiso"):
        raise SceneError(f"{key}: \"mixed\" solves its symmetric indefinite (u, p) system with a sparse direct "
                         f"factorisation (PARDISO's LDL^T, else SuperLU); solver.linear = {solver.linear!r} does not "
                         "apply (use \"auto\")")
    what = (f"[[{topology[0].kind}]]" if topology else "[[adapt]]" if adapt else
            "contact" if contact is not None or obstacles else None)
    if what is not None:
        raise SceneError(f"{key}: \"mixed\" cannot be combined with {what} yet")


def _check_native(key, law, native, dim):
    """Plausibility of native parameters whose meaning we know; finiteness is checked for all."""
    mu = native.get("mu")
    if mu is not None and mu <= 0:
        raise SceneError(f"{key}.mu: shear modulus must be > 0 (got {format_value(mu)})")
    lam = native.get("lam")
    if lam is not None and mu is not None:
        # positive bulk modulus <=> -1 < nu < 0.5 (3D); plane strain needs lam + mu > 0
        if (dim == 2 and lam + mu <= 0) or (dim != 2 and 3 * lam + 2 * mu <= 0):
            raise SceneError(f"{key}.lam: lam = {format_value(lam)} with mu = {format_value(mu)} gives a non-positive "
                             "bulk modulus (Poisson's ratio outside (-1, 0.5))")
    kappa = native.get("kappa")
    if kappa is not None and kappa <= 0:
        raise SceneError(f"{key}.kappa: bulk modulus must be > 0 (got {format_value(kappa)})")
    if "C10" in native and "C01" in native and native["C10"] + native["C01"] <= 0:
        raise SceneError(f"{key}.C10: C10 + C01 must be > 0 (got {format_value(native['C10'] + native['C01'])})")
