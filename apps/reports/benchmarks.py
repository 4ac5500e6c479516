"""The extra built-in benchmarks of `tensormass report accuracy --benchmark NAME`.

Each benchmark is a function (quick, progress, sweep) -> dict with
  rows       result rows (accuracy.COLUMNS; rows with main=False are shown but left out of the
             Pareto front and the plots),
  reference  {"subject", "numerical", "analytic"} lines for report.md,
  compile_s  {(element, law, quadrature): warm-up seconds},
  notes      extra markdown lines for the benchmark's section in report.md.

beam2d            the thesis' 2D beam (plane strain) under self weight: triangle / triangle6 / quad;
volume            volume change of a 5 m cube compressed by 5 % and 20 % for nu = 0, 0.25, 0.499;
mixed             the thesis' mixed bar (8 x 1 x 1 m) against all-hexahedron and tetra10;
large_deflection  a soft cantilever bending ~1/3 of its length: hooke vs stvk vs neohookean vs
                  stable_neohookean, and how Hooke's error grows with the load;
shear             the thesis' ch. 7 shear of a 5 m cube: bottom clamped, top moved sideways by 1 % of
                  the edge (its other components held at 0); lateral reaction force on the top face;
torsion           the same cube, top face turned rigidly by a small angle about the vertical axis
                  through its centre; torque of the reaction forces on the top face.
"""
from __future__ import annotations

import copy
import math
import time
import tracemalloc

import numpy as np

from ...runtime.scene.scene import Scene
from .common import analytic_tip
from .common import benchmark_row as _row
from .common import cells_label as _cells
from .common import run_dict as _run

__all__ = ["BENCHMARKS", "beam2d", "volume", "mixed", "large_deflection", "shear", "torsion",
           "deformed_volume", "VOLUME_REFERENCE", "shear_analytic", "torsion_analytic", "cube_run"]


# -- shared helpers (the others: common.py) ---------------------------------------------------------
def _cfg(defaults_full, defaults_quick, quick, sweep):
    cfg = copy.deepcopy(defaults_quick if quick else defaults_full)
    if sweep:
        cfg.update(copy.deepcopy(sweep))
    return cfg


# -- beam2d ----------------------------------------------------------------------------------------
BEAM2D = {"size": (1.2, 0.2), "E": 1.0e8, "nu": 0.3, "rho": 800.0, "g": 9.81}
BEAM2D_FULL = {"elements": ["triangle", "triangle6", "quad"], "law": "hooke", "quadrature": "gauss2",
               "levels": [[6, 1], [12, 2], [24, 4], [48, 8]], "claim": True, "reference": [96, 16]}
BEAM2D_QUICK = {"elements": ["triangle", "triangle6", "quad"], "law": "hooke", "quadrature": "gauss2",
                "levels": [[6, 1], [12, 2]], "claim": True, "reference": [48, 8]}
CLAIM_T6, CLAIM_T3 = [20, 5], [80, 20]       # 2 triangles per cell: 200 triangle6, 3200 triangles


def beam2d_scene(element, cells, law="hooke", quadrature="gauss2"):
    L, h = BEAM2D["size"]
    return {"name": f"beam2d_{element}", "mesh": {"generate": "bar", "size": list(BEAM2D["size"]),
                                                  "cells": list(cells), "element": element},
            "material": [{"region": "all", "law": law, "quadrature": quadrature, "E": BEAM2D["E"],
                          "nu": BEAM2D["nu"], "density": BEAM2D["rho"]}],
            "fixed": [{"box": [[-1e-9, -1.0], [1e-9, 1.0]]}],
            "loads": {"gravity": [0.0, -BEAM2D["g"]]},
            "solver": {"kind": "static", "steps": 1},
            "probe": [{"name": "tip", "point": [L, h / 2]}]}


def beam2d_analytic():
    """(Euler-Bernoulli, + Timoshenko shear) plane-strain tip deflection per unit thickness."""
    L, h = BEAM2D["size"]
    E, nu, rho, g = BEAM2D["E"], BEAM2D["nu"], BEAM2D["rho"], BEAM2D["g"]
    Ep = E / (1.0 - nu ** 2)
    q = rho * g * h
    eb = q * L ** 4 / (8.0 * Ep * h ** 3 / 12.0)
    return eb, eb + q * L ** 2 / (2.0 * (5.0 / 6.0) * (E / (2.0 * (1.0 + nu))) * h)


def beam2d(quick, progress, sweep=None) -> dict:
    cfg = _cfg(BEAM2D_FULL, BEAM2D_QUICK, quick, sweep)
    law, quad = cfg["law"], cfg["quadrature"]
    eb, timo = beam2d_analytic()
    progress(f"beam2d: 2D plane-strain beam under self weight, {', '.join(cfg['elements'])}; "
             f"Euler-Bernoulli (E/(1-nu^2)) {eb:.5g} m, + shear {timo:.5g} m")
    rows, compile_s = [], {}
    runs = [(e, c) for e in cfg["elements"] for c in cfg["levels"]]
    if cfg.get("claim"):
        runs += [("triangle6", CLAIM_T6), ("triangle", CLAIM_T3)]
    for e in dict.fromkeys(e for e, _ in runs):
        t0 = time.perf_counter()
        _run(beam2d_scene(e, [2, 1], law, quad), trace=False)
        compile_s[(e, law, quad)] = time.perf_counter() - t0
    for e, c in runs:
        s, peak, _ = _run(beam2d_scene(e, c, law, quad))
        w = -float(s.probes["tip"][1])
        rows.append(_row("beam2d", e, law, quad, c, "", s, peak, w))
        progress(f"  {e:<10} cells {_cells(c):<6} dofs {rows[-1]['dofs']:>6}  tip {w:.5g} m  "
                 f"total {s.time['total']:.3f} s")
    ref = cfg["reference"]
    s, _, _ = _run(beam2d_scene("triangle6", ref, law, quad), trace=False)
    w_ref = -float(s.probes["tip"][1])
    for r in rows:
        r["error_analytic"] = abs(r["value"] - timo) / timo
        r["error_reference"] = abs(r["value"] - w_ref) / abs(w_ref)
    notes = []
    claim = {}
    for r in rows:
        if (r["element"], r["cells"]) in (("triangle6", _cells(CLAIM_T6)), ("triangle", _cells(CLAIM_T3))):
            claim[r["element"]] = r
    if len(claim) == 2:
        t6, t3 = claim["triangle6"], claim["triangle"]
        holds = t6["error_reference"] <= t3["error_reference"]
        faster = t6["time_total"] <= t3["time_total"]
        notes += ["### Thesis claim: ~200 triangle6 vs 3200 triangles", "",
                  "| mesh | cells | elements | dofs | tip [m] | error vs reference | total time [s] |",
                  "|---|---|---:|---:|---:|---:|---:|",
                  f"| triangle6 | {t6['cells']} | 200 | {t6['dofs']} | {t6['value']:.5g} | "
                  f"{t6['error_reference']:.3g} | {t6['time_total']:.3g} |",
                  f"| triangle | {t3['cells']} | 3200 | {t3['dofs']} | {t3['value']:.5g} | "
                  f"{t3['error_reference']:.3g} | {t3['time_total']:.3g} |", "",
                  ("The claim holds: " if holds else "The claim does not hold: ")
                  + f"200 triangle6 ({t6['dofs']} dofs) give a tip error of {t6['error_reference']:.2%} against "
                  f"{t3['error_reference']:.2%} for 3200 linear triangles ({t3['dofs']} dofs), "
                  + ("and take less" if faster else "though they take more")
                  + f" run time ({t6['time_total']:.3g} s vs {t3['time_total']:.3g} s).", ""]
    reference = {
        "subject": "2D beam (plane strain) 1.2 x 0.2 m, rho = 800 kg/m^3, E = 100 MPa, nu = 0.3, clamped at "
                   "x = 0, gravity 9.81 m/s^2 along -y; tip deflection = -u_y at (1.2, 0.1)",
        "numerical": f"triangle6 / {law} / {quad} on {_cells(ref)} cells ({2 * ref[0] * ref[1]} triangle6, "
                     f"{s.n_free_dofs} free dofs): tip deflection {w_ref:.6g} m",
        "analytic": f"for information: plane-strain Euler-Bernoulli (E/(1-nu^2)) {eb:.6g} m, + Timoshenko shear "
                    f"(kappa = 5/6) {timo:.6g} m; the numerical reference differs from the latter by "
                    f"{abs(w_ref - timo) / timo:.2%}",
    }
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": notes}


# -- volume ----------------------------------------------------------------------------------------
VOLUME_REFERENCE = {0.05: {0.0: 5.00, 0.25: 3.10, 0.499: 0.02}, 0.20: {0.0: 20.00, 0.25: 12.70, 0.499: 0.10}}
VOLUME_FULL = {"laws": ["hooke", "stvk", "neohookean", "mooney_rivlin"], "nus": [0.0, 0.25, 0.499],
               "strains": [0.05, 0.20], "cells": [4, 4, 4], "element": "hexahedron", "steps": 4,
               "formulations": ["displacement", "mean_dilatation"]}
VOLUME_QUICK = {"laws": ["hooke", "neohookean"], "nus": [0.0, 0.25, 0.499], "strains": [0.05, 0.20],
                "cells": [2, 2, 2], "element": "hexahedron", "steps": 2,
                "formulations": ["displacement", "mean_dilatation"]}
CUBE, CUBE_E = 5.0, 1.0e4

# trilinear hexahedron (VTK node order) on [-1, 1]^3: reference corners
_HEX_REF = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                     [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)


def _hex_volumes(x):
    """Volumes of trilinear hexahedra x (n, 8, 3): 2x2x2 Gauss of det J (exact for trilinear maps)."""
    g = 1.0 / math.sqrt(3.0)
    vol = np.zeros(x.shape[0])
    for p in ((a, b, c) for a in (-g, g) for b in (-g, g) for c in (-g, g)):
        dN = np.empty((8, 3))
        for k in range(3):
            f = [(1 + _HEX_REF[:, j] * p[j]) for j in range(3)]
            f[k] = _HEX_REF[:, k]
            dN[:, k] = f[0] * f[1] * f[2] / 8.0
        J = np.einsum("nai,ak->nik", x, dN)
        vol += np.linalg.det(J)
    return vol


def deformed_volume(mesh, displacement) -> float:
    """Volume of a 3D mesh (hexahedra and linear/quadratic tetrahedra by their corners) at points + u."""
    x = np.asarray(mesh.points, float) + np.asarray(displacement, float).reshape(mesh.points.shape)
    total = 0.0
    for b in mesh.blocks:
        c = x[np.asarray(b.cells)]
        if b.type == "hexahedron":
            total += float(_hex_volumes(c).sum())
        elif b.type in ("tetra", "tetra10"):
            d = c[:, 1:4] - c[:, :1]
            total += float(np.linalg.det(d).sum() / 6.0)
        else:
            raise ValueError(f"deformed_volume: no volume rule for {b.type}")
    return total


def volume_scene(law, nu, strain, cells, element="hexahedron", steps=2, formulation="displacement"):
    a = CUBE
    return {"name": f"volume_{law}_{nu}_{strain}", "mesh": {"generate": "bar", "size": [a, a, a],
                                                           "cells": list(cells), "element": element},
            "material": [{"region": "all", "law": law, "quadrature": "gauss2", "E": CUBE_E, "nu": nu,
                          "density": 1000.0, "formulation": formulation}],
            # bottom slides (normal component only); top is pushed down and held (removes rigid modes)
            "fixed": [{"box": [[-1.0, -1.0, -1e-9], [a + 1, a + 1, 1e-9]], "components": [2]},
                      {"box": [[-1.0, -1.0, a - 1e-9], [a + 1, a + 1, a + 1e-9]],
                       "displacement": [0.0, 0.0, -strain * a]}],
            "solver": {"kind": "static", "steps": 1 if law == "hooke" else int(steps)}}


def volume(quick, progress, sweep=None) -> dict:
    cfg = _cfg(VOLUME_FULL, VOLUME_QUICK, quick, sweep)
    el, cells = cfg["element"], cfg["cells"]
    progress(f"volume: {CUBE:g} m cube compressed, {el} {_cells(cells)}, laws {', '.join(cfg['laws'])}")
    rows, compile_s, failures = [], {}, []
    forms = cfg.get("formulations", ["displacement"])
    for law in cfg["laws"]:
        t0 = time.perf_counter()
        for form in forms:
            _run(volume_scene(law, 0.25, 0.05, [1, 1, 1], el, 1, form), trace=False)
        compile_s[(el, law, "gauss2")] = time.perf_counter() - t0
        for form in forms:
            for strain in cfg["strains"]:
                for nu in cfg["nus"]:
                    case = f"nu={nu:g} compression={strain:.0%}"
                    try:
                        s, peak, sim = _run(volume_scene(law, nu, strain, cells, el, cfg["steps"], form))
                    except Exception as exc:  # noqa: BLE001 - a failed setting is a result, reported
                        failures.append(f"{law} {form} {case}: {type(exc).__name__}: {exc}")
                        progress(f"  {law:<10} {form:<16} {case:<26} FAILED: {exc}")
                        continue
                    mesh = sim.model.mesh
                    v0 = deformed_volume(mesh, np.zeros_like(mesh.points))
                    dv = 100.0 * (v0 - deformed_volume(mesh, sim.displacement)) / v0
                    r = _row("volume", el, law, "gauss2", cells, case, s, peak, dv)
                    r["formulation"] = form
                    ref = VOLUME_REFERENCE.get(round(strain, 6), {}).get(round(nu, 6))
                    r["reference_value"] = ref
                    if ref is not None:
                        r["error_analytic"] = abs(dv - ref) / ref
                    rows.append(r)
                    progress(f"  {law:<10} {form:<16} {case:<26} volume change {dv:.3f} %  (thesis FEM "
                             f"{'n/a' if ref is None else f'{ref:.2f}'} %)  total {s.time['total']:.3f} s")
    notes = ["### Relative volume loss [%] against the thesis' FEM", "",
             "| law | formulation | compression | nu | volume loss [%] | thesis FEM [%] | difference [pp] |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        ref = r.get("reference_value")
        nu_s, strain_s = r["case"].split()
        notes.append(f"| {r['law']} | {r['formulation']} | {strain_s.split('=')[1]} | {nu_s.split('=')[1]} | {r['value']:.3f} | "
                     + (f"{ref:.2f} | {r['value'] - ref:+.3f} |" if ref is not None else "n/a | n/a |"))
    notes += ["", "The thesis' numbers come from its own FEM runs, not from an exact solution: differences of "
              "a few tenths of a percentage point (mesh, load steps, boundary details) are expected.",
              "Mean dilatation keeps each cell's volumetric measure on average instead of at every point. Only the "
              "laws whose measure is the volume (det F: neohookean, stable_neohookean, mooney_rivlin) keep the "
              "volume: Hooke's measure is 1 + tr eps and StVK's 1 + tr E, which at 20 % compression differ from "
              "the volume ratio by a few percent whatever the formulation.", ""]
    if failures:
        notes += ["Runs that failed:", ""] + [f"- {f}" for f in failures] + [""]
    reference = {
        "subject": f"{CUBE:g} m cube, E = {CUBE_E:g} Pa, {el} {_cells(cells)} cells; the top face is pushed down "
                   "by 5 % / 20 % of the edge and held laterally, the bottom face slides (only u_z = 0); "
                   "value = relative volume loss in % of the deformed mesh (element volumes from the deformed "
                   "coordinates, det J integrated exactly)",
        "numerical": "none (error_reference is n/a; these rows are not in the Pareto front)",
        "analytic": "the thesis' FEM volume changes in compression: 5 %: 5.00 / 3.10 / 0.02 %, 20 %: "
                    "20.00 / 12.70 / 0.10 % for nu = 0 / 0.25 / 0.499; error_analytic = |value - ref| / ref",
    }
    for r in rows:
        r["main"] = False
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": notes}


# -- mixed -----------------------------------------------------------------------------------------
MIXED = {"size": (8.0, 1.0, 1.0), "E": 1.0e8, "nu": 0.3, "rho": 1000.0, "g": 9.81}
MIXED_FULL = {"elements": ["mixed", "hexahedron", "tetra10"], "law": "hooke", "quadrature": "gauss2",
              "levels": [[16, 2, 2], [32, 4, 4]], "reference": [48, 6, 6]}
MIXED_QUICK = {"elements": ["mixed", "hexahedron", "tetra10"], "law": "hooke", "quadrature": "gauss2",
               "levels": [[16, 2, 2]], "reference": [32, 4, 4]}


def mixed_scene(element, cells, law="hooke", quadrature="gauss2"):
    L, b, h = MIXED["size"]
    return {"name": f"mixed_{element}", "mesh": {"generate": "bar", "size": list(MIXED["size"]),
                                                 "cells": list(cells), "element": element},
            "material": [{"region": "all", "law": law, "quadrature": quadrature, "E": MIXED["E"],
                          "nu": MIXED["nu"], "density": MIXED["rho"]}],
            "fixed": [{"box": [[-1e-9, -1.0, -1.0], [1e-9, b + 1, h + 1]]}],
            "loads": {"gravity": [0.0, 0.0, -MIXED["g"]]},
            "solver": {"kind": "static", "steps": 1},
            "probe": [{"name": "tip", "point": [L, b / 2, h / 2]}]}


def mixed(quick, progress, sweep=None) -> dict:
    cfg = _cfg(MIXED_FULL, MIXED_QUICK, quick, sweep)
    law, quad = cfg["law"], cfg["quadrature"]
    eb, timo = analytic_tip(MIXED["size"], MIXED["E"], MIXED["nu"], MIXED["rho"], MIXED["g"])
    progress(f"mixed: 8 x 1 x 1 m bar, {', '.join(cfg['elements'])}; analytic tip {timo:.5g} m")
    rows, compile_s = [], {}
    for e in cfg["elements"]:
        t0 = time.perf_counter()
        _run(mixed_scene(e, [4, 1, 1], law, quad), trace=False)
        compile_s[(e, law, quad)] = time.perf_counter() - t0
        for c in cfg["levels"]:
            s, peak, _ = _run(mixed_scene(e, c, law, quad))
            w = -float(s.probes["tip"][2])
            rows.append(_row("mixed", e, law, quad, c, "", s, peak, w))
            progress(f"  {e:<10} cells {_cells(c):<8} dofs {rows[-1]['dofs']:>6}  tip {w:.5g} m  "
                     f"total {s.time['total']:.3f} s")
    ref = cfg["reference"]
    s, _, _ = _run(mixed_scene("tetra10", ref, law, quad), trace=False)
    w_ref = -float(s.probes["tip"][2])
    for r in rows:
        r["error_analytic"] = abs(r["value"] - timo) / timo
        r["error_reference"] = abs(r["value"] - w_ref) / abs(w_ref)
    reference = {
        "subject": "the thesis' mixed bar 8 x 1 x 1 m, rho = 1000 kg/m^3, E = 100 MPa, nu = 0.3, clamped at x = 0, "
                   "gravity along -z; element \"mixed\" = hexahedra | wedges | pyramids | tetrahedra along x; "
                   "tip deflection = -u_z at the centre of the free end",
        "numerical": f"tetra10 / {law} / {quad} on {_cells(ref)} cells ({s.n_free_dofs} free dofs): "
                     f"tip deflection {w_ref:.6g} m",
        "analytic": f"Euler-Bernoulli {eb:.6g} m + Timoshenko shear (kappa = 5/6) = {timo:.6g} m",
    }
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": []}


# -- large_deflection ------------------------------------------------------------------------------
SOFT = {"size": (1.2, 0.2, 0.2), "E": 1.2e6, "nu": 0.3, "rho": 800.0, "g": 9.81}
LAWS = ["hooke", "stvk", "neohookean", "stable_neohookean"]
LARGE_FULL = {"element": "hexahedron", "laws": LAWS, "levels": [[6, 1, 1], [12, 2, 2], [24, 4, 4]],
              "reference": [36, 6, 6], "steps": 10, "load_scales": [0.05, 0.1, 0.2, 0.4, 0.7, 1.0],
              "load_cells": [12, 2, 2]}
LARGE_QUICK = {"element": "hexahedron", "laws": LAWS, "levels": [[6, 1, 1], [12, 2, 2]],
               "reference": [24, 4, 4], "steps": 4, "load_scales": [0.1, 1.0], "load_cells": [6, 1, 1]}


def soft_scene(element, law, cells, steps, scale=1.0):
    L, b, h = SOFT["size"]
    return {"name": f"large_{element}_{law}", "mesh": {"generate": "bar", "size": list(SOFT["size"]),
                                                       "cells": list(cells), "element": element},
            "material": [{"region": "all", "law": law, "quadrature": "gauss2", "E": SOFT["E"], "nu": SOFT["nu"],
                          "density": SOFT["rho"]}],
            "fixed": [{"box": [[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]}],
            "loads": {"gravity": [0.0, 0.0, -SOFT["g"] * scale]},
            "solver": {"kind": "static", "steps": 1 if law == "hooke" else int(steps)},
            "probe": [{"name": "tip", "point": [L, b / 2, h / 2]}]}


def large_deflection(quick, progress, sweep=None) -> dict:
    cfg = _cfg(LARGE_FULL, LARGE_QUICK, quick, sweep)
    el, steps = cfg["element"], cfg["steps"]
    L = SOFT["size"][0]
    lin = analytic_tip(SOFT["size"], SOFT["E"], SOFT["nu"], SOFT["rho"], SOFT["g"])[1]
    progress(f"large_deflection: soft cantilever E = {SOFT['E']:g} Pa (linear theory tip {lin:.3g} m = "
             f"{lin / L:.0%} of L), {el}, {steps} load steps, laws {', '.join(cfg['laws'])}")
    rows, compile_s, failures = [], {}, []
    for law in cfg["laws"]:
        t0 = time.perf_counter()
        _run(soft_scene(el, law, [2, 1, 1], 1, 0.01), trace=False)
        compile_s[(el, law, "gauss2")] = time.perf_counter() - t0
        for c in cfg["levels"]:
            try:
                s, peak, _ = _run(soft_scene(el, law, c, steps))
            except Exception as exc:  # noqa: BLE001
                failures.append(f"{law} cells {_cells(c)}: {type(exc).__name__}: {exc}")
                progress(f"  {law:<18} cells {_cells(c)} FAILED: {exc}")
                continue
            w = -float(s.probes["tip"][2])
            rows.append(_row("large_deflection", el, law, "gauss2", c, "", s, peak, w))
            progress(f"  {law:<18} cells {_cells(c):<8} dofs {rows[-1]['dofs']:>6}  tip {w:.5g} m "
                     f"({w / L:.0%} of L)  total {s.time['total']:.3f} s")
    ref = cfg["reference"]
    s, _, _ = _run(soft_scene(el, "neohookean", ref, steps), trace=False)
    w_ref = -float(s.probes["tip"][2])
    for r in rows:
        r["error_analytic"] = abs(r["value"] - lin) / lin
        r["error_reference"] = abs(r["value"] - w_ref) / abs(w_ref)
    # Hooke against neohookean on the same mesh as the load grows
    lc = cfg["load_cells"]
    notes = [f"### Where Hooke's error becomes large ({el} {_cells(lc)}, same mesh for both laws)", "",
             "| load (x g) | neohookean tip [m] | tip / L | hooke tip [m] | hooke error vs neohookean |",
             "|---:|---:|---:|---:|---:|"]
    first_bad = None
    for k in cfg["load_scales"]:
        try:
            wn = -float(_run(soft_scene(el, "neohookean", lc, steps, k), trace=False)[0].probes["tip"][2])
            wh = -float(_run(soft_scene(el, "hooke", lc, steps, k), trace=False)[0].probes["tip"][2])
        except Exception as exc:  # noqa: BLE001
            notes.append(f"| {k:g} | failed: {type(exc).__name__} | | | |")
            continue
        err = abs(wh - wn) / abs(wn)
        if first_bad is None and err > 0.05:
            first_bad = (k, wn / L, err)
        notes.append(f"| {k:g} | {wn:.4g} | {wn / L:.1%} | {wh:.4g} | {err:.1%} |")
        progress(f"  load x{k:g}: neohookean {wn:.4g} m, hooke {wh:.4g} m, hooke error {err:.1%}")
    notes.append("")
    notes.append(f"Hooke's error against neohookean first exceeds 5 % at {first_bad[0]:g} g "
                 f"(tip deflection {first_bad[1]:.0%} of L, error {first_bad[2]:.1%})."
                 if first_bad else "Hooke's error against neohookean stays below 5 % over these loads.")
    notes.append("")
    if failures:
        notes += ["Runs that failed:", ""] + [f"- {f}" for f in failures] + [""]
    reference = {
        "subject": f"soft cantilever 1.2 x 0.2 x 0.2 m, E = {SOFT['E']:g} Pa, nu = 0.3, rho = 800 kg/m^3, clamped at "
                   f"x = 0, self weight along -z, static with {steps} load steps (hooke: 1); tip deflection = "
                   "-u_z at the centre of the free end",
        "numerical": f"neohookean / gauss2 {el} on {_cells(ref)} cells ({s.n_free_dofs} free dofs): tip deflection "
                     f"{w_ref:.6g} m ({w_ref / L:.0%} of L)",
        "analytic": f"small-strain beam theory (Euler-Bernoulli + shear) {lin:.6g} m: not valid at this deflection; "
                    "error_analytic shows how far linear theory is off",
    }
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": notes}


# -- shear and torsion of a cube (thesis ch. 7) ----------------------------------------------------
CUBE_NU = 0.3
SHEAR_X = 0.01 * CUBE          # lateral displacement of the top face: 1 % of the edge
TORSION_THETA = 0.01           # rad, rotation of the top face about the vertical centre axis
CUBE_FULL = {"elements": ["hexahedron", "tetra", "tetra10"], "law": "hooke", "quadrature": "gauss2",
             "levels": [[2, 2, 2], [4, 4, 4], [8, 8, 8]], "levels_quadratic": [[2, 2, 2], [4, 4, 4], [8, 8, 8]]}
CUBE_QUICK = {"elements": ["hexahedron", "tetra10"], "law": "hooke", "quadrature": "gauss2",
              "levels": [[2, 2, 2], [4, 4, 4]], "levels_quadratic": [[2, 2, 2], [4, 4, 4]]}
_QUADRATIC_3D = ("tetra10",)


def shear_analytic(l=CUBE, E=CUBE_E, nu=CUBE_NU, x=SHEAR_X) -> float:
    """The thesis' shear force F = 12 E I x / (l^3 (1 + beta)), beta = 2 (1 + nu), I = l^4 / 12."""
    I = l ** 4 / 12.0
    return 12.0 * E * I * x / (l ** 3 * (1.0 + 2.0 * (1.0 + nu)))


def torsion_analytic(l=CUBE, E=CUBE_E, nu=CUBE_NU, theta=TORSION_THETA) -> float:
    """The thesis' torque tau = 1.125 * 1/2 (l/2)^3 * E / (1 + nu) * theta (= 0.141 G l^4 theta / l)."""
    return 1.125 * 0.5 * (l / 2.0) ** 3 * E / (1.0 + nu) * theta


def cube_scene(kind, element, cells, law="hooke", quadrature="gauss2"):
    """The 5 m cube, bottom face clamped, top face held: shifted by SHEAR_X along x (shear) or at 0
    (torsion: cube_run replaces the top face's prescribed displacements by a rigid rotation)."""
    a = CUBE
    top = [SHEAR_X, 0.0, 0.0] if kind == "shear" else [0.0, 0.0, 0.0]
    return {"name": f"{kind}_{element}", "mesh": {"generate": "bar", "size": [a, a, a], "cells": list(cells),
                                                  "element": element},
            "material": [{"region": "all", "law": law, "quadrature": quadrature, "E": CUBE_E, "nu": CUBE_NU,
                          "density": 1000.0}],
            "fixed": [{"box": [[-1.0, -1.0, -1e-9], [a + 1, a + 1, 1e-9]]},
                      {"box": [[-1.0, -1.0, a - 1e-9], [a + 1, a + 1, a + 1e-9]], "displacement": top}],
            "solver": {"kind": "static", "steps": 1 if law == "hooke" else 4}}


def cube_run(kind, element, cells, law="hooke", quadrature="gauss2", theta=TORSION_THETA, trace=True):
    """(Summary, peak MB, value) of one shear or torsion run of the cube.

    The top face's prescribed dofs are all three components of every node at z = l.  Shear: value =
    total x reaction on the top face; torsion: the top nodes' prescribed displacements are set, through
    the Model, to the rigid rotation by theta about the vertical axis through the face centre, and value =
    z torque of the top reactions about that axis (moment arms from the undeformed positions).  The
    reaction at a prescribed dof is -f_int = dW/du (assembly.assemble returns f_int = -dW/du).
    """
    # deferred: model, assembly, simulation (scipy.sparse, pyamg), 0.50 s skipped by `tensormass report --help` (0.7 s)
    from ...runtime.assembly.assembly import assemble
    from ...runtime.model.model import Model
    from ...runtime.run.simulation import Simulation
    scene = Scene.from_dict(cube_scene(kind, element, cells, law, quadrature))
    if trace:
        tracemalloc.start()
    try:
        model = Model.from_scene(scene)
        pts = np.asarray(model.mesh.points, float)
        top = np.flatnonzero(np.abs(pts[:, 2] - CUBE) <= 1e-9 * CUBE)
        c = np.array([CUBE / 2, CUBE / 2])
        if kind == "torsion":
            d = pts[top, :2] - c
            cs, sn = math.cos(theta), math.sin(theta)
            u_top = np.zeros((top.size, 3))
            u_top[:, 0] = (cs - 1.0) * d[:, 0] - sn * d[:, 1]
            u_top[:, 1] = sn * d[:, 0] + (cs - 1.0) * d[:, 1]
            dofs = (top[:, None] * 3 + np.arange(3)).ravel()
            pos = np.searchsorted(model.fixed_dofs, dofs)
            assert np.array_equal(model.fixed_dofs[pos], dofs), "top face dofs must all be prescribed"
            prescribed = model.prescribed.copy()
            prescribed[pos] = u_top.ravel()
            model.prescribed = prescribed
        sim = Simulation(model)
        summary = sim.run()
        peak = tracemalloc.get_traced_memory()[1] / 1e6 if trace else float("nan")
    finally:
        if trace:
            tracemalloc.stop()
    _, f_int, _ = assemble(model, sim.displacement.ravel())
    reaction = -np.asarray(f_int).reshape(-1, 3)[top]
    if kind == "shear":
        value = float(reaction[:, 0].sum())
    else:
        d = pts[top, :2] - c
        value = float((d[:, 0] * reaction[:, 1] - d[:, 1] * reaction[:, 0]).sum())
    return summary, peak, value


def _cube_benchmark(kind, quick, progress, sweep) -> dict:
    cfg = _cfg(CUBE_FULL, CUBE_QUICK, quick, sweep)
    law, quad = cfg["law"], cfg["quadrature"]
    analytic = shear_analytic() if kind == "shear" else torsion_analytic()
    unit = "N" if kind == "shear" else "N m"
    what = ("lateral reaction force on the top face" if kind == "shear" else "torque on the top face")
    progress(f"{kind}: {CUBE:g} m cube, E = {CUBE_E:g} Pa, nu = {CUBE_NU:g}, {', '.join(cfg['elements'])}; "
             f"thesis formula {analytic:.5g} {unit}")
    rows, compile_s = [], {}
    for e in cfg["elements"]:
        levels = cfg["levels_quadratic"] if e in _QUADRATIC_3D else cfg["levels"]
        t0 = time.perf_counter()
        cube_run(kind, e, [1, 1, 1], law, quad, trace=False)
        compile_s[(e, law, quad)] = time.perf_counter() - t0
        for c in levels:
            s, peak, v = cube_run(kind, e, c, law, quad)
            r = _row(kind, e, law, quad, c, "", s, peak, v)
            r["error_analytic"] = abs(v - analytic) / abs(analytic)
            r["ratio_analytic"] = v / analytic
            rows.append(r)
            progress(f"  {e:<10} cells {_cells(c):<6} dofs {r['dofs']:>6}  {kind} {v:.5g} {unit} "
                     f"(x{v / analytic:.3f} of the thesis formula)  total {s.time['total']:.3f} s")
    # numerical reference: the finest run of the most accurate element (tetra10 if swept, else the last one)
    cand = [r for r in rows if r["element"] in _QUADRATIC_3D] or rows
    ref = max(cand, key=lambda r: r["dofs"])
    for r in rows:
        r["error_reference"] = abs(r["value"] - ref["value"]) / abs(ref["value"])
    notes = [f"### {kind.capitalize()}: FEM against the thesis formula", "",
             f"| element | cells | dofs | {what} [{unit}] | / thesis formula | / numerical reference |",
             "|---|---|---:|---:|---:|---:|"]
    for r in rows:
        notes.append(f"| {r['element']} | {r['cells']} | {r['dofs']} | {r['value']:.5g} | {r['ratio_analytic']:.3f} | "
                     f"{r['value'] / ref['value']:.4f} |")
    notes += ["", "The thesis formula is a beam / Saint-Venant estimate (" +
              ("a guided beam of length l with a shear term, kappa = 1" if kind == "shear" else
               "free warping, torsion constant 0.141 l^4 of a square section") +
              "), not an exact solution for a cube clamped on two faces: a ratio of order 1, not 1.000, "
              "is expected; mesh convergence is judged against the numerical reference.", ""]
    if kind == "shear":
        subject = (f"{CUBE:g} m cube, E = {CUBE_E:g} Pa, nu = {CUBE_NU:g}, {law}; bottom face clamped; every top-face "
                   f"node displaced by x = {SHEAR_X:g} m (1 % of l) along x with its y and z components held at 0; "
                   "value = total x reaction force on the top face, -f_int summed over its x dofs [N]")
        formula = (f"the thesis' F = 12 E I x / (l^3 (1 + beta)), beta = 2 (1 + nu), I = l^4 / 12: {analytic:.6g} N")
    else:
        subject = (f"{CUBE:g} m cube, E = {CUBE_E:g} Pa, nu = {CUBE_NU:g}, {law}; bottom face clamped; the top face "
                   f"turned rigidly by theta = {TORSION_THETA:g} rad about the vertical axis through its centre "
                   "(each top node's own prescribed displacement, set through the Model); value = torque about "
                   "that axis of the top-face reactions -f_int (undeformed moment arms) [N m]")
        formula = (f"the thesis' tau = 1.125 * 1/2 (l/2)^3 * E/(1 + nu) * theta: {analytic:.6g} N m")
    reference = {
        "subject": subject,
        "numerical": f"the finest run of {ref['element']} / {law} / {quad} ({ref['cells']} cells, {ref['dofs']} free "
                     f"dofs): {ref['value']:.6g} {unit}, {ref['value'] / analytic:.4f} x the thesis formula",
        "analytic": formula + "; error_analytic = |value - formula| / formula",
    }
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": notes}


def shear(quick, progress, sweep=None) -> dict:
    return _cube_benchmark("shear", quick, progress, sweep)


def torsion(quick, progress, sweep=None) -> dict:
    return _cube_benchmark("torsion", quick, progress, sweep)


BENCHMARKS = {"beam2d": beam2d, "volume": volume, "mixed": mixed, "large_deflection": large_deflection,
              "shear": shear, "torsion": torsion}
