"""A nearly incompressible block in 3D (`tensormass report accuracy --benchmark block`): tetrahedra lock.

A unit cube, clamped at z = 0, a uniform shear traction (0.01, 0, 0) on its top face z = 1; Hooke
with E = 1 and nu = 0.3 (compressible) or 0.4999 (nearly incompressible). The measured value is
u_x at the centre of the top face (0.5, 0.5, 1). Meshes are the generated structured cubes
(`mesh.generate = "bar"`): n x n x n hexahedral cells cut into 6 tetrahedra each (tetra), the same
with shared midside nodes (tetra10).

Series: tetra with the displacement formulation and with nodal_pressure (the locking-free choice of
linear tetrahedra), tetra10 with the displacement formulation and with mean_dilatation (P2-P0).
The reference of each nu is tetra10 + mean_dilatation on REFERENCE x REFERENCE x REFERENCE cells;
the report gives its value at half and a quarter of that resolution (how converged it is).
"""
from __future__ import annotations

import time

from .common import benchmark_row as _row
from .common import run_dict as _run

__all__ = ["block", "block_scene"]

TRACTION = 0.01
SERIES = (("tetra", "displacement"), ("tetra", "nodal_pressure"),
          ("tetra10", "displacement"), ("tetra10", "mean_dilatation"))
REFERENCE = ("tetra10", "mean_dilatation")
BLOCK_FULL = {"nus": [0.3, 0.4999], "levels": {"tetra": [4, 8, 16, 24], "tetra10": [4, 8]}, "reference": 16}
BLOCK_QUICK = {"nus": [0.3, 0.4999], "levels": {"tetra": [2, 4], "tetra10": [2]}, "reference": 4}


def block_scene(element: str, n: int, nu: float, formulation: str = "displacement") -> dict:
    return {"name": f"block_{element}_{n}", "mesh": {"generate": "bar", "size": [1.0, 1.0, 1.0],
                                                     "cells": [n, n, n], "element": element},
            "material": [{"region": "all", "law": "hooke", "quadrature": "gauss2", "E": 1.0, "nu": nu,
                          "density": 1.0, "formulation": formulation}],
            "fixed": [{"box": [[-1.0, -1.0, -1e-9], [2.0, 2.0, 1e-9]]}],
            "loads": {"traction": [{"box": [[-1.0, -1.0, 1.0 - 1e-9], [2.0, 2.0, 1.0 + 1e-9]],
                                    "value": [TRACTION, 0.0, 0.0]}]},
            "solver": {"kind": "static", "steps": 1},
            "probe": [{"name": "top", "point": [0.5, 0.5, 1.0]}]}


def _value(element, n, nu, formulation, trace=True):
    s, peak, _ = _run(block_scene(element, n, nu, formulation), trace=trace)
    return s, peak, float(s.probes["top"][0])


def block(quick, progress, sweep=None) -> dict:
    cfg = dict(BLOCK_QUICK if quick else BLOCK_FULL)
    cfg.update(sweep or {})
    ref_n = cfg["reference"]
    progress(f"block: unit cube, clamped base, shear traction on top, Hooke E = 1; tetra / tetra10 x "
             f"formulations, nu = {', '.join(f'{v:g}' for v in cfg['nus'])}")
    rows, compile_s, refs, checks = [], {}, {}, {}
    for element, form in SERIES:
        t0 = time.perf_counter()
        _value(element, 1, 0.3, form, trace=False)
        compile_s[(element, "hooke", "gauss2")] = compile_s.get((element, "hooke", "gauss2"), 0.0) + time.perf_counter() - t0
    for nu in cfg["nus"]:
        case = f"nu={nu:.4g}"
        values = {m: _value(*REFERENCE[:1], m, nu, REFERENCE[1], trace=False)[2]
                  for m in sorted({max(1, ref_n // 4), max(1, ref_n // 2), ref_n})}
        refs[case] = values[ref_n]
        checks[case] = values
        for element, form in SERIES:
            for n in cfg["levels"][element]:
                s, peak, w = _value(element, n, nu, form)
                r = _row("block", element, "hooke", "gauss2", (n, n, n), case, s, peak, w)
                r["formulation"] = form
                r["error_reference"] = abs(w - refs[case]) / abs(refs[case])
                r["main"] = nu == max(cfg["nus"])
                rows.append(r)
                progress(f"  {case:<10} {element:<8} {form:<16} {n:>3}^3 u_x(top) {w:.6g} "
                         f"({(w - refs[case]) / refs[case]:+.1%} vs reference)  total {s.time['total']:.3f} s")
    notes = ["### Top-centre displacement against the tetra10 + mean dilatation reference (signed error)", "",
             "| nu | element | formulation | cells per side: error |", "|---|---|---|---|"]
    for nu in cfg["nus"]:
        case = f"nu={nu:.4g}"
        for element, form in SERIES:
            cells = [r for r in rows if r["case"] == case and r["element"] == element and r["formulation"] == form]
            notes.append(f"| {nu:.4g} | {element} | {form} | " + ", ".join(
                f"{r['cells'].split('x')[0]}: {(r['value'] - refs[case]) / refs[case]:+.1%}" for r in cells) + " |")
    notes += ["", "### The reference (tetra10 + mean_dilatation)", "",
              "| nu | " + " | ".join(f"{m}^3" for m in sorted(next(iter(checks.values())))) + " |",
              "|---|" + "---:|" * len(next(iter(checks.values())))]
    for case, values in checks.items():
        notes.append(f"| {case.split('=')[1]} | " + " | ".join(f"{v:.6g}" for _, v in sorted(values.items())) + " |")
    notes += ["", "Linear tetrahedra lock at nu = 0.4999 with the displacement formulation (about half the "
              "reference displacement however fine the mesh); nodal pressure converges to the reference. "
              "The meshes are structured (6 tetrahedra per cube cell), not what a gmsh user brings.", ""]
    reference = {
        "subject": "unit cube clamped at z = 0, uniform shear traction (0.01, 0, 0) on z = 1, Hooke E = 1; "
                   "value = u_x at (0.5, 0.5, 1)",
        "numerical": f"tetra10 + mean_dilatation (P2-P0) / hooke / gauss2 on {ref_n}^3 cells (x6 tetrahedra): "
                     + ", ".join(f"{k}: {v:.6g}" for k, v in refs.items()),
        "analytic": "none; error_analytic is n/a",
    }
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": notes,
            "references": refs, "reference_checks": checks}
