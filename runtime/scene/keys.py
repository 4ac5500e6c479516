"""Every scene key as data: its table, type, default, unit, allowed values and meaning.

The scene parser (runtime.scene.scene) is the authority on what a scene accepts; this table describes
the same keys for people (the documentation's scene-key reference is generated from it) and for
tools that check TOML fragments.  tests/runtime/scene/test_scene_keys.py keeps the two in agreement: the
keys of every table are the ones the parser accepts, the defaults are the parser's dataclass
defaults, and every list of allowed values named here resolves.

    from tensormass.runtime.scene.keys import KEYS, TABLES, allowed_values
    [k.name for k in KEYS if k.table == "solver"]        # the keys of [solver]
    allowed_values(key)                                   # the allowed values, read from the code

Allowed values are given either as a tuple, or as "module:ATTRIBUTE" naming the code's own list
(relative to the tensormass package), so that a new solver kind or formulation shows up in the
documentation without an edit here.  Nothing is imported until allowed_values() is called, so
reading this table stays cheap.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass

__all__ = ["Key", "Table", "KEYS", "TABLES", "REQUIRED", "allowed_values", "keys_of", "table_of"]

REQUIRED = "required"        # the default of a key that must be given
NO_DEFAULT = "none"          # optional, with no value when left out


@dataclass(frozen=True)
class Table:
    """A scene table: its TOML name ("" for the top level), whether it is an array of tables
    ([[name]]), and what it is for."""
    name: str
    array: bool
    doc: str


@dataclass(frozen=True)
class Key:
    """One key of a table.  default: the value when the key is left out (REQUIRED, NO_DEFAULT, or a
    value); default_text, when set, says in words what the default depends on.  choices: a tuple,
    or "module:ATTRIBUTE" naming the code's list (keys of a dict count)."""
    table: str
    name: str
    type: str
    default: object = NO_DEFAULT
    unit: str = ""
    choices: tuple | str | None = None
    doc: str = ""
    default_text: str | None = None


TABLES = (
    Table("", False, "The top level of a scene file: its name and its tables."),
    Table("mesh", False, "The body: a generated mesh or a mesh file."),
    Table("material", True, "Materials, matched to cells in order: the first entry that matches a cell wins."),
    Table("fixed", True, "Constrained nodes: clamped, prescribed displacements or rigid motions; each reports "
                         "its reaction."),
    Table("fixed.rotation", False, "An inline table of a [[fixed]] entry: a rotation about an axis."),
    Table("amplitude", True, "Named piecewise-linear tables that scale loads and prescribed motions over time."),
    Table("loads", False, "Gravity and the arrays of tables of loads."),
    Table("loads.force", True, "A total force split evenly over the selected nodes."),
    Table("loads.traction", True, "A force per unit area on the selected boundary faces."),
    Table("loads.moment", True, "A total moment split over the selected nodes (shells: nodes with rotations)."),
    Table("loads.pressure", True, "A follower pressure on the selected boundary faces, normal to the deformed "
                                  "surface."),
    Table("solver", False, "How the scene is stepped and solved, and the health monitor's limits."),
    Table("probe", True, "Displacements reported per step: interpolated at a point, or averaged over nodes."),
    Table("output", False, "What is written, and where."),
    Table("adapt", True, "Rules checked during the run: switch a cell's law, or refine cells."),
    Table("cut", True, "Cut or tear the body during the run."),
    Table("remove", True, "Remove cells during the run (resection)."),
    Table("refine", True, "Split hexahedra 1:8 during the run."),
    Table("contact", False, "Contact of the body with obstacles, between its bodies and with itself: the method and "
                            "its settings (see Contact)."),
    Table("obstacle", True, "Rigid, kinematic obstacles the body touches: a plane, sphere, capsule, box or closed "
                            "triangle mesh, moved by a rigid motion."),
    Table("obstacle.rotation", False, "An inline table of an [[obstacle]] entry: a rotation about an axis."),
)

_BOX = "[[x0, y0, z0], [x1, y1, z1]] (2D: two components)"
_VEC = "array of 2 or 3 numbers (the mesh's dimension)"
_REGION = "string or integer"
_LAWS = "runtime.scene.keys:builtin_laws"


def _load_amplitude(table: str) -> Key:
    """The amplitude key of [[loads.force]], [[loads.traction]] and [[loads.moment]] (one rule for all three)."""
    return Key(table, "amplitude", "string", default_text="ramp (static), constant (dynamic)",
               doc="An amplitude scaling the load.")


def _when(table: str) -> tuple:
    """When an event of [[cut]], [[remove]] or [[refine]] happens: the same two keys for each."""
    return (Key(table, "time", "number", unit="s", doc="After the first step ending at or past it (dynamic runs)."),
            Key(table, "step", "integer", doc="Or after this step."))


KEYS = (
    # -- top level ---------------------------------------------------------------------------
    Key("", "name", "string", default_text="the scene file's name without .toml",
        doc="The scene's name, used in titles and summaries."),
    Key("", "description", "string", default="", doc="Free text, kept in the summary."),
    Key("", "mesh", "table", REQUIRED, doc="See [mesh]."),
    Key("", "material", "array of tables", REQUIRED, doc="See [[material]]; at least one entry."),
    Key("", "fixed", "array of tables", doc="See [[fixed]]. A static scene needs at least one."),
    Key("", "loads", "table", doc="See [loads]."),
    Key("", "solver", "table", doc="See [solver]."),
    Key("", "probe", "array of tables", doc="See [[probe]]."),
    Key("", "output", "table", doc="See [output]; left out, nothing is written by a Python run."),
    Key("", "adapt", "array of tables", doc="See [[adapt]]."),
    Key("", "amplitude", "array of tables", doc="See [[amplitude]]."),
    Key("", "cut", "array of tables", doc="See [[cut]]."),
    Key("", "remove", "array of tables", doc="See [[remove]]."),
    Key("", "refine", "array of tables", doc="See [[refine]]."),
    Key("", "contact", "table", doc="See [contact]; an [[obstacle]] alone switches contact on with its defaults."),
    Key("", "obstacle", "array of tables", doc="See [[obstacle]]."),
    # -- [mesh] --------------------------------------------------------------------------------
    Key("mesh", "generate", "string", choices="runtime.scene.parser:GENERATORS",
        doc="A generated mesh: bar (a box of cells), plate or sphere (shell triangles), ball (solid "
            "tetrahedra). Give exactly one of generate and file."),
    Key("mesh", "file", "string (path)",
        doc="A mesh file in any meshio format (gmsh .msh included), relative to the scene file."),
    Key("mesh", "size", "array of 2 or 3 numbers", unit="m",
        default_text="[1.0, 0.2, 0.2] (2D: [1.0, 0.2]; plate: [1.0, 1.0])",
        doc="bar: the box's edge lengths (2 entries: a 2D mesh); plate: [a, b]."),
    Key("mesh", "cells", "array of 2 or 3 integers", default_text="[10, 2, 2] (2D: [10, 2]; plate: [8, 8])",
        doc="Cells along each axis (bar, plate)."),
    Key("mesh", "element", "string", choices="runtime.scene.keys:mesh_elements",
        default_text="hexahedron (2D: quad; plate and sphere: shell; ball: tetra)",
        doc="bar: tetra, tetra10, hexahedron, wedge, pyramid, mixed (3D); quad, triangle, triangle6, mixed (2D). "
            "plate, sphere and a file's triangles: shell. ball: tetra."),
    Key("mesh", "origin", _VEC, unit="m", default_text="the zero vector", doc="The corner of the generated bar or plate; "
        "the centre of the sphere or ball."),
    Key("mesh", "radius", "number", 0.5, "m", doc="sphere and ball: the radius."),
    Key("mesh", "subdivisions", "integer", 3, doc="sphere: icosphere subdivisions, 0 to 7 (20 x 4^s triangles)."),
    Key("mesh", "divisions", "integer", 6, doc="ball: cells along the central cube's edge, 1 to 40."),
    # -- [[material]] ----------------------------------------------------------------------------
    Key("material", "region", _REGION, "all",
        doc="\"all\", an element type, an integer cell tag or group id, or a volume group's name."),
    Key("material", "box", _BOX, unit="m", doc="Only the cells whose centroid lies in the box (with region: both)."),
    Key("material", "law", "string", "stvk", choices=_LAWS, doc="The constitutive law (see the catalogue)."),
    Key("material", "law_file", "string", doc="A law file outside the package (Python defining LAW = Law(...)), "
        "relative to the scene file; law is then the name it defines (see Materials, Your own law)."),
    Key("material", "quadrature", "string", "gauss2", choices=("gauss1", "gauss2", "gauss3", "exact", "discrete"),
        default_text="gauss2 (discrete laws: discrete; shells: exact)",
        doc="The integration rule; the element x law x quadrature must be in the catalogue."),
    Key("material", "E", "number", unit="Pa", doc="Young's modulus, > 0; with nu, or the law's native parameters."),
    Key("material", "nu", "number", unit="1", doc="Poisson's ratio, in (-1, 0.5); 0.5 (incompressible) with formulation = \"mixed\"."),
    Key("material", "density", "number", 1000.0, "kg/m^3", doc="Mass density, > 0."),
    Key("material", "formulation", "string", "displacement", choices="runtime.physics.formulations:FORMULATIONS",
        doc="How the law's volumetric part is integrated (see Materials and formulations)."),
    Key("material", "viscous", "array of tables",
        doc="Prony branches [{tau = 0.1, beta = 0.5}, ...]: relaxation time tau (s, > 0) and stiffness beta "
        "(>= 0) over the relaxed law's; the law's E and nu are the relaxed (long-term) ones."),
    Key("material", "fibres", "array or string", unit="1",
        doc="A law with fibre directions (hgo, hgo2): one per direction, a vector [1, 0, 0], \"FILE.py:FUNCTION\" "
        "(a function of the cells' rest centroids, (n, dim), returning (n, 3)) or \"NAME\" (the mesh file's "
        "cell data NAME, a vector per cell); normalised per cell."),
    # -- [[fixed]] -------------------------------------------------------------------------------
    Key("fixed", "box", _BOX, unit="m", doc="The nodes inside the box; box or region (or both) is required."),
    Key("fixed", "region", _REGION, doc="The nodes of a mesh group (name or id)."),
    Key("fixed", "displacement", _VEC, unit="m",
        doc="A prescribed displacement (left out: clamped), scaled by the amplitude (default: the ramp)."),
    Key("fixed", "components", "array of integers", default_text="all",
        doc="The constrained components (0 = x); shells: 3 to 5 are the rotations."),
    Key("fixed", "amplitude", "string", default_text="\"ramp\"",
        doc="The [[amplitude]] (or \"ramp\", \"constant\") scaling the displacement or motion."),
    Key("fixed", "rotation", "inline table", doc="A rigid rotation; see [[fixed]] rotation."),
    Key("fixed", "translation", _VEC, unit="m", doc="A rigid translation (with or without rotation)."),
    Key("fixed", "name", "string", default_text="\"fixed[i]\"", doc="The reaction's name; names must differ."),
    Key("fixed", "moment_about", _VEC, unit="m", default_text="the centroid of the entry's nodes at rest",
        doc="The point the reaction moment is taken about."),
    Key("fixed.rotation", "axis", "array of 3 numbers", doc="The axis direction (3D only; not zero)."),
    Key("fixed.rotation", "point", _VEC, REQUIRED, "m", doc="A point on the axis (2D: the centre)."),
    Key("fixed.rotation", "angle", "number", REQUIRED, "degree", doc="The angle at amplitude 1."),
    # -- [[amplitude]] ---------------------------------------------------------------------------
    Key("amplitude", "name", "string", REQUIRED,
        doc="The name loads and [[fixed]] entries refer to; not \"ramp\" or \"constant\" (built in)."),
    Key("amplitude", "time", "array of numbers", unit="s",
        doc="Abscissae in seconds (static runs: the load factor), >= 0, strictly increasing. "
            "Give time or factor."),
    Key("amplitude", "factor", "array of numbers", unit="1", doc="Abscissae in load factor, 0 to 1, strictly increasing."),
    Key("amplitude", "value", "array of numbers", REQUIRED, "1", doc="The amplitude at each abscissa."),
    # -- [loads] ---------------------------------------------------------------------------------
    Key("loads", "gravity", _VEC, unit="m/s^2", default_text="the zero vector", doc="Gravitational acceleration."),
    Key("loads", "gravity_amplitude", "string", doc="An amplitude scaling gravity."),
    Key("loads", "force", "array of tables", doc="See [[loads.force]]."),
    Key("loads", "traction", "array of tables", doc="See [[loads.traction]]."),
    Key("loads", "moment", "array of tables", doc="See [[loads.moment]]."),
    Key("loads", "pressure", "array of tables", doc="See [[loads.pressure]]."),
    Key("loads.force", "box", _BOX, unit="m", doc="The nodes inside; box or region (both: the intersection)."),
    Key("loads.force", "region", _REGION, doc="The nodes of a mesh group."),
    Key("loads.force", "value", _VEC, REQUIRED, "N", doc="The total force, split evenly over the nodes."),
    _load_amplitude("loads.force"),
    Key("loads.traction", "box", _BOX, unit="m", doc="The boundary faces with every node inside."),
    Key("loads.traction", "region", _REGION, doc="The boundary faces of a mesh group."),
    Key("loads.traction", "value", _VEC, REQUIRED, "Pa", doc="Force per unit area, integrated consistently."),
    _load_amplitude("loads.traction"),
    Key("loads.moment", "box", _BOX, unit="m", doc="The nodes inside."),
    Key("loads.moment", "region", _REGION, doc="The nodes of a mesh group."),
    Key("loads.moment", "value", "array of 3 numbers", REQUIRED, "N m", doc="The total moment (shells)."),
    _load_amplitude("loads.moment"),
    Key("loads.pressure", "box", _BOX, unit="m", doc="The boundary faces with every node inside."),
    Key("loads.pressure", "region", _REGION, doc="The boundary faces of a mesh group."),
    Key("loads.pressure", "value", "number", REQUIRED, "Pa",
        doc="Normal to the deformed surface; > 0 pushes inward."),
    Key("loads.pressure", "amplitude", "string", doc="An amplitude scaling it (dynamic runs only)."),
    # -- [solver] --------------------------------------------------------------------------------
    Key("solver", "kind", "string", "static", choices="runtime.scene.parser:SOLVER_KINDS", doc="The integrator."),
    Key("solver", "dt", "number", 0.01, "s", doc="The time step (dynamic runs; static runs with viscous "
        "materials: the time each load step lasts), > 0."),
    Key("solver", "steps", "integer", 1, doc="Time steps (dynamic) or load steps (static), 1 to 10^8."),
    Key("solver", "linear", "string", "auto", choices="runtime.scene.parser:LINEAR_SOLVERS", doc="The linear solver."),
    Key("solver", "cg_tolerance", "number", 1e-8, "1", doc="Relative residual of the CG solves."),
    Key("solver", "cg_max_iterations", "integer", 1000, doc="CG iterations at most."),
    Key("solver", "mode", "string", "exact", choices="runtime.scene.parser:SOLVER_MODES",
        doc="exact: every step solved to the tolerances above; interactive: implicit_euler's budgeted step "
            "(stiffness_every = 50, stiffness_tolerance = 5e-3, factor_tolerance = 1e-4 unless given; "
            "docs/guide/interactive.md)."),
    Key("solver", "stiffness_every", "integer", 1,
        doc="implicit_euler: K, the step's matrix and its factor kept for up to N steps; the steps between take "
            "fresh forces with the kept matrix. The summary estimates the trajectory error this costs."),
    Key("solver", "stiffness_tolerance", "number", 5e-3, "1",
        doc="With stiffness_every > 1: K is assembled sooner when a step's velocity error, estimated from the "
            "forces, passes this share of the largest speed (inf: every N steps only)."),
    Key("solver", "factor_tolerance", "number", 1e-10, "1",
        doc="Relative residual a factor's solve is refined to: a fresh PARDISO factor, or a kept band or PARDISO one."),
    Key("solver", "newton_tolerance", "number", 1e-8, "1", doc="Newton's relative residual."),
    Key("solver", "newton_max_iterations", "integer", 25, doc="Newton iterations per step at most."),
    Key("solver", "rayleigh", "array of 2 numbers", (0.0, 0.0), "1/s, s",
        doc="Rayleigh damping [alpha, beta]: D = alpha M + beta K, both >= 0."),
    Key("solver", "project_psd", "boolean",
        default_text="unset: plain Newton, the projection switched on when a step does not descend",
        doc="Project element Hessians onto positive semi-definite matrices."),
    Key("solver", "rho_inf", "number", 1.0, "1",
        doc="generalized_alpha only: spectral radius at infinite frequency, in [0, 1]; 1 = no numerical damping."),
    Key("solver", "backend", "string", choices="backends:BACKENDS",
        default_text="c when a C compiler is found (about 1 s to compile a kernel), else numba (6 to 40 s)",
        doc="The kernel backend (both give the same results)."),
    Key("solver", "device", "string", "cpu", choices="runtime.scene.parser:DEVICES",
        doc="cuda: implicit_euler's stiffness assembled and solved on the GPU (tensormass[cuda]; docs/guide/gpu.md "
            "says what such a run takes)."),
    Key("solver", "health_monitor", "boolean", True, doc="false: no health checks (the summary says so)."),
    Key("solver", "max_energy_growth", "number", 100.0, "1",
        doc="Stop when the energy balance grows by this times the scene's energy scale."),
    Key("solver", "max_displacement", "number", 10.0, "1",
        doc="Stop when a node moves this many body sizes away from the body's mean motion."),
    Key("solver", "on_inversion", "string", "warn", choices="runtime.scene.parser:INVERSION_ACTIONS",
        doc="Inverted elements of laws defined there: warn (invalid if still inverted at the end) or stop."),
    Key("solver", "mass", "string", "lumped", choices="runtime.scene.parser:MASS_KINDS",
        doc="Lumped (row sums, HRZ for quadratic elements) or consistent (implicit solvers only)."),
    Key("solver", "threads", "integer", default_text="$TENSORMASS_THREADS, else every core",
        doc="Assembly threads (tensormass run --threads overrides)."),
    Key("solver", "preserve_volume", "boolean", False, doc="Closed shells: project onto the rest volume after every step."),
    # -- [[probe]] -------------------------------------------------------------------------------
    Key("probe", "name", "string", default_text="\"probe<i>\"", doc="The probe's name; names must differ."),
    Key("probe", "point", _VEC, unit="m",
        doc="The displacement interpolated at this point (inside the body or on it within 10 % of a cell)."),
    Key("probe", "region", _REGION, doc="Instead of point: the mean displacement of a group's nodes."),
    Key("probe", "box", _BOX, unit="m", doc="Instead of point: the mean displacement of the nodes inside."),
    # -- [output] --------------------------------------------------------------------------------
    Key("output", "dir", "string (path)", doc="The output folder, relative to the scene file."),
    Key("output", "every", "integer", 1, doc="Write a frame every this many steps."),
    Key("output", "fields", "array of strings", choices="runtime.physics.fields:FIELDS",
        default_text="[\"von_mises\", \"cauchy_stress\", \"det_F_min\"]",
        doc="The fields every frame carries, each as cell or point data (name@cell / name@point: "
            "the other); [] for none."),
    Key("output", "picture", "boolean or string", default_text="none",
        doc="A PNG of the deformed body at the end: true (von Mises; the displacement where a kernel gives no "
            "stress, as co-rotational shells), a field name or \"displacement\"."),
    Key("output", "plot", "boolean", False, doc="The per-step history curves as summary.png."),
    Key("output", "view", "string or [azimuth, elevation]", default_text="[-60, 20]", unit="degrees",
        choices="runtime.scene.parser:VIEWS",
        doc="The picture's camera: top, bottom, front, back, left, right, or angles (run --view overrides)."),
    Key("output", "clip", "[[point...], [normal...]]", unit="m",
        doc="The picture's cut-away: only the cells whose rest centre lies on the side the normal points "
            "away from are drawn, with the faces the cut exposes."),
    # -- [[adapt]] -------------------------------------------------------------------------------
    Key("adapt", "criterion", "string", REQUIRED, choices="runtime.scene.parser:ADAPT_CRITERIA",
        doc="The per-element criterion (rotation in degrees)."),
    Key("adapt", "threshold", "number", REQUIRED, doc="The criterion's threshold, >= 0 (relative: in [0, 1])."),
    Key("adapt", "action", "string", "switch_law", choices="runtime.scene.parser:ADAPT_ACTIONS", doc="What a passing cell does."),
    Key("adapt", "law", "string", choices=_LAWS, doc="switch_law: the target law (required there)."),
    Key("adapt", "from", "string", choices=_LAWS, doc="switch_law: only cells under this law."),
    Key("adapt", "back", "number", doc="switch_law: switch back past this value (hysteresis)."),
    Key("adapt", "relative", "boolean", False, doc="The threshold is a fraction of the largest value."),
    Key("adapt", "below", "boolean", False, doc="Act when the criterion falls below the threshold."),
    Key("adapt", "every", "integer", 1, doc="Check every this many steps."),
    Key("adapt", "rounds", "integer", 1, doc="refine: refinement passes over the run at most."),
    # -- [[cut]], [[remove]], [[refine]] ---------------------------------------------------------
    *_when("cut"),
    Key("cut", "plane", "[[point...], [normal...]]", unit="m",
        doc="The plane (rest coordinates): faces between cells whose centroids lie on either side open."),
    Key("cut", "box", _BOX, unit="m", doc="Only the faces inside: an incision (a blade's start)."),
    Key("cut", "name", "string", doc="The event's name in the summary."),
    Key("cut", "criterion", "string", choices="runtime.scene.parser:TEAR_CRITERIA",
        doc="Tearing: open the faces across which the body is stretched past 1 + threshold."),
    Key("cut", "threshold", "number", unit="1", doc="Tearing: the stretch - 1 at which a face opens, > 0."),
    Key("cut", "every", "integer", 1, doc="Tearing: checked every this many steps."),
    Key("cut", "sweep", _VEC, unit="m", doc="A blade: the box moves by this vector from time over duration."),
    Key("cut", "duration", "number", unit="s", doc="A blade: how long the sweep takes."),
    *_when("remove"),
    Key("remove", "box", _BOX, unit="m", doc="The cells whose rest centroid lies inside."),
    Key("remove", "region", _REGION, doc="The cells of a mesh group (with box: both)."),
    Key("remove", "name", "string", doc="The event's name in the summary."),
    *_when("refine"),
    Key("refine", "box", _BOX, REQUIRED, "m", doc="The hexahedra whose rest centroid lies inside are split 1:8."),
    Key("refine", "name", "string", doc="The event's name in the summary."),
    # -- [contact] -------------------------------------------------------------------------------
    Key("contact", "method", "string", "ipc", choices="runtime.contact.base:METHODS",
        doc="ipc (barrier, CCD, friction; no surface ever crosses) or penalty (obstacles only; vertices may "
            "sink in). Which solver takes which: see Contact."),
    Key("contact", "dhat", "number", unit="m", default_text="dhat_relative x the body's bounding-box diagonal",
        doc="IPC: the distance below which the barrier acts."),
    Key("contact", "dhat_relative", "number", 1e-3, "1", doc="IPC: dhat as a fraction of the body's diagonal."),
    Key("contact", "stiffness", "number", unit="IPC: Pa m (barrier kappa); penalty: N/m",
        default_text="IPC: adaptive; penalty: 10 E h (E the largest Young's modulus, h the mean surface edge)",
        doc="IPC: the barrier stiffness; penalty: the spring per surface vertex."),
    Key("contact", "mu", "number", 0.0, "1", doc="IPC: Coulomb friction coefficient, >= 0 (0: frictionless)."),
    Key("contact", "friction_iterations", "integer", 2,
        doc="IPC friction: solves per step, each with the normal forces and tangents of the last (lagged)."),
    Key("contact", "eps_v", "number", unit="m/s", default_text="1e-3 x the body's diagonal per second",
        doc="IPC friction: the slip velocity below which friction is smoothed (static friction's stand-in)."),
    Key("contact", "self", "boolean", False, doc="IPC: a body against itself (its own surface)."),
    Key("contact", "bodies", "boolean", True, doc="IPC: distinct connected bodies of the mesh against each other."),
    Key("contact", "check_every", "integer", 1,
        doc="IPC: test the surfaces for intersection every this many steps (one found: status invalid)."),
    Key("contact", "max_penetration", "number", unit="m", default_text="1e-3 x the body's diagonal",
        doc="Penalty: warn when a vertex sinks deeper than this into an obstacle."),
    # -- [[obstacle]] ----------------------------------------------------------------------------
    Key("obstacle", "name", "string", default_text="\"obstacle[i]\"",
        doc="The obstacle's name in the history (its force and moment); names must differ."),
    Key("obstacle", "shape", "string", REQUIRED, choices="runtime.contact.obstacles:SHAPES",
        doc="plane (point, normal), sphere (center, radius), capsule (a, b, radius), box (box), mesh (file)."),
    Key("obstacle", "point", "array of 3 numbers", unit="m", doc="plane: a point on it."),
    Key("obstacle", "normal", "array of 3 numbers", doc="plane: the side the body stays on (not zero)."),
    Key("obstacle", "center", "array of 3 numbers", unit="m", doc="sphere: the centre."),
    Key("obstacle", "radius", "number", unit="m", doc="sphere, capsule: the radius, > 0."),
    Key("obstacle", "a", "array of 3 numbers", unit="m", doc="capsule: one end of the segment."),
    Key("obstacle", "b", "array of 3 numbers", unit="m", doc="capsule: the other end (not a)."),
    Key("obstacle", "box", "[[x0, y0, z0], [x1, y1, z1]]", unit="m", doc="box: its corners at rest (axis-aligned)."),
    Key("obstacle", "file", "string (path)",
        doc="mesh: a closed triangle surface (STL, OBJ, any meshio format), relative to the scene file; IPC only."),
    Key("obstacle", "scale", "number", 1.0, "1", doc="mesh: multiplies the file's coordinates."),
    Key("obstacle", "resolution", "number", unit="m", default_text="the body's mean surface edge",
        doc="sphere, capsule: the largest chord of the IPC tessellation, below the diameter."),
    Key("obstacle", "translation", "array of 3 numbers", unit="m",
        doc="A rigid translation at amplitude 1 (with or without rotation)."),
    Key("obstacle", "rotation", "inline table", doc="A rigid rotation; see [[obstacle]] rotation."),
    Key("obstacle", "amplitude", "string", default_text="\"ramp\"",
        doc="The [[amplitude]] (or \"ramp\", \"constant\") scaling the motion; needs translation or rotation."),
    Key("obstacle.rotation", "axis", "array of 3 numbers", REQUIRED, doc="The axis direction (not zero)."),
    Key("obstacle.rotation", "point", "array of 3 numbers", REQUIRED, "m", doc="A point on the axis."),
    Key("obstacle.rotation", "angle", "number", REQUIRED, "degree", doc="The angle at amplitude 1."),
)

# [[material]] also takes the law's native parameters (mu, lam, C10, ...) and options (A): they
# depend on the law, so the catalogue reference lists them per law (laws.get(name).parameters).
MATERIAL_LAW_PARAMETERS = "the law's native parameters and options (see the catalogue)"


def mesh_elements() -> tuple:
    """What mesh.element accepts: the generated bars' element types (mixed included) and shell."""
    from .parser import ELEMENTS_2D, ELEMENTS_3D      # deferred: the parser imports this module
    return tuple(dict.fromkeys(ELEMENTS_3D + ELEMENTS_2D + ("shell",)))


def builtin_laws() -> tuple:
    """What law names (material.law, adapt.law / from) list: the built-in laws.  A user law (law_file,
    $TENSORMASS_LAWS) is accepted too, but belongs to its user: the generated reference stays the
    same whatever law files the process that builds it has loaded."""
    from ... import laws        # deferred: 0.17 s; this module is the schema, cheap to import (docs)
    return tuple(laws.names(user=False))


def table_of(name: str) -> Table:
    for t in TABLES:
        if t.name == name:
            return t
    raise KeyError(name)


def keys_of(table: str) -> tuple:
    """The keys of one table, in declaration order."""
    return tuple(k for k in KEYS if k.table == table)


def allowed_values(key: Key) -> tuple | None:
    """The allowed values of a key: its tuple, or the code's list it names (dict keys for a dict,
    the result for a function)."""
    if key.choices is None or isinstance(key.choices, tuple):
        return key.choices
    module, attribute = key.choices.split(":")
    value = getattr(importlib.import_module(f"tensormass.{module}"), attribute)
    if callable(value):
        value = value()
    return tuple(value)
