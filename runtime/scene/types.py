"""The parts of a scene, as plain dataclasses (runtime.scene.parser fills them from TOML data and
checks every value; runtime.scene.scene.Scene holds them)."""
from __future__ import annotations

from dataclasses import dataclass, field

from ... import laws
from ...backends.c.loader import default_backend
from ..physics.motion import Rotation


@dataclass
class MeshSpec:
    generate: str | None = None          # "bar" (built-in generator) or None when file is given
    file: str | None = None              # any meshio format
    size: tuple = (1.0, 0.2, 0.2)
    cells: tuple = (10, 2, 2)
    element: str = "hexahedron"          # tetra, tetra10, hexahedron, wedge, pyramid, mixed, triangle, triangle6, quad
    origin: tuple = (0.0, 0.0, 0.0)      # (shell: "shell" with generate = "plate" / "sphere", or a file's triangles)
    radius: float = 0.5                  # generate = "sphere": radius of the icosphere ...
    subdivisions: int = 3                # ... and its subdivisions (20 x 4^s triangles)
    divisions: int = 6                   # generate = "ball": tetrahedra, n cells along the central cube's edge


@dataclass
class Material:
    """First match wins. region: "all", an element type name, an integer cell tag (volume group id), or a
    volume group's name (runtime.mesh.regions); or box."""
    region: str | int = "all"
    box: tuple | None = None             # ((x0, y0, z0), (x1, y1, z1)): cells whose centroid is inside
    law: str = "stvk"
    quadrature: str = "gauss2"
    E: float | None = None
    nu: float | None = None
    params: dict = field(default_factory=dict)   # native parameters instead of E, nu (mu=, lam=, C10=, ...)
    density: float = 1000.0
    formulation: str = "displacement"    # runtime.physics.formulations: displacement | mean_dilatation | nodal_pressure
    law_file: str | None = None          # the file of a law outside the package (laws.load_file), resolved
    viscous: tuple | None = None         # Prony branches ((tau, beta), ...) (laws/viscous.py); None: elastic
    fibres: tuple | None = None          # one entry per direction of the law (runtime.mesh.fibres): a vector or a function

    def native_parameters(self) -> dict:
        """The law's native parameters as floats (from E, nu or as given; laws validates E and nu;
        a discrete law: E, nu and its options from params)."""
        law = laws.get(self.law)
        if self.formulation == "mixed" and self.nu is not None:      # nu = 0.5 allowed: pressure unknowns
            native = law.native_parameters(self.E, self.nu, incompressible=True, **self.params)
        else:
            native = law.native_parameters(self.E, self.nu, **self.params)
        return {k: float(v) for k, v in native.items()}


@dataclass
class Fixed:
    box: tuple | None                     # nodes inside are constrained (None: region only)
    displacement: tuple | None = None     # None: clamped (zero); else prescribed displacement vector
    components: tuple | None = None       # which components (0, 1, 2) are constrained; None = all
    amplitude: str | None = None          # [[amplitude]] name scaling the displacement/motion; None: the ramp
    rotation: Rotation | None = None      # rigid motion (runtime.physics.motion): rotation about an axis ...
    translation: tuple | None = None      # ... and/or translation, applied as true rotations at every step
    region: str | int | None = None       # a mesh group (name or id): its nodes (with box: those inside)
    name: str | None = None               # reaction name (runtime.physics.reactions); None: "fixed[i]"
    moment_about: tuple | None = None     # reaction moment point; None: the centroid of its nodes at rest


@dataclass
class NodalLoad:
    box: tuple | None                     # force applied to the nodes inside the box (None: region only)
    force: tuple                          # total force, split evenly over those nodes
    kind: str = "force"                   # "force" (total, split over nodes) or "traction" (per unit area of boundary faces inside the box)
    #                                       or "moment" (total moment in N m, split over the nodes: shells)
    amplitude: str | None = None          # [[amplitude]] name; None: ramp (static), constant (dynamic)
    region: str | int | None = None       # a mesh group (name or id): its nodes / boundary faces (with box: inside)


@dataclass
class PressureLoad:
    box: tuple | None                     # boundary faces whose nodes all lie inside the box (None: region only)
    value: float                          # Pa, normal to the current surface; > 0 pushes inward
    region: str | int | None = None       # a mesh group (name or id): its boundary faces (with box: inside)
    amplitude: str | None = None          # [[amplitude]] name scaling it over time (dynamic runs)


@dataclass
class Loads:
    gravity: tuple = (0.0, 0.0, 0.0)
    nodal: list = field(default_factory=list)    # [NodalLoad]
    pressure: list = field(default_factory=list)  # [PressureLoad] (runtime/assembly/pressure.py)
    gravity_amplitude: str | None = None  # [[amplitude]] name for gravity (runtime.physics.motion)


@dataclass
class Solver:
    kind: str = "static"                  # static | implicit_euler | backward_euler | explicit | generalized_alpha
    dt: float = 0.01
    steps: int = 1                        # time steps (dynamic) or load steps (static)
    device: str = "cpu"                   # cpu | cuda: where implicit_euler's Newton system lives
    linear: str = "auto"                  # auto | direct | cg | amg | band | pardiso | lu (runtime/solve/solvers.py)
    cg_tolerance: float = 1e-8
    cg_max_iterations: int = 1000
    mode: str = "exact"                   # exact | interactive (a preset of the two keys below)
    stiffness_every: int = 1              # implicit_euler: K (and the step's factor) kept for N steps at most
    stiffness_tolerance: float = 5e-3     # ... and while the step error estimated from the forces stays below
    factor_tolerance: float = 1e-10       # relative residual a factor's solve is refined to
    newton_tolerance: float = 1e-8        # relative residual
    newton_max_iterations: int = 25
    rayleigh: tuple = (0.0, 0.0)          # alpha (mass), beta (stiffness)
    project_psd: bool | None = None       # None: plain Newton, projection switched on when a step fails to descend
    rho_inf: float = 1.0                  # generalized_alpha: 1 = no numerical damping, < 1 damps high frequencies
    backend: str = field(default_factory=default_backend)   # c | numba: c when a C compiler is found
    # Health monitor (runtime/physics/health.py): when a run leaves the trusted region
    health_monitor: bool = True           # false: no checks (a run may then end in a meaningless state)
    max_energy_growth: float = 100.0      # stop when the energy balance grows by this x the scene's energy scale
    max_displacement: float = 10.0        # stop when a node moves this x the body size away from the mean motion
    on_inversion: str = "warn"            # inverted elements (laws defined there): "warn" (invalid at the end) | "stop"
    mass: str = "lumped"                  # lumped (row sums / HRZ) | consistent (implicit solvers; runtime/assembly/mass.py)
    threads: int | None = None            # assembly threads (runtime/base/parallel.py); None: $TENSORMASS_THREADS / every core
    preserve_volume: bool = False         # closed shells: project onto the rest volume after every step


@dataclass
class Probe:
    name: str
    point: tuple | None                   # u interpolated at the point (runtime.mesh.probes); or:
    region: str | int | None = None       # the mean displacement of a group's nodes (with box: those inside)
    box: tuple | None = None              # ... or of the nodes inside a box


@dataclass
class Output:
    dir: str | None = None                # None: no files written
    every: int = 1
    fields: tuple | None = None           # names from runtime.physics.fields.FIELDS; None: its DEFAULT_FIELDS
    picture: str | None = None            # a PNG of the deformed body coloured by this field at the end
    picture_named: bool = False           # the field was named ("von_mises"), not picture = true's default
    plot: bool = False                    # the per-step history as a PNG beside the summary
    view: tuple | None = None             # the picture's camera (azimuth, elevation) in degrees; None: (-60, 20)
    clip: tuple | None = None             # the picture's cut-away ((point), (normal)): the side the normal points to is removed


@dataclass
class Adapt:
    """One adaptation rule (see runtime.change.adapt): when an element's criterion passes the threshold, act.

    switch_law: the element changes to `law` (only elements now under `from_law`, any other law
    when None); with `back`, it returns to its previous law once the criterion falls below `back`.
    refine: triangles and tetrahedra are bisected (at most `rounds` times over the run).
    relative: the threshold is a fraction of the largest value over the mesh (the thesis' R_S rule).
    """
    criterion: str                        # R_L | R_A | R_M | R_HM | R_S | rotation (degrees)
    threshold: float
    action: str = "switch_law"            # switch_law | refine
    law: str | None = None                # target law of switch_law
    from_law: str | None = None           # scene key "from"
    back: float | None = None             # switch back below this value (hysteresis)
    relative: bool = False
    below: bool = False                   # act when the criterion is BELOW the threshold (quality criteria)
    every: int = 1                        # evaluate every N steps
    rounds: int = 1                       # refine: how many refinement passes over the whole run


@dataclass
class TopologyEvent:
    """A [[cut]] or [[remove]] event (runtime.mesh.topology, runtime.change.cutting), at a time or after a step.

    cut: the faces between cells whose centroids lie on either side of the plane (point, normal),
    in rest coordinates, inside `box` when given (an incision), are separated.  A blade (sweep,
    duration): the box moves by `sweep` from `time` over `duration`, and the faces of the plane open
    as it reaches them (their centroids).  Or tearing
    (criterion = "stretch"): after every `every` steps, the interior faces (inside `box`) across
    which the body is stretched by more than 1 + threshold open.
    remove: the cells whose rest centroid lies in `box` (and/or in the mesh group `region`).
    refine: the hexahedra whose rest centroid lies in `box` are split 1:8 (runtime.physics.hanging constrains
    the nodes that hang on their whole neighbours).
    """
    kind: str                             # cut | remove | refine
    time: float | None = None             # dynamic runs: after the first step ending at or past it
    step: int | None = None               # or after this step (any solver)
    point: tuple | None = None            # cut: a point of the plane
    normal: tuple | None = None           # cut: its normal
    box: tuple | None = None
    region: object = None                 # remove: a mesh group
    name: str | None = None
    criterion: str | None = None          # cut: "stretch" tears faces whose normal stretch passes the threshold
    threshold: float | None = None        # stretch - 1 across the face (0.5: stretched by half)
    every: int = 1                        # tearing: checked every this many steps
    sweep: tuple | None = None            # a blade: the box moves by this vector from `time` ...
    duration: float | None = None         # ... over this long, opening the faces it reaches as it goes
