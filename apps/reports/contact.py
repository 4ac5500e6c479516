"""`tensormass report contact`: contact rows against closed forms (Hertz, friction on an incline,
frictionless impact), each a measured number, its closed form and a pass/fail bound.

    rows = run_contact("out", quick=False)      # prints the table, writes out/contact.json
    hertz()         -> dict        # one row on the committed octant; hertz((0.15, 0.25)): meshed by gmsh
    incline(mu, theta_deg) -> dict
    impact()        -> dict

**Hertz.**  An elastic ball (R = 1 m, E = 1e5 Pa, nu = 0.3, law "hooke": small strain, as Hertz)
pressed by a rigid plane.  By symmetry only the octant x, y, z >= 0 is meshed: the symmetry planes
hold the normal component (x = 0: u_x, y = 0: u_y, z = 0: u_z), which is the ball squeezed between
two planes, each side indented by delta.  The octant is meshed by gmsh (`hertz_octant`): quadratic
tetrahedra (tetra10, gauss2; their edge middles on the sphere), of size `fine` a within 1.5 a of the
pole and growing to `coarse` R beyond 0.8 R, a = sqrt(R delta) the contact radius.  The full run
meshes it with fine = 0.15, coarse = 0.25 when gmsh is installed; otherwise, and in the quick run and
the tests, it reads HERTZ_MESH, the same octant meshed at fine = 0.25, coarse = 0.3 and committed
beside this module.  delta = 0.0025 R (a / R = 0.05: Hertz is a small a / R theory), dhat = 1e-3
delta.  The plate starts a gap g0 = 2 dhat above the pole and travels g0 + delta in `steps` load
steps; at each the indentation is the travel minus g0 minus the barrier's gap (the step's
min_distance).  Closed forms: F = (4/3) E* sqrt(R) delta^(3/2), E* = E / (1 - nu^2), a quarter of
it on the octant; contact radius a = sqrt(R delta); and, from the two, F = 4 E* a^3 / (3 R), which
holds the force against the measured radius.  The measured radius comes from the nodal contact
forces: Hertz's pressure p0 sqrt(1 - r^2/a^2) has the force-weighted mean <r^2> = 2 a^2 / 5, so
a = sqrt(5 <r^2> / 2) (robust to the mesh, unlike the outermost loaded node).

Hertz's delta is the approach of points far from the contact in a half-space; here it is measured
from the ball's centre, which the load moves too.  That difference is linear in the force, C F / (E R),
so the force against delta reads high by about (3/2) C F / (E R delta), a share growing like
sqrt(delta / R): the row prints force_error / sqrt(delta / R) per load step, constant when this is
all that is left.  The force against the measured radius does not see it (both are local to the
contact).

**Friction.**  A hexahedral block (neo-Hookean, E = 1e6 Pa) on a horizontal plane under tilted
gravity g (sin t, 0, -cos t), backward Euler.  mu > tan t: it sticks; IPC's friction is smoothed
(below the slip speed eps_v it acts as a viscous-like force), so "sticks" means the block's mean
speed after settling stays below eps_v; the creep that smoothing allows has the closed form
eps_v (1 - sqrt(1 - tan t / mu)) (ipctk's mollifier f1(s) = 2 s - s^2 for s = v / eps_v < 1), printed next to it.  mu < tan t: the mean x
displacement after the first third of the run is fitted by x0 + v0 t + a t^2 / 2 and a is
compared with g (sin t - mu cos t), bound 2 %.  dhat = 1e-4 m (the barrier's gap is then far below
the block's size), eps_v = 1e-3 m/s, dt = 0.01 s, friction_iterations = 2 (the default).

**Impact.**  Two cubes of one mesh file ([contact] bodies = true), no gravity, nothing fixed,
initial velocities +-V along x (Simulation(scene, v0=...)), backward Euler.  Contact forces are
equal and opposite pair by pair, so the total momentum (the consistent mass matrix times the
velocity, summed per component) stays at its initial value (zero) to round-off: the bound is
1e-10 of one body's momentum m V, far above double rounding (1e-16) and far below what a
missing reaction would give (order 1).  The bodies separate: the facing faces' gap is positive
at the end and the mean velocities point apart.

**What was measured** (full run): slide a = 3.2062 against 3.2059 m/s^2 (+0.01 %); stick creep
5.864e-4 against 5.814e-4 m/s (x_end 0.2 mm); impact momentum drift 6.6e-14 m V, end gap +0.053 m,
velocities -+0.229 m/s.  Hertz: see docs/guide/reports.md for the table of meshes, deltas and dhat.
"""
from __future__ import annotations

import importlib.util
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from ...runtime.base.errors import TensormassError
from ...runtime.base.files import write_json_atomic
from ...runtime.scene.scene import Scene

__all__ = ["hertz", "hertz_octant", "HERTZ_MESH", "incline", "impact", "run_contact", "add_contact_command", "table", "FULL", "QUICK"]

G = 9.81
# Hertz
R, E_BALL, NU_BALL, DELTA = 1.0, 1e5, 0.3, 0.0025
DHAT_HERTZ = 1e-3 * DELTA
HERTZ_MESH = Path(__file__).with_name("hertz_octant.vtu")     # hertz_octant(fine=0.25, coarse=0.3), committed
# friction
BLOCK, E_BLOCK, RHO, DHAT_FRICTION, EPS_V = (0.1, 0.1, 0.05), 1e6, 1000.0, 1e-4, 1e-3
# impact
CUBE, GAP, SPEED = 0.1, 0.02, 1.0

FULL = {"hertz_sizes": (0.15, 0.25), "block_cells": (2, 2, 1), "friction_dt": 0.01, "friction_steps": 30,
        "impact_cells": 2, "impact_dt": 0.005, "impact_steps": 30}
QUICK = {"hertz_sizes": None, "block_cells": (1, 1, 1), "friction_dt": 0.01, "friction_steps": 20,
         "impact_cells": 1, "impact_dt": 0.005, "impact_steps": 20}
BOUNDS = {"hertz_force": 0.05, "hertz_radius": 0.05, "hertz_force_radius": 0.05, "slide": 0.02, "momentum": 1e-10}


def _write_mesh(path, points, cell_type, cells) -> str:
    import meshio                       # deferred: the report's --help needs none of it

    meshio.write(str(path), meshio.Mesh(points, [(cell_type, cells)]))
    return str(path)


def _simulation(scene_dict, **kwargs):
    from ...runtime.run.simulation import Simulation    # deferred: heavy import, not needed for --help

    return Simulation(Scene.from_dict(scene_dict), output=False, **kwargs)


def hertz_octant(path, delta: float = DELTA, fine: float = 0.25, coarse: float = 0.3) -> str:
    """Mesh the octant x, y, z >= 0 of the ball of radius R with gmsh into `path` (tetra10, written with
    meshio): element size fine a up to 1.5 a from the pole (0, 0, R), a = sqrt(R delta), growing to
    coarse R beyond 0.8 R; second order, so the edge middles lie on the sphere."""
    try:
        import gmsh
    except ImportError:
        raise TensormassError("report contact: meshing the Hertz octant needs gmsh (pip install "
                              "'tensormass[mesh]'); without it the report reads the committed octant") from None
    import meshio                       # deferred: the report's --help needs none of it

    a = math.sqrt(R * delta)
    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("hertz_octant")
        occ = gmsh.model.occ
        occ.intersect([(3, occ.addSphere(0.0, 0.0, 0.0, R))], [(3, occ.addBox(0.0, 0.0, 0.0, 2 * R, 2 * R, 2 * R))])
        pole = occ.addPoint(0.0, 0.0, R)
        occ.synchronize()
        field = gmsh.model.mesh.field
        field.add("Distance", 1)
        field.setNumbers(1, "PointsList", [pole])
        field.add("Threshold", 2)
        for key, value in (("InField", 1), ("SizeMin", fine * a), ("SizeMax", coarse * R),
                           ("DistMin", 1.5 * a), ("DistMax", 0.8 * R)):
            field.setNumber(2, key, value)
        field.setAsBackgroundMesh(2)
        for key in ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature"):
            gmsh.option.setNumber(key, 0)
        gmsh.option.setNumber("Mesh.ElementOrder", 2)
        gmsh.model.mesh.generate(3)
        with tempfile.TemporaryDirectory() as tmp:
            msh = str(Path(tmp) / "octant.msh")
            gmsh.write(msh)
            mesh = meshio.read(msh)     # meshio maps gmsh's tetra10 node order to VTK's
    finally:
        gmsh.finalize()
    cells = mesh.get_cells_type("tetra10")
    used = np.unique(cells)             # drop the pole point and any node no tetrahedron uses
    renumber = np.full(len(mesh.points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    meshio.write(str(path), meshio.Mesh(mesh.points[used], [("tetra10", renumber[cells])]))
    return str(path)


def hertz(sizes=None, delta: float = DELTA, dhat: float = DHAT_HERTZ, steps: int = 4, mesh=None) -> dict:
    """The octant of an elastic ball pressed by a rigid plane (module docstring): measured force and
    contact radius against Hertz's.  sizes: (fine, coarse) to mesh the octant with gmsh, or None to
    read `mesh` (default HERTZ_MESH)."""
    g0 = 2.0 * dhat
    eps = 1e-9 * R
    with tempfile.TemporaryDirectory() as tmp:
        if sizes is not None:
            mesh = hertz_octant(Path(tmp) / "hertz_octant.vtu", delta, *sizes)
        mesh = str(mesh or HERTZ_MESH)
        scene = {"name": "hertz", "mesh": {"file": mesh},
                 "material": [{"law": "hooke", "quadrature": "gauss2", "E": E_BALL, "nu": NU_BALL}],
                 "fixed": [{"name": "sym_x", "box": [[-eps, -2 * R, -2 * R], [eps, 2 * R, 2 * R]], "components": [0]},
                           {"name": "sym_y", "box": [[-2 * R, -eps, -2 * R], [2 * R, eps, 2 * R]], "components": [1]},
                           {"name": "sym_z", "box": [[-2 * R, -2 * R, -eps], [2 * R, 2 * R, eps]], "components": [2]}],
                 "contact": {"dhat": dhat},
                 "obstacle": [{"name": "plate", "shape": "plane", "point": [0.0, 0.0, R + g0], "normal": [0.0, 0.0, -1.0],
                               "translation": [0.0, 0.0, -(delta + g0)]}],
                 "solver": {"kind": "static", "steps": steps, "newton_max_iterations": 60}, "output": {"fields": []}}
        start = time.perf_counter()
        sim = _simulation(scene)
        summary = sim.run()
        wall = time.perf_counter() - start
    points = np.asarray(sim.model.mesh.points, dtype=float)
    e_star = E_BALL / (1.0 - NU_BALL ** 2)
    travel = (delta + g0) * np.arange(1, steps + 1) / steps
    indentations = travel - g0 - np.asarray(summary.per_step["contact"]["min_distance"], dtype=float)
    forces = 4.0 * np.asarray(summary.per_step["obstacles"]["plate"]["force"], dtype=float)[:, 2]   # the octant: a quarter
    touching = indentations > 0.0
    errors = np.full(steps, np.nan)
    errors[touching] = forces[touching] / (4.0 / 3.0 * e_star * math.sqrt(R) * indentations[touching] ** 1.5) - 1.0
    indentation, force = float(indentations[-1]), float(forces[-1])
    nodal = np.asarray(sim.model.contact.nodal_forces(sim.ctx.u)).reshape(-1, 3)[:len(points)]
    weight = np.abs(nodal[:, 2])
    r2 = (points[:, 0] ** 2 + points[:, 1] ** 2)
    radius = math.sqrt(2.5 * float((weight * r2).sum() / weight.sum()))
    force_hertz = 4.0 / 3.0 * e_star * math.sqrt(R) * indentation ** 1.5
    radius_hertz = math.sqrt(R * indentation)
    force_of_radius = 4.0 * e_star * radius ** 3 / (3.0 * R)
    return {"row": "hertz", "status": summary.status, "mesh": "gmsh" if sizes is not None else Path(mesh).name,
            "sizes": None if sizes is None else list(sizes), "delta": delta, "dhat": dhat,
            "nodes": int(len(points)), "cells": int(sim.model.mesh.n_cells),
            "indentation": indentation, "force": force, "force_hertz": force_hertz,
            "force_error": force / force_hertz - 1.0, "radius": radius, "radius_hertz": radius_hertz,
            "radius_error": radius / radius_hertz - 1.0,
            "force_of_radius": force_of_radius, "force_radius_error": force / force_of_radius - 1.0,
            "step_indentations": indentations.tolist(), "step_force_errors": errors.tolist(),
            "finite_ball": (errors / np.sqrt(np.maximum(indentations, 1e-300) / R)).tolist(),
            "loaded_nodes": int((weight > 0).sum()),
            "newton_iterations": int(summary.iterations["newton"]), "wall_time": wall}


def incline(mu: float, theta_deg: float, cells=FULL["block_cells"], dt: float = FULL["friction_dt"],
            steps: int = FULL["friction_steps"], eps_v: float = EPS_V, dhat: float = DHAT_FRICTION) -> dict:
    """A block on a plane under gravity tilted by theta (module docstring): sticks or slides."""
    theta = math.radians(theta_deg)
    scene = {"name": "incline",
             "mesh": {"generate": "bar", "size": list(BLOCK), "cells": list(cells), "element": "hexahedron",
                      "origin": [0.0, 0.0, 2.0 * dhat]},
             "material": [{"law": "neohookean", "quadrature": "gauss2", "E": E_BLOCK, "nu": 0.3, "density": RHO}],
             "loads": {"gravity": [G * math.sin(theta), 0.0, -G * math.cos(theta)]},
             "contact": {"mu": mu, "eps_v": eps_v, "dhat": dhat},
             "obstacle": [{"name": "floor", "shape": "plane", "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}],
             "solver": {"kind": "backward_euler", "dt": dt, "steps": steps}, "output": {"fields": []}}
    xs = []
    start = time.perf_counter()
    sim = _simulation(scene, on_step=lambda s: xs.append(float(s.displacement[:, 0].mean())))
    summary = sim.run()
    wall = time.perf_counter() - start
    x = np.array(xs)
    t = dt * np.arange(1, len(x) + 1)
    first = len(x) // 3                           # contact settles (the block starts 2 dhat above the floor)
    basis = np.vstack([np.ones(len(x) - first), t[first:], 0.5 * t[first:] ** 2]).T
    x0, v0, a = np.linalg.lstsq(basis, x[first:], rcond=None)[0]
    a_theory = G * (math.sin(theta) - mu * math.cos(theta))
    creep = float((x[-1] - x[first]) / (t[-1] - t[first]))
    slides = mu < math.tan(theta)
    # sticking under smoothed friction: mu N f1(v / eps_v) = N tan t with f1(s) = 2 s - s^2 (ipctk's
    # mollifier below eps_v) gives the creep speed v = eps_v (1 - sqrt(1 - tan t / mu))
    creep_theory = float("nan") if slides else eps_v * (1.0 - math.sqrt(1.0 - math.tan(theta) / mu))
    row = {"row": "friction_slide" if slides else "friction_stick", "status": summary.status, "mu": mu,
           "theta_deg": theta_deg, "tan_theta": math.tan(theta), "dt": dt, "steps": steps, "eps_v": eps_v,
           "dhat": dhat, "x_end": float(x[-1]), "acceleration": float(a), "acceleration_theory": max(a_theory, 0.0),
           "mean_speed": creep, "creep_theory": creep_theory, "newton_iterations": int(summary.iterations["newton"]), "wall_time": wall}
    row["acceleration_error"] = float(a / a_theory - 1.0) if slides else float("nan")
    return row


def _cube(cells: int):
    g = np.linspace(0.0, CUBE, cells + 1)
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    points = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    i = np.arange(len(points)).reshape(cells + 1, cells + 1, cells + 1)
    a, b = i[:-1, :-1, :-1].ravel(), i[1:, :-1, :-1].ravel()
    c, d = i[1:, 1:, :-1].ravel(), i[:-1, 1:, :-1].ravel()
    e, f = i[:-1, :-1, 1:].ravel(), i[1:, :-1, 1:].ravel()
    gg, h = i[1:, 1:, 1:].ravel(), i[:-1, 1:, 1:].ravel()
    return points, np.stack([a, b, c, d, e, f, gg, h], axis=1)


def impact(cells: int = FULL["impact_cells"], dt: float = FULL["impact_dt"], steps: int = FULL["impact_steps"],
           folder=None) -> dict:
    """Two cubes meeting head on, frictionless (module docstring): momentum and separation."""
    points, hexes = _cube(cells)
    n = len(points)
    both = np.vstack([points, points + [CUBE + GAP, 0.0, 0.0]])
    v0 = np.zeros_like(both)
    v0[:n, 0], v0[n:, 0] = SPEED, -SPEED
    momenta = []
    with tempfile.TemporaryDirectory() as tmp:
        mesh = _write_mesh(Path(folder or tmp) / "two_cubes.vtu", both, "hexahedron", np.vstack([hexes, hexes + n]))
        scene = {"name": "impact", "mesh": {"file": mesh},
                 "material": [{"law": "neohookean", "quadrature": "gauss2", "E": 1e5, "nu": 0.3, "density": RHO}],
                 "contact": {"bodies": True, "dhat": 1e-4},
                 "solver": {"kind": "backward_euler", "dt": dt, "steps": steps}, "output": {"fields": []}}

        def record(sim):
            v = sim.ctx.v[:3 * len(both)]
            momenta.append((sim.model.mass_matrix @ v).reshape(-1, 3).sum(axis=0))

        start = time.perf_counter()
        sim = _simulation(scene, v0=v0, on_step=record)
        summary = sim.run()
        wall = time.perf_counter() - start
    body = RHO * CUBE ** 3 * SPEED
    drift = float(np.abs(np.array(momenta)).max()) / body      # the initial total momentum is zero
    x = both + sim.displacement
    v = sim.velocity
    return {"row": "impact", "status": summary.status, "cells": int(2 * len(hexes)), "steps": steps, "dt": dt,
            "momentum_drift": drift, "contact_steps": int(sum(1 for p in summary.per_step["contact"]["pairs"] if p)),
            "gap_end": float(x[n:, 0].min() - x[:n, 0].max()), "velocity_left": float(v[:n, 0].mean()),
            "velocity_right": float(v[n:, 0].mean()), "newton_iterations": int(summary.iterations["newton"]),
            "wall_time": wall}


def verdicts(rows) -> list:
    """(row name, measured, closed form, bound, passed) per checked quantity."""
    out = []
    for r in rows:
        if r["row"] == "hertz":
            out.append(("Hertz force [N]", r["force"], r["force_hertz"], BOUNDS["hertz_force"],
                        abs(r["force_error"]) <= BOUNDS["hertz_force"]))
            out.append(("Hertz contact radius [m]", r["radius"], r["radius_hertz"], BOUNDS["hertz_radius"],
                        abs(r["radius_error"]) <= BOUNDS["hertz_radius"]))
            out.append(("Hertz force [N] against the radius", r["force"], r["force_of_radius"],
                        BOUNDS["hertz_force_radius"], abs(r["force_radius_error"]) <= BOUNDS["hertz_force_radius"]))
        elif r["row"] == "friction_slide":
            out.append((f"slide a [m/s^2] (mu {r['mu']}, {r['theta_deg']} deg)", r["acceleration"],
                        r["acceleration_theory"], BOUNDS["slide"], abs(r["acceleration_error"]) <= BOUNDS["slide"]))
        elif r["row"] == "friction_stick":
            out.append((f"stick creep [m/s] (mu {r['mu']}, {r['theta_deg']} deg)", r["mean_speed"],
                        r["creep_theory"], r["eps_v"], abs(r["mean_speed"]) < r["eps_v"]))
        elif r["row"] == "impact":
            out.append(("impact momentum drift / (m V)", r["momentum_drift"], 0.0, BOUNDS["momentum"],
                        r["momentum_drift"] <= BOUNDS["momentum"]))
            out.append(("impact end gap [m] (> 0: apart)", r["gap_end"], 0.0, 0.0,
                        r["gap_end"] > 0 and r["velocity_left"] < 0 < r["velocity_right"]))
    return out


def table(rows) -> str:
    head = f"{'check':<44} {'measured':>12} {'closed form':>12} {'bound':>8}  pass"
    lines = [head, "-" * len(head)]
    for name, measured, closed, bound, ok in verdicts(rows):
        lines.append(f"{name:<44} {measured:>12.5g} {closed:>12.5g} {bound:>8.3g}  {'yes' if ok else 'NO'}")
    return "\n".join(lines)


def run_contact(out, quick: bool = False, progress=print) -> list:
    """Every row; prints the table and writes out/contact.json (atomically)."""
    cfg = QUICK if quick else FULL
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    friction = dict(cells=cfg["block_cells"], dt=cfg["friction_dt"], steps=cfg["friction_steps"])
    rows = [_hertz(cfg["hertz_sizes"], progress), incline(0.2, 30.0, **friction), incline(0.7, 30.0, **friction),
            impact(cfg["impact_cells"], cfg["impact_dt"], cfg["impact_steps"])]
    checks = [{"check": c[0], "measured": c[1], "closed_form": c[2], "bound": c[3], "passed": c[4]}
              for c in verdicts(rows)]
    write_json_atomic(out / "contact.json", {"case": {"quick": quick, **cfg, "bounds": BOUNDS}, "rows": rows,
                                             "checks": checks})
    if progress is not None:
        progress(table(rows))
        progress(f"wrote {out / 'contact.json'}")
    return rows


def _hertz(sizes, progress) -> dict:
    """The Hertz row: the octant meshed by gmsh at `sizes`, or the committed one when sizes is None or
    gmsh is not installed (said on the way)."""
    if sizes is not None and importlib.util.find_spec("gmsh") is None:
        if progress is not None:
            progress(f"report contact: gmsh is not installed, so Hertz runs on the committed octant "
                     f"{HERTZ_MESH.name} (pip install 'tensormass[mesh]' for the finer one)")
        sizes = None
    row = hertz(sizes)
    if progress is not None:
        steps = ", ".join(f"{100 * e:+.2f} % ({100 * d:.3f})" for e, d in
                          zip(row["step_force_errors"], row["step_indentations"]))
        progress(f"Hertz on {row['mesh']} ({row['nodes']} nodes, {row['loaded_nodes']} loaded): force error per "
                 f"load step (delta / R, %): {steps}; error / sqrt(delta / R): "
                 + ", ".join(f"{c:.3f}" for c in row["finite_ball"]))
    return row


def _cmd_contact(args) -> int:
    """Exit 1 if a run failed or a check is outside its bound."""
    rows = run_contact(args.out, quick=args.quick)
    ran = all(r["status"] in ("ok", "warnings") for r in rows)
    return 0 if ran and all(c[4] for c in verdicts(rows)) else 1


def add_contact_command(subparsers) -> None:
    p = subparsers.add_parser("contact", help="contact against closed forms: Hertz, friction on an incline, impact")
    p.add_argument("--quick", action="store_true", help="coarse meshes and few steps")
    p.add_argument("--out", default="tensormass-contact", help="output folder for contact.json")
    p.set_defaults(run=_cmd_contact)
