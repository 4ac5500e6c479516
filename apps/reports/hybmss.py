"""The thesis' chapter-7 comparisons (`tensormass report accuracy --benchmark hybmss`): MSS-Baudet,
HybMSS-FD, HybMSS and our hexahedral FEM on the same meshes, beside Tables 7.3-7.6 and Fig. 7.5.

Models (every one on the same structured mesh of cubic hexahedra, `[solver] backend = "c"`):

  MSS-Baudet       law "mss" (Baudet 2009: 12 edge + 4 inner-diagonal springs per cube)
  HybMSS-FD        law "hybmss", A = 0 (no face diagonals; springs + volume correction)
  HybMSS           law "hybmss", A = 1 (face diagonals + volume correction)
  FEM hooke        hooke, gauss2 (the thesis' FEM is linear Hooke in LS-Dyna)
  FEM SNH          stable_neohookean, gauss2: large strains (the 20 % and 45 degree rows)
  FEM SNH-MD       stable_neohookean, gauss2, formulation mean_dilatation: locking-free at nu = 0.499

Cases (E = 10 kPa unless stated).  The thesis runs 10 s of dynamics (dt = 1 ms) and reads the
state at the end; here every case is a static equilibrium reached by load stepping (the prescribed
displacement or gravity ramped over STEPS load steps, Newton at each), which is what 10 s of damped
dynamics tends to.

  compression   the 5 m cube of 10 x 10 x 10 cells of 0.5 m, top face pushed down by 5 % / 20 % of
                the edge, nu = 0, 0.25, 0.499; value = |V0 - V| / V0 in %  (Table 7.3)
  stretching    the 0.25 x 0.25 x 1 m beam of 5 x 5 x 20 cells of 0.05 m, pulled along its axis by
                5 % / 20 %, the same nus; value = |V0 - V| / V0 in %  (Table 7.4)
  shear         the 5 m cube, nu = 0.25, bottom clamped, top face moved sideways by 5 % / 20 % of
                the edge (its other components held); value = the top support's reaction force
                along the motion in N  (Table 7.5; analytic 3571 / 14285 N, Timoshenko)
  torsion       the 5 m cube, nu = 0.25, bottom clamped, top face turned rigidly by 1 / 45 degrees
                about the vertical axis through its centre ([[fixed]] rotation); value = the top
                support's reaction moment about that axis in N m (runtime/physics/reactions.py)
                (Table 7.6; analytic 1227 / 55223 N m)
  bending       cantilever 2.4 x 0.4 x 0.4 m, 24 x 4 x 4 and 48 x 8 x 8 cells, E = 10 MPa,
                nu = 0.25, clamped at x = 0, gravity g = 10 along -z, density RHO_BEND (the thesis
                does not give rho; this keeps the tip deflection near 1.3 % of L); value = tip
                deflection -u_z at (L, h/2, h/2) in m, against Euler-Bernoulli 1.5 rho g L^4/(E h^2)
                (Fig. 7.5: curves only, no thesis numbers)

Boundary conditions of compression and stretching (the thesis does not state them): "clamped"
plates (the loaded faces held laterally: bottom clamped, top moved along the axis only) by default;
"sliding" plates (only the axial component prescribed on both faces, the rigid motions removed by a
corner pinned in x, y and a second bottom corner in y) as a second set in the full report: the
lateral faces are then free everywhere and linear theory gives dV/V = eps (1 - 2 nu) exactly.

The deformed volume is exact: the sum over the deformed trilinear hexahedra of det J integrated by
2 x 2 x 2 Gauss points (det J of a trilinear map is of degree 2 in each coordinate, so exact), which
is the volume bounded by the deformed bilinear boundary faces (benchmarks.deformed_volume).

Rows: results.csv (accuracy.COLUMNS): law = the model's law, formulation, case, value,
reference_value (linear theory / Timoshenko / Saint-Venant / Euler-Bernoulli), error_analytic =
|value - reference_value| / |reference_value|, thesis_value (the thesis' number for the same model
and case, blank where it has none), error_reference = |value - thesis_value| / |thesis_value|, the
times of the run summary, model = the thesis' name of the model.
"""
from __future__ import annotations

import copy
import math
import time
import warnings

import numpy as np

from .benchmarks import deformed_volume
from .common import benchmark_row as _row
from .common import cells_label as _cells
from .common import run_dict as _run
from ...runtime.scene.scene import Scene

__all__ = ["hybmss", "hybmss_scene", "MODELS", "THESIS", "analytic"]

# (name, law, extra material keys, thesis column)
MODELS = (
    ("MSS-Baudet", "mss", {}, "MSS-Baudet"),
    ("HybMSS-FD", "hybmss", {"A": 0.0}, "HybMSS-FD"),
    ("HybMSS", "hybmss", {"A": 1.0}, "HybMSS"),
    ("FEM hooke", "hooke", {"quadrature": "gauss2"}, "FEM"),
    ("FEM SNH", "stable_neohookean", {"quadrature": "gauss2"}, "FEM"),
    ("FEM SNH-MD", "stable_neohookean", {"quadrature": "gauss2", "formulation": "mean_dilatation"}, "FEM"),
)
_COLUMN = {c: i for i, c in enumerate(("MSS-Baudet", "HybMSS-FD", "HybMSS", "FEM"))}

# The thesis' Tables 7.3-7.6 (SEED_DIGEST section 5.4): columns MSS-Baudet, HybMSS-FD, HybMSS, FEM.
THESIS = {
    "compression": {(0.0, 0.05): (2.6, 5.37, 5.61, 5.00), (0.25, 0.05): (3.17, 3.25, 3.17, 3.10),
                    (0.499, 0.05): (3.49, 0.00, 0.01, 0.02), (0.0, 0.20): (12.99, 23.62, 19.88, 20.00),
                    (0.25, 0.20): (16.68, 15.99, 13.52, 12.70), (0.499, 0.20): (18.73, 0.01, 0.00, 0.10)},
    "stretching": {(0.0, 0.05): (0.63, 7.46, 4.40, 5.00), (0.25, 0.05): (1.14, 0.85, 2.54, 2.61),
                   (0.499, 0.05): (1.54, 0.00, 0.00, 0.00), (0.0, 0.20): (0.25, 24.92, 20.00, 19.99),
                   (0.25, 0.20): (0.73, 3.15, 8.90, 10.11), (0.499, 0.20): (1.13, 0.00, 0.00, 0.00)},
    "shear": {0.05: (10985.0, 3390.0, 3396.0, 3317.0), 0.20: (46460.0, 14662.0, 14600.0, 13234.0)},
    "torsion": {1.0: (3463.0, 1277.0, 1306.0, 1279.0), 45.0: (160892.0, 60005.0, 60565.0, 57981.0)},
}
THESIS_ANALYTIC = {"shear": {0.05: 3571.0, 0.20: 14285.0}, "torsion": {1.0: 1227.0, 45.0: 55223.0}}

E_SOFT, NU_CUBE, CUBE = 1.0e4, 0.25, 5.0
BEAM = (0.25, 0.25, 1.0)
BEND = {"size": (2.4, 0.4, 0.4), "E": 1.0e7, "nu": 0.25, "g": 10.0}
RHO, RHO_BEND = 1000.0, 100.0
CASES = ("compression", "stretching", "shear", "torsion", "bending")

HYBMSS_FULL = {"cases": list(CASES), "models": [m[0] for m in MODELS], "nus": [0.0, 0.25, 0.499],
               "strains": [0.05, 0.20], "angles": [1.0, 45.0], "bcs": ["clamped", "sliding"],
               "cube": 10, "beam": [5, 5, 20], "bend": [[24, 4, 4], [48, 8, 8]],
               "steps": {0.05: 4, 0.20: 10, 1.0: 2, 45.0: 12, "bending": 2}}
HYBMSS_QUICK = {"cases": list(CASES), "models": [m[0] for m in MODELS], "nus": [0.0, 0.25, 0.499],
                "strains": [0.05, 0.20], "angles": [1.0, 45.0], "bcs": ["clamped"],
                "cube": 4, "beam": [2, 2, 8], "bend": [[12, 2, 2]],
                "steps": {0.05: 2, 0.20: 5, 1.0: 1, 45.0: 6, "bending": 1}}


def analytic(case, load, nu=NU_CUBE, E=E_SOFT) -> float:
    """The reference of a case: linear theory dV/V = eps (1 - 2 nu) in % (compression, stretching),
    Timoshenko's F = 12 E I x / (l^3 (1 + beta)), beta = 2 (1 + nu) (shear, load = strain), the
    thesis' torque 1.125/2 (l/2)^3 E/(1 + nu) theta (torsion, load = degrees), Euler-Bernoulli
    1.5 rho g L^4 / (E h^2) (bending, load = rho)."""
    if case in ("compression", "stretching"):
        return 100.0 * load * (1.0 - 2.0 * nu)
    if case == "shear":
        return 12.0 * E * CUBE ** 4 / 12.0 * load * CUBE / (CUBE ** 3 * (1.0 + 2.0 * (1.0 + nu)))
    if case == "torsion":
        return 1.125 * 0.5 * (CUBE / 2.0) ** 3 * E / (1.0 + nu) * math.radians(load)
    if case == "bending":
        L, _, h = BEND["size"]
        return 1.5 * load * BEND["g"] * L ** 4 / (BEND["E"] * h ** 2)
    raise ValueError(f"unknown case {case!r}")


def _model(name):
    for m in MODELS:
        if m[0] == name:
            return m
    raise ValueError(f"unknown model {name!r}; choose from {', '.join(m[0] for m in MODELS)}")


def _face(size, axis, at, tol=1e-9):
    """The box of the face of a bar of this size normal to `axis` at coordinate `at`."""
    lo, hi = [-1.0] * 3, [s + 1.0 for s in size]
    lo[axis], hi[axis] = at - tol * max(size), at + tol * max(size)
    return [lo, hi]


def _point(p, size, tol=1e-9):
    t = tol * max(size)
    return [[x - t for x in p], [x + t for x in p]]


def hybmss_scene(model, case, cells, load, nu=NU_CUBE, bc="clamped", steps=1) -> dict:
    """The scene dict of one model on one case (load: strain, degrees, or rho for bending)."""
    name, law, extra, _ = _model(model)
    if case in ("compression", "stretching", "shear", "torsion"):
        size = [CUBE] * 3 if case != "stretching" else list(BEAM)
        E, rho = E_SOFT, RHO
    elif case == "bending":
        size, E, rho, nu = list(BEND["size"]), BEND["E"], load, BEND["nu"]
    else:
        raise ValueError(f"unknown case {case!r}; choose from {', '.join(CASES)}")
    material = {"region": "all", "law": law, "E": E, "nu": nu, "density": rho, **extra}
    H = size[2]
    bottom, top = _face(size, 2, 0.0), _face(size, 2, H)
    loads = {}
    probe = []
    if case in ("compression", "stretching"):
        d = (-1.0 if case == "compression" else 1.0) * load * H
        if bc == "clamped":
            fixed = [{"name": "bottom", "box": bottom}, {"name": "top", "box": top, "displacement": [0.0, 0.0, d]}]
        elif bc == "sliding":
            fixed = [{"name": "bottom", "box": bottom, "components": [2]},
                     {"name": "top", "box": top, "displacement": [0.0, 0.0, d], "components": [2]},
                     {"name": "pin", "box": _point([0.0, 0.0, 0.0], size), "components": [0, 1]},
                     {"name": "roller", "box": _point([size[0], 0.0, 0.0], size), "components": [1]}]
        else:
            raise ValueError(f"unknown boundary conditions {bc!r}; choose clamped or sliding")
    elif case == "shear":
        fixed = [{"name": "bottom", "box": bottom},
                 {"name": "top", "box": top, "displacement": [load * CUBE, 0.0, 0.0]}]
    elif case == "torsion":
        centre = [CUBE / 2.0, CUBE / 2.0, CUBE]
        fixed = [{"name": "bottom", "box": bottom},
                 {"name": "top", "box": top, "rotation": {"axis": [0.0, 0.0, 1.0], "point": centre, "angle": load},
                  "moment_about": centre}]
    else:
        fixed = [{"name": "clamp", "box": _face(size, 0, 0.0)}]
        loads = {"gravity": [0.0, 0.0, -BEND["g"]]}
        probe = [{"name": "tip", "point": [size[0], size[1] / 2.0, size[2] / 2.0]}]
    data = {"name": f"hybmss_{case}_{law}", "mesh": {"generate": "bar", "size": size, "cells": list(cells),
                                                       "element": "hexahedron"},
            "material": [material], "fixed": fixed,
            "solver": {"kind": "static", "steps": 1 if law == "hooke" else int(steps), "backend": "c"}}
    if loads:
        data["loads"] = loads
    if probe:
        data["probe"] = probe
    return data


def _measure(case, sim, summary):
    if case in ("compression", "stretching"):
        mesh = sim.model.mesh
        v0 = deformed_volume(mesh, np.zeros_like(mesh.points))
        return 100.0 * abs(v0 - deformed_volume(mesh, sim.displacement)) / v0
    if case == "shear":
        return float(summary.reactions["top"]["force"][0])
    if case == "torsion":
        return float(summary.reactions["top"]["moment"][2])
    return -float(summary.probes["tip"][2])


def _load_label(case, load):
    return f"{load:g} deg" if case == "torsion" else (f"rho={load:g}" if case == "bending" else f"{load:.0%}")


def _failed_row(model, case_label, cells, law, quad, form, msg):
    nan = float("nan")
    return {"benchmark": "hybmss", "element": "hexahedron", "law": law, "quadrature": quad, "formulation": form,
            "cells": _cells(cells), "case": case_label, "main": False, "dofs": 0, "value": nan,
            "error_analytic": nan, "error_reference": nan, "time_setup": nan, "time_assembly": nan,
            "time_solve": nan, "time_total": nan, "peak_memory_mb": nan, "model": model, "status": "failed",
            "message": msg}


class _Singular(Exception):
    status = "singular"


def _singular_at_rest(data) -> bool:
    """Whether the constrained stiffness at rest of a scene is singular: K x = K z does not give z back
    (sparse LU, a fixed pseudo-random z).  The runtime refuses such static runs only for laws whose
    single cell has spurious zero modes (mss); hybmss at A = 0 and nu = 1/4 has the same springs and no
    volume term (kappa = 0), so its lattice can be singular too and the runtime would not say so."""
    import scipy.sparse.linalg as spla

    # deferred: model and assembly (scipy.sparse, pyamg), 0.43 s skipped by `tensormass report --help` (0.7 s)
    from ...runtime.assembly.assembly import assemble
    from ...runtime.model.model import Model
    m = Model.from_scene(Scene.from_dict(copy.deepcopy(data)))
    _, _, K = assemble(m, np.zeros(m.n_dofs))
    free = np.asarray(m.free_dofs)
    Kf = K[free][:, free].tocsc()
    z = np.random.default_rng(7).standard_normal(free.size)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            x = spla.splu(Kf).solve(Kf @ z)
    except RuntimeError:                  # "Factor is exactly singular"
        return True
    return not (np.all(np.isfinite(x)) and np.linalg.norm(x - z) <= 1e-3 * np.linalg.norm(z))


def _one(model, case, cells, load, nu, bc, steps):
    """One run: a result row (a failed run is a row with value nan and its message)."""
    _, law, extra, col = _model(model)
    quad = extra.get("quadrature", "discrete")
    form = extra.get("formulation", "displacement")
    label = f"{case} {_load_label(case, load)}" + (f" nu={nu:g} {bc}" if case in ("compression", "stretching") else "")
    try:
        data = hybmss_scene(model, case, cells, load, nu, bc, steps)
        if quad == "discrete" and _singular_at_rest(data):
            raise _Singular("the stiffness at rest is singular: the lattice's zero-energy modes are not held by "
                            "these boundary conditions, so the static answer is not unique (checked here, before "
                            "the run)")
        with warnings.catch_warnings():      # a blowing-up Newton (a buckled lattice) overflows in numpy on its
            warnings.simplefilter("ignore", RuntimeWarning)      # way to the runtime's own error, kept below
            summary, peak, sim = _run(data)
        value = _measure(case, sim, summary)
        row = _row("hybmss", "hexahedron", law, quad, cells, label, summary, peak, value)
        row.update(formulation=form, status=summary.status, message="", main=False, model=model)
        row["newton"] = int(summary.iterations.get("newton", 0))
    except Exception as exc:  # noqa: BLE001 - a failed (e.g. buckled) model is a result, reported
        row = _failed_row(model, label, cells, law, quad, form,
                          str(exc) if isinstance(exc, _Singular) else f"{type(exc).__name__}: {exc}")
        status = getattr(exc, "status", None)
        if status:
            row["status"] = status
    ref = analytic(case, load, nu) if case != "bending" else analytic(case, load)
    row["reference_value"] = ref
    if math.isfinite(row["value"]) and ref != 0:
        row["error_analytic"] = abs(row["value"] - ref) / abs(ref)
    thesis = None
    if case in ("compression", "stretching"):
        t = THESIS[case].get((round(nu, 6), round(load, 6)))
        thesis = None if t is None else t[_COLUMN[col]]
    elif case in ("shear", "torsion"):
        t = THESIS[case].get(round(load, 6))
        thesis = None if t is None else t[_COLUMN[col]]
    row["thesis_value"] = "" if thesis is None else thesis
    if thesis and math.isfinite(row["value"]):
        row["error_reference"] = abs(row["value"] - thesis) / abs(thesis)
    row["_key"] = (case, bc, round(nu, 6), round(load, 6), _cells(cells), model)
    return row


def hybmss(quick, progress, sweep=None) -> dict:
    cfg = copy.deepcopy(HYBMSS_QUICK if quick else HYBMSS_FULL)
    cfg.update(copy.deepcopy(sweep or {}))
    for case in cfg["cases"]:
        if case not in CASES:
            raise ValueError(f"hybmss: unknown case {case!r}; choose from {', '.join(CASES)}")
    models = [_model(m)[0] for m in cfg["models"]]
    n = int(cfg["cube"])
    progress(f"hybmss: thesis ch. 7 (Tables 7.3-7.6, Fig. 7.5), models {', '.join(models)}; cases "
             f"{', '.join(cfg['cases'])}; cube {n}^3, beam {_cells(cfg['beam'])}, bending "
             f"{', '.join(_cells(c) for c in cfg['bend'])}; static equilibrium with load stepping, backend c")
    compile_s = {}
    for m in models:                      # warm-up: compile / load each model's kernels on one cube
        _, law, extra, _ = _model(m)
        t0 = time.perf_counter()
        _run(hybmss_scene(m, "shear", [1, 1, 1], 0.01, steps=1), trace=False)
        compile_s[("hexahedron", law, m)] = time.perf_counter() - t0
    rows = []
    steps = cfg["steps"]

    def emit(row):
        rows.append(row)
        v = row["value"]
        th = row["thesis_value"]
        progress(f"  {row['model']:<11} {row['case']:<36} cells {row['cells']:<8} "
                 + (f"value {v:.5g}" if math.isfinite(v) else f"FAILED ({row['message'][:80]})")
                 + f"  reference {row['reference_value']:.5g}" + (f"  thesis {th:g}" if th != "" else "")
                 + (f"  {row['time_total']:.3f} s" if math.isfinite(row["time_total"]) else ""))

    for case in cfg["cases"]:
        if case in ("compression", "stretching"):
            cells = [n, n, n] if case == "compression" else list(cfg["beam"])
            for bc in cfg["bcs"]:
                for strain in cfg["strains"]:
                    for nu in cfg["nus"]:
                        for m in models:
                            emit(_one(m, case, cells, strain, nu, bc, steps[strain]))
        elif case == "shear":
            for strain in cfg["strains"]:
                for m in models:
                    emit(_one(m, case, [n, n, n], strain, NU_CUBE, "clamped", steps[strain]))
        elif case == "torsion":
            for angle in cfg["angles"]:
                for m in models:
                    emit(_one(m, case, [n, n, n], angle, NU_CUBE, "clamped", steps.get(angle, 12)))
        else:
            for cells in cfg["bend"]:
                for m in models:
                    emit(_one(m, case, cells, RHO_BEND, BEND["nu"], "clamped", steps["bending"]))
    notes = _tables(rows, cfg, models)
    reference = {
        "subject": "the thesis' chapter-7 tests (SEED_DIGEST 5.4) for MSS-Baudet (mss), HybMSS-FD (hybmss A = 0), "
                   "HybMSS (hybmss A = 1) and hexahedral FEM (hooke; stable_neohookean; stable_neohookean + "
                   "mean_dilatation), gauss2, on the same cubic meshes, backend c; static equilibrium by load "
                   "stepping instead of the thesis' 10 s of dynamics; value: volume change |V0 - V|/V0 in % "
                   "(compression, stretching), reaction force in N (shear), reaction moment in N m (torsion), "
                   "tip deflection in m (bending)",
        "numerical": "the thesis' own number for the same model and case (thesis_value; its FEM column for our "
                     "three FEM models); error_reference = |value - thesis| / |thesis|",
        "analytic": "reference_value: linear theory eps (1 - 2 nu) for free lateral faces (volume cases), "
                    "Timoshenko F = 12 E I x / (l^3 (1 + beta)) (shear: 3571.4 / 14285.7 N), the thesis' "
                    "tau = 1.125/2 (l/2)^3 E/(1 + nu) theta (torsion: 1227.2 / 55223 N m), Euler-Bernoulli "
                    "1.5 rho g L^4 / (E h^2) (bending); error_analytic = |value - reference| / |reference|",
    }
    for r in rows:
        r.pop("_key", None)
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": notes}


# -- report tables ---------------------------------------------------------------------------------
def _fmt(row, spec):
    if row is None:
        return "-"
    v = row["value"]
    if not math.isfinite(v):
        return "singular" if row.get("status") == "singular" else "failed"
    s = format(v, spec)
    if row.get("status") == "warnings":
        s += " (w)"
    return s


def _thesis(row, spec):
    th = None if row is None else row["thesis_value"]
    return "" if th in (None, "") else f" ({format(th, spec)})"


def _tables(rows, cfg, models) -> list:
    by = {r["_key"]: r for r in rows}
    n = int(cfg["cube"])
    lines = ["Each cell: ours (the thesis' number for that model; its FEM column beside all three of our FEM "
             "models). (w): the run ended with warnings (e.g. inverted elements on the way). Static equilibrium "
             "with load stepping replaces the thesis' 10 s of dynamics. \"singular\": the constrained stiffness "
             "at rest is singular (zero-energy modes of the lattice that these boundary conditions leave free), "
             "so there is no unique static answer and the run was not made; \"failed\": Newton found no "
             "equilibrium on the load path (a buckling lattice: the thesis saw MSS-Baudet and HybMSS-FD unstable "
             "in compression).", ""]
    head = "| " + " | ".join(models) + " |"
    sep = "|" + "---:|" * len(models)
    for case, title, cells in (("compression", "Table 7.3, compression: volume change [%]", [n, n, n]),
                               ("stretching", "Table 7.4, stretching: volume change [%]", list(cfg["beam"]))):
        if case not in cfg["cases"]:
            continue
        for bc in cfg["bcs"]:
            lines += [f"### {title}, {bc} plates, {_cells(cells)} cells", "",
                      "| nu | strain | linear theory eps(1-2nu) " + head, "|---:|---:|---:" + sep]
            for strain in cfg["strains"]:
                for nu in cfg["nus"]:
                    cellsl = [by.get((case, bc, round(nu, 6), round(strain, 6), _cells(cells), m)) for m in models]
                    lines.append(f"| {nu:g} | {strain:.0%} | {analytic(case, strain, nu):.2f} | "
                                 + " | ".join(_fmt(r, ".2f") + _thesis(r, ".2f") for r in cellsl) + " |")
            lines.append("")
    for case, title, loads, unit, spec in (
            ("shear", "Table 7.5, shear: reaction force [N]", cfg["strains"], "N", ".0f"),
            ("torsion", "Table 7.6, torsion: reaction moment [N m]", cfg["angles"], "N m", ".0f")):
        if case not in cfg["cases"]:
            continue
        lines += [f"### {title}, {_cells([n, n, n])} cells, nu = {NU_CUBE:g}", "",
                  "| load | analytic (thesis) " + head, "|---:|---:" + sep]
        for load in loads:
            cellsl = [by.get((case, "clamped", round(NU_CUBE, 6), round(load, 6), _cells([n, n, n]), m)) for m in models]
            th = THESIS_ANALYTIC[case].get(round(load, 6))
            lines.append(f"| {_load_label(case, load)} | {analytic(case, load):.1f}"
                         + ("" if th is None else f" ({th:g})") + " | "
                         + " | ".join(_fmt(r, spec) + _thesis(r, spec) for r in cellsl) + " |")
        lines.append("")
    if "bending" in cfg["cases"]:
        L, _, h = BEND["size"]
        eb = analytic("bending", RHO_BEND)
        lines += [f"### Fig. 7.5, bending: tip deflection [mm], E = {BEND['E']:g} Pa, nu = {BEND['nu']:g}, "
                  f"rho = {RHO_BEND:g} kg/m^3, g = {BEND['g']:g}", "",
                  f"Euler-Bernoulli 1.5 rho g L^4/(E h^2) = {1e3 * eb:.3f} mm ({eb / L:.2%} of L); the thesis gives "
                  "curves only (HybMSS close to the analytic curve, HybMSS-FD softer, the more so on the finer mesh).",
                  "", "| cells " + head + " ours / Euler-Bernoulli: " + ", ".join(models) + " |",
                  "|---" + sep + "---|"]
        for cells in cfg["bend"]:
            cellsl = [by.get(("bending", "clamped", round(BEND["nu"], 6), round(RHO_BEND, 6), _cells(cells), m))
                      for m in models]
            ratios = ", ".join("-" if r is None or not math.isfinite(r["value"]) else f"{r['value'] / eb:.3f}"
                               for r in cellsl)
            lines.append(f"| {_cells(cells)} | " + " | ".join(
                "-" if r is None or not math.isfinite(r["value"]) else f"{1e3 * r['value']:.3f}" for r in cellsl)
                + f" | {ratios} |")
        lines.append("")
    # run time per model and case (the thesis' point: springs are cheap)
    lines += ["### Run time per model [s] (time_total of the run summary: setup + load steps; mean over the "
              "case's runs)", "", "| case " + head, "|---" + sep]
    for case in cfg["cases"]:
        cellsl = []
        for m in models:
            ts = [r["time_total"] for r in rows if r["model"] == m and r["case"].startswith(case)
                  and math.isfinite(r["time_total"])]
            cellsl.append(f"{sum(ts) / len(ts):.3f}" if ts else "-")
        lines.append(f"| {case} | " + " | ".join(cellsl) + " |")
    lines.append("")
    failed = [r for r in rows if not math.isfinite(r["value"]) and r.get("status") != "singular"]
    singular = [r for r in rows if r.get("status") == "singular"]
    if failed:
        lines += ["Runs that failed:", ""] + [f"- {r['model']} {r['case']} {r['cells']}: {r['message']}"
                                               for r in failed] + [""]
    if singular:
        lines += [f"Not run, singular stiffness at rest ({len(singular)}): "
                  + "; ".join(f"{r['model']} {r['case']}" for r in singular) + ".", ""]
    return lines
