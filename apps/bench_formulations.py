"""`tensormass bench formulations`: what a locking-free formulation costs per Newton iteration.

The scenes of `tensormass bench organ` (neo-Hookean, nu = 0.45, static: gravity and a tool's
traction on the unstructured gmsh organ; the hexahedral cantilever) run with the displacement
formulation and with the element's locking-free one (runtime.physics.formulations: nodal_pressure on
tetra, mean_dilatation on tetra10 and hexahedra), one thread, best of `repeats`.  Reported per
case: ms per Newton iteration (assembly + linear solve, from the run's Summary.time), the
assembly's share, Newton iterations, the stiffness matrix's stored entries (nodal pressure couples
the nodes around a node: a wider pattern) and the probe; the ratios formulation / displacement
are the extra cost.  Needs gmsh for the organ meshes (tensormass[mesh]).
"""
from __future__ import annotations

import re
import time

from ..runtime.base import parallel
from ..runtime.base.files import write_json_atomic
from .bench_organ import Case, organ_mesh, probe_point, scene_text
from .machine import machine_info
from ..runtime.scene.scene import Scene
from ..runtime.run.simulation import Simulation

__all__ = ["run_formulations_bench", "add_formulations_command"]

CASES = (
    (Case("tetra_h6_static", "organ", "tetra", "static", 1, size=0.006), "nodal_pressure"),
    (Case("tetra10_h8_static", "organ", "tetra10", "static", 1, size=0.008), "mean_dilatation"),
    (Case("hex_cantilever_48x8x8", "cantilever", "hexahedron", "static", 1, cells=(48, 8, 8)), "mean_dilatation"),
)
QUICK_CASES = (
    (Case("quick_tetra_h12_static", "organ", "tetra", "static", 1, size=0.012, scale=1.0), "nodal_pressure"),
    (Case("quick_hex_cantilever_12x2x4", "cantilever", "hexahedron", "static", 1, cells=(12, 2, 4)), "mean_dilatation"),
)


def _scene(case: Case, formulation: str):
    mesh = organ_mesh(case)[0] if case.body == "organ" else None
    text = scene_text(case, mesh)
    text = re.sub(r"(?m)^(nu = .*)$", rf'\1\nformulation = "{formulation}"', text, count=1)
    point = probe_point(case)
    text += f'\n[[probe]]\nname = "probe"\npoint = [{point[0]}, {point[1]}, {point[2]}]\n'
    return Scene.from_string(text)


def _measure(case: Case, formulation: str, repeats: int) -> dict:
    best = None
    for _ in range(repeats):
        sim = Simulation(_scene(case, formulation), output=False)
        s = sim.run()
        if s.status not in ("ok", "warnings"):
            raise RuntimeError(f"bench formulations: {case.name} with {formulation} ended {s.status}: {s.message}")
        newton = max(1, int(s.iterations.get("newton", 0)))
        row = {"newton": newton, "ms_per_iteration": 1e3 * (s.time["assembly"] + s.time["linear_solve"]) / newton,
               "assembly_ms_per_iteration": 1e3 * s.time["assembly"] / newton,
               "setup_s": s.time["setup"], "probe": [float(x) for x in s.probes["probe"]],
               "matrix_entries": int(sim.ctx.asm.pattern.nnz)}
        if best is None or row["ms_per_iteration"] < best["ms_per_iteration"]:
            best = row
    return best


def run_formulations_bench(quick=False, json_path=None, repeats=None, progress=print, cases=None) -> dict:
    cases = cases or (QUICK_CASES if quick else CASES)
    repeats = repeats or (1 if quick else 2)
    parallel.set_threads(1)
    report = {"machine": machine_info(), "quick": quick, "threads": 1, "repeats": repeats, "cases": {}}
    for case, formulation in cases:
        t0 = time.perf_counter()
        base = _measure(case, "displacement", repeats)
        other = _measure(case, formulation, repeats)
        ratio = other["ms_per_iteration"] / base["ms_per_iteration"]
        report["cases"][case.name] = {"title": case.title, "formulation": formulation, "displacement": base,
                                      formulation: other, "ratio_per_iteration": ratio,
                                      "ratio_assembly": other["assembly_ms_per_iteration"] / base["assembly_ms_per_iteration"]}
        progress(f"{case.title}: displacement {base['ms_per_iteration']:.2f} ms/iteration "
                 f"(assembly {base['assembly_ms_per_iteration']:.2f}, {base['newton']} its), {formulation} "
                 f"{other['ms_per_iteration']:.2f} ms/iteration (assembly {other['assembly_ms_per_iteration']:.2f}, "
                 f"{other['newton']} its): {ratio:.2f}x per iteration; matrix entries {base['matrix_entries']} -> "
                 f"{other['matrix_entries']}; probe u_z {base['probe'][-1]:.4g} -> "
                 f"{other['probe'][-1]:.4g} m  ({time.perf_counter() - t0:.0f} s)")
    if json_path is not None:
        write_json_atomic(json_path, report)
    return report


def cmd_formulations(args) -> int:
    run_formulations_bench(quick=args.quick, json_path=args.json)
    return 0


def add_formulations_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("formulations", help="extra cost per Newton iteration of the locking-free "
                                    "formulations (organ tetra / tetra10, hexahedral cantilever; needs gmsh)")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="small meshes, one repeat (CI smoke test)")
    p.set_defaults(run=cmd_formulations)
