"""Scenes: what to simulate, as plain data (parsed from TOML by `Scene.from_toml`).

A scene file is data only: nothing in it is evaluated as code. Every key is
validated; unknown keys, unknown laws or elements, nu >= 0.5 (0.5 only with formulation
"mixed"), E <= 0 and the
like raise SceneError naming the key (arrays of tables are indexed from 0:
``material[1]`` is the second ``[[material]]``).

    scene = Scene.from_toml("beam.toml")   # validated; the mesh is built/read and checked against it
    mesh = scene.load_mesh()                # the same (cached) Mesh
    which = scene.assign_materials(mesh)    # per block: index of the material of each cell

The schema and its parser are runtime.scene.parser; the parts of a scene, runtime.scene.types.
What needs the mesh lives elsewhere: building/reading it and checking the scene against it in
runtime.scene.mesh_source, boxes, regions and the material of each cell in runtime.mesh.regions.

Schema (every table but [mesh] and [[material]] is optional)::

    name = "beam"                           # default: the file name without .toml
    description = "..."
    [mesh]
    generate = "bar"                        # or: file = "organ.msh" (relative to the scene file)
    size = [1.2, 0.2, 0.2]                  # 2 entries: a 2D mesh
    cells = [24, 4, 4]
    element = "hexahedron"                  # tetra tetra10 wedge pyramid mixed | 2D: quad (default) triangle triangle6 mixed
    origin = [0.0, 0.0, 0.0]
    [[material]]                            # first match wins
    region = "all"                          # "all", an element type, an integer cell tag / group id, or a group name
    box = [[x0, y0, z0], [x1, y1, z1]]      # optional: cells whose centroid is inside (and region)
    law = "stvk"
    quadrature = "gauss2"
    E = 1.0e8                               # with nu; or the law's native parameters (mu, lam, ...)
    nu = 0.3
    density = 800.0
    formulation = "displacement"            # or mean_dilatation | nodal_pressure (runtime.physics.formulations; per element)
    [[fixed]]
    box = [[...], [...]]                    # nodes inside: clamped, or
    region = "attached"                     # instead of / with box: the nodes of a mesh group (name or id)
    displacement = [0.0, 0.0, -0.01]        # prescribed (a full vector), on
    components = [2]                        # these components only (default: all)
    amplitude = "press"                     # optional: an [[amplitude]] scales it over time (default: the ramp)
    name = "clamp"                          # optional: the reaction's name (default "fixed[i]"; runtime.physics.reactions)
    moment_about = [0.0, 0.1, 0.1]          # optional: the reaction moment's point (default: the nodes' centroid)
    [[fixed]]                               # a rigid motion of the nodes in the box (runtime.physics.motion):
    box = [[...], [...]]
    rotation = { axis = [1, 0, 0], point = [1, 0.1, 0.1], angle = 90.0 }   # degrees; 2D: no axis
    translation = [0.0, 0.0, -0.01]         # and/or; true rotations at every step, scaled by the amplitude
    [[amplitude]]                           # a piecewise-linear table, end values held outside it
    name = "press"
    time = [0.0, 0.5, 1.0]                  # seconds (static runs: the load factor), or factor = [...] (0..1)
    value = [0.0, 1.0, 0.0]
    [loads]
    gravity = [0.0, 0.0, -9.81]
    gravity_amplitude = "press"             # optional; force and traction loads take amplitude = "..."
    [[loads.force]]                         # total force, split evenly over the nodes in the box
    box = [[...], [...]]                    # and/or region = "<group>" (both: the intersection)
    value = [0.0, 0.0, -10.0]
    [[loads.traction]]                      # force per unit area of the boundary faces in the box
    box = [[...], [...]]
    value = [0.0, 0.0, -100.0]
    [[loads.pressure]]                      # follower pressure (Pa) on the boundary faces in the box,
    box = [[...], [...]]                    # normal to the deformed surface; > 0 pushes inward
    value = 2000.0
    [solver]                                # the Solver fields below (mass = "lumped" | "consistent")
    [[probe]]                               # u interpolated at the point (runtime.mesh.probes)
    name = "tip"
    point = [1.2, 0.1, 0.1]                 # interpolated; inside the body or on it within 10 % of a cell
    # or region = "<group>" and/or box = [[...], [...]]: the mean displacement of those nodes
    [output]
    dir = "out"                             # relative to the scene file (tensormass run --out: to the working dir)
    every = 10
    fields = ["von_mises", "cauchy_stress", "det_F_min"]   # the default; [] for none (runtime.physics.fields.FIELDS)
    picture = "von_mises"                   # or true / any field / "displacement": <dir>/<field>.png at the end
    plot = true                             # the per-step history as <dir>/summary.png (runtime.run.curves)
    [[cut]]                                 # open the body along a plane during the run (runtime.mesh.topology)
    time = 0.2                              # or step = k; plane = [[point...], [normal...]], box = ... limits it;
    plane = [[0.1, 0, 0], [1, 0, 0]]        # sweep = [...] + duration = T: a blade; or criterion = "stretch"
    [[remove]]                              # and threshold = 0.35: tearing.  remove: the cells whose rest
    step = 5                                # centroid is in the box (and/or region)
    box = [[...], [...]]
    [[refine]]                              # split the hexahedra whose rest centroid is in the box 1:8
    time = 0.1                              # (or step = k); hanging nodes are constrained
    box = [[...], [...]]
    [contact]                               # contact (runtime.contact); an [[obstacle]] alone switches it on
    method = "ipc"                          # or "penalty" (obstacles only); runtime.contact.base.METHODS_OF: per solver
    dhat = 1e-3                             # IPC barrier distance [m] (default dhat_relative = 1e-3 x body diagonal)
    stiffness = 1e4                         # IPC barrier kappa (default adaptive); penalty: N/m per vertex (10 E h)
    mu = 0.2                                # IPC friction, lagged (friction_iterations = 2, eps_v [m/s])
    self = false                            # and bodies = true, check_every = 1; penalty: max_penetration [m]
    [[obstacle]]                            # a rigid, kinematic body (runtime.contact.obstacles); name = "tool"
    shape = "capsule"                       # plane: point, normal | sphere: center, radius | box: box |
    a = [0.0, 0.0, 0.1]                     # mesh: file, scale | capsule: a, b, radius
    b = [0.0, 0.0, 0.2]                     # (sphere, capsule: resolution [m], the tessellation's chord)
    radius = 0.01
    translation = [0.0, 0.0, -0.02]         # and/or rotation = {axis, point, angle}, as for [[fixed]];
    amplitude = "press"                     # default: the ramp over the run

Boxes are closed and inclusive, with a tolerance of 1e-8 of the mesh's bounding
box diagonal; their bounds may be +-inf (TOML ``inf``), never NaN.
"""
from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..base.errors import SceneError
from ..mesh.regions import assign_materials as _assign_materials
from .mesh_source import check_against_mesh, load_mesh as _load_mesh
from .parser import Parser
from .types import Loads, MeshSpec, Output, Solver


@dataclass
class Scene:
    mesh: MeshSpec
    materials: list                       # [Material]
    fixed: list = field(default_factory=list)     # [Fixed]
    loads: Loads = field(default_factory=Loads)
    solver: Solver = field(default_factory=Solver)
    probes: list = field(default_factory=list)    # [Probe]
    output: Output = field(default_factory=Output)
    adapt: list = field(default_factory=list)     # [Adapt]
    name: str = "scene"
    description: str = ""
    source: str | None = None             # the scene file, when read from one
    max_memory: int | str | None = None   # memory limit (bytes or "8G"); None: see runtime.scene.resources
    amplitudes: list = field(default_factory=list)  # [Amplitude] (runtime.physics.motion)
    topology: list = field(default_factory=list)    # [TopologyEvent]: [[cut]] and [[remove]] in time order
    contact: object = None                          # runtime.contact.base.ContactSpec ([contact]) or None
    obstacles: list = field(default_factory=list)   # [runtime.contact.obstacles.Obstacle] ([[obstacle]])

    # -- reading ------------------------------------------------------------------------------
    @classmethod
    def from_toml(cls, path, load_mesh: bool = True, max_memory=None) -> "Scene":
        """Read and validate a scene file; relative mesh paths are relative to its folder.

        max_memory: bytes or a size such as "8G"; the run is refused (ResourceError) when its
        estimate is above it.  None: $TENSORMASS_MAX_MEMORY, else most of the available memory.
        """
        path = Path(path)
        text = read_scene_file(path)
        scene = cls.from_string(text, base_dir=path.parent, name=path.stem, source=str(path),
                                load_mesh=load_mesh, max_memory=max_memory)
        return scene

    @classmethod
    def from_string(cls, text: str, base_dir=None, name: str = "scene", source: str | None = None,
                    load_mesh: bool = True, max_memory=None) -> "Scene":
        """Parse TOML text (syntax errors are reported with their line) and validate it."""
        where = source or "scene"
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise SceneError(f"{where}: invalid TOML: {exc}") from None
        except RecursionError:                # tomllib parses nested arrays/tables recursively
            raise SceneError(f"{where}: invalid TOML: arrays or inline tables nested too deeply "
                             "(a scene needs at most a few levels)") from None
        data = dict(data)
        data.setdefault("name", name)
        scene = cls.from_dict(data, base_dir=base_dir, load_mesh=load_mesh, max_memory=max_memory)
        scene.source = source
        return scene

    @classmethod
    def from_dict(cls, data, base_dir=None, load_mesh: bool = True, max_memory=None) -> "Scene":
        """Validate a scene given as plain data (what tomllib returns).

        With load_mesh (the default) the mesh is generated or read here, so that
        everything that depends on it (element x law x quadrature combinations,
        cells without a material, boxes that hold no node, vector sizes of file
        meshes) is checked before anything runs; see load_mesh() and validate().
        """
        scene = cls(**Parser(base_dir).scene_fields(data), max_memory=max_memory)
        if load_mesh:
            scene.validate(scene.load_mesh())
        return scene

    # -- the mesh -------------------------------------------------------------------------------
    @property
    def dim(self) -> int | None:
        """2 or 3; None for a file mesh that has not been read yet."""
        mesh = getattr(self, "_mesh", None)
        if mesh is not None:
            return mesh.dim
        if self.mesh.file is None:
            return len(self.mesh.size)
        return None

    def load_mesh(self):
        """The mesh (generated or read once, then cached; see runtime.scene.mesh_source.load_mesh)."""
        return _load_mesh(self)

    @property
    def estimate(self):
        """The run's resource estimate (runtime.scene.resources.Estimate) made by load_mesh; None before."""
        return getattr(self, "_estimate", None)

    def assign_materials(self, mesh=None) -> list:
        """Per cell block, the index into self.materials of each cell (-1: no material matches)."""
        return _assign_materials(self.load_mesh() if mesh is None else mesh, self.materials)

    def validate(self, mesh=None) -> None:
        """Checks that need the mesh (run by from_dict unless load_mesh=False; runtime.scene.mesh_source)."""
        check_against_mesh(self, self.load_mesh() if mesh is None else mesh)

    # -- writing --------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain data (for summaries); not guaranteed to round-trip through from_dict."""
        return asdict(self)


def read_scene_file(path) -> str:
    """The text of a scene file; SceneError naming the file when it cannot be read."""
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(f"scene file not found: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"cannot read scene file {path}: {exc}") from None
