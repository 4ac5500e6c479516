"""`tensormass bench steps`: time per implicit Euler step and per Newton iteration on large bodies.

Bodies: a ~10 000-tetrahedron and a ~20 000-hexahedron bar (stvk and neohookean),
clamped at one end under gravity. For each: an implicit Euler step (one
linearisation, the thesis' scheme) and the Newton iterations of a static solve,
each split into assembly and linear solve, with the direct and the CG solver.
"""
from __future__ import annotations

import time

from .bench import machine_info, write_json_atomic

BODIES = {
    # name: (element, cells, size)
    "tetra_10k": ("tetra", (24, 6, 12), (2.0, 0.5, 1.0)),
    "hexahedron_20k": ("hexahedron", (60, 18, 18), (3.0, 0.9, 0.9)),
}
QUICK_BODIES = {
    "tetra_1k": ("tetra", (12, 3, 5), (2.0, 0.5, 1.0)),
    "hexahedron_2k": ("hexahedron", (24, 9, 9), (3.0, 0.9, 0.9)),
}
LAWS = ("stvk", "neohookean")


def scene_text(element, cells, size, law, kind, linear, steps) -> str:
    quadrature = "gauss1" if element == "tetra" else "gauss2"
    return f"""
name = "bench_{element}_{law}_{kind}"
[mesh]
generate = "bar"
size = {list(size)}
cells = {list(cells)}
element = "{element}"
[[material]]
region = "all"
law = "{law}"
quadrature = "{quadrature}"
E = 1.0e6
nu = 0.3
density = 1000.0
[[fixed]]
box = [[-1e-9, -10, -10], [1e-9, 10, 10]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "{kind}"
dt = {1 / 60}
steps = {steps}
linear = "{linear}"
rayleigh = [0.1, 0.01]
"""


def measure(element, cells, size, law, kind, linear, steps) -> dict:
    from .scene import Scene
    from .simulation import Simulation
    scene = Scene.from_string(scene_text(element, cells, size, law, kind, linear, steps))
    t0 = time.perf_counter()
    summary = Simulation(scene).run().to_dict()
    wall = time.perf_counter() - t0
    t, it = summary["time"], summary["iterations"]
    newton = max(it["newton"], 1)
    per = steps if kind != "static" else newton
    return {
        "kind": kind, "linear": linear, "law": law, "element": element,
        "elements": summary.get("n_elements"), "free_dofs": summary.get("n_free_dofs"),
        "steps": steps, "newton": it["newton"], "linear_iterations": it["linear"],
        "setup_s": t["setup"], "wall_s": wall,
        "assembly_per_unit_s": t["assembly"] / per, "solve_per_unit_s": t["linear_solve"] / per,
        "per_unit_s": (t["total"] - t["setup"]) / per,
        "unit": "step" if kind != "static" else "newton iteration",
    }


def run_steps_bench(quick=False, json_path=None, progress=print) -> dict:
    bodies = QUICK_BODIES if quick else BODIES
    results = []
    for body, (element, cells, size) in bodies.items():
        for law in LAWS:
            for kind, steps in (("implicit_euler", 3), ("static", 1)):
                for linear in ("direct", "cg"):
                    r = {"body": body, **measure(element, cells, size, law, kind, linear, steps)}
                    results.append(r)
                    if progress:
                        progress(f"{body:15s} {law:11s} {kind:15s} {linear:6s} {r['elements']:6d} el {r['free_dofs']:6d} dofs: "
                                 f"{1e3 * r['per_unit_s']:8.1f} ms per {r['unit']} (assembly {1e3 * r['assembly_per_unit_s']:.1f} ms, "
                                 f"solve {1e3 * r['solve_per_unit_s']:.1f} ms; {r['linear_iterations']} linear iterations)")
    report = {"machine": machine_info(), "quick": quick, "results": results}
    if json_path:
        write_json_atomic(json_path, report)
    return report


def cmd_steps(args) -> int:
    run_steps_bench(quick=args.quick, json_path=args.json)
    return 0


def add_steps_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("steps", help="time per implicit Euler step and per Newton iteration (10k tets, 20k hexes)")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="small bodies (CI smoke test)")
    p.set_defaults(run=cmd_steps)
