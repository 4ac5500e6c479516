"""`tensormass report accuracy`: what accuracy a setting buys for its run time.

    tensormass report accuracy [SCENE] [--benchmark NAME [NAME...]] [--quick] --out DIR

Built-in benchmarks (--benchmark, default cantilever; "all" runs every one; see benchmarks.py):
cantilever (below), beam2d (2D plane-strain beam: triangle / triangle6 / quad, and the thesis'
claim 200 triangle6 vs 3200 triangles), volume (volume loss of a compressed 5 m cube against the
thesis' FEM numbers), mixed (the 8 x 1 x 1 m mixed-element bar against hexahedra and tetra10),
large_deflection (soft cantilever: hooke vs stvk vs neohookean vs stable_neohookean), shear and
torsion (the thesis' ch. 7 5 m cube: reaction force / torque on the top face against the thesis'
formulas and the finest tetra10 run), adaptive_beam (hooke / stvk / adaptive hooke->stvk on a large-
rotation cantilever), refinement (R_S refinement against uniform refinement; see adaptive.py), cook
(Cook's membrane: locking of 2D elements and the locking-free formulations; cook.py) and block (a
nearly incompressible cube of tetrahedra; block.py) and hybmss (the thesis' chapter-7 tables: MSS-Baudet,
HybMSS-FD, HybMSS and hexahedral FEM side by side; hybmss.py), cylinder (a thick-walled cylinder
under internal pressure in plane strain, prism and hexahedral layers against Lame; cylinder.py) and
incompressible (Newton iterations at nu = 0.499 on the organ and the cantilever, with FElupe's
plain-Newton counts where it is installed; incompressible.py) and dynamics (the organ falling for 1 s:
time per step against the trajectory's error for the budgeted implicit Euler step, CG caps, dt, explicit;
dynamics.py, whose rows end with DYNAMICS_COLUMNS) and tissue (Prony relaxation and creep, the LBMC
power laws as Prony fits in simple shear, the thesis' B22 block, HGO tension; tissue.py).
results.csv starts with a `benchmark` column, has a `formulation` column (runtime.physics.formulations) and a
`case` column (volume: nu and compression); with hybmss rows it ends with model, reference_value and
thesis_value (MODEL_COLUMNS);
`value` is the benchmark's measured quantity (tip deflection in m, volume loss in %).  Each
benchmark gets its own section, references and Pareto front in report.md and its own plot panel.

Without SCENE, the cantilever benchmark of BRIEF section 4 is swept: the thesis cantilever
(1.2 x 0.2 x 0.2 m, rho = 800 kg/m^3, E = 100 MPa, nu = 0.3) clamped at x = 0 and bending
under its own weight (g = 9.81, tip deflection about 6 mm: small enough for Hooke), over
element x law x quadrature x resolution.  The tip deflection (-u_z at the centre of the
free end, x = L) is compared with

* error_analytic:  Euler-Bernoulli plus Timoshenko's shear term,
  w = rho g A L^4 / (8 E I) + rho g A L^2 / (2 kappa G A), kappa = 5/6, G = E / (2 (1 + nu));
  beam theory itself is only approximate for this stubby beam (L / h = 6), so this error
  levels off near 1-2 % even for a converged solid model;
* error_reference: a converged numerical reference, a dedicated tetra10 / hooke / gauss2
  run on a mesh finer than (full mode) or as fine as the finest of (quick mode) the sweep.

With SCENE (a generated mesh), every combination of --elements x --laws x --quadratures (each
optional, default the scene's own; laws and quadratures apply to every material) is run with
mesh.cells scaled by 1, 2, 4, ... (--levels, default 3, 2 with --quick); combinations the
catalogue lacks (e.g. a quadrature an element does not have) are skipped with a note in
report.md.  The reference for the first probe's displacement is the finest run of the most
accurate-looking combination (quadratic element, then highest quadrature order, then most
dofs; ties: the first listed), error_reference = |u - u_ref| / |u_ref| (0 for the reference
itself); error_analytic is filled in only when the scene is a 3D generated bar under gravity
along -z with its first probe at x = L.

With SCENE whose mesh is a file (mesh.file), the levels are uniform refinements of the file's
mesh instead (file_levels.py): triangle / tetra files are refined (every edge halved per level)
and swept as read and raised to triangle6 / tetra10 (straight-sided midside nodes) by default;
triangle6 / tetra10 files are refined through their (possibly curved) cells' maps; other cell
types are swept on the mesh as read (one level).  The `cells` column is then the cell count.

Timings come from the run Summary: time_setup (model build, kernel loading, assembly
pattern; every combination is warmed up once on its coarsest mesh before it is measured, so
one-off numba compilation is not in it, and is reported apart in report.md), time_assembly,
time_solve (linear solves), time_total (setup + steps).  peak_memory_mb is tracemalloc's
peak over building and running the model: memory allocated through Python and numpy
(arrays, sparse matrices); memory that compiled libraries allocate on their own (SuperLU's
or CHOLMOD's factors, numba's runtime) is not counted.

Outputs (each written atomically, temp file + os.replace): DIR/results.csv,
DIR/error_vs_time.png (log-log error_reference against time_total, Pareto front marked),
DIR/convergence.png (error against free dofs), DIR/report.md.
"""
from __future__ import annotations

import copy
import csv
import io
import math
import time
import tomllib
from pathlib import Path

from ...runtime.base.errors import TensormassError
from ...runtime.base.files import write_bytes_atomic
from ...runtime.scene.scene import Scene
from ...runtime.base.errors import SceneError
from .adaptive import BENCHMARKS as ADAPTIVE
from .benchmarks import BENCHMARKS as CLASSIC
from .cook import cook
from .cylinder import cylinder
from .dynamics import DYNAMICS_COLUMNS, dynamics, plot as dynamics_plot
from .tissue import tissue
from .incompressible import incompressible
from .block import block
from .hybmss import hybmss
from .common import E_MOD, NU, RHO, SIZE, G, analytic_tip, measure, result_row
from .file_levels import FileLevels
from ..batch import map_tasks
from ..batch import DASK_MISSING, dask_available

__all__ = ["run_accuracy", "add_accuracy_command", "pareto_front", "COLUMNS", "MODEL_COLUMNS", "BENCHMARK_NAMES"]

COLUMNS = ["benchmark", "element", "law", "quadrature", "formulation", "cells", "case", "dofs", "value", "error_analytic",
           "error_reference", "time_setup", "time_assembly", "time_solve", "time_total", "peak_memory_mb"]
# appended to results.csv when a row names its model (the hybmss benchmark; blank in the other rows)
MODEL_COLUMNS = ["model", "reference_value", "thesis_value"]

# -- the built-in benchmark (SIZE, E_MOD, NU, RHO, G: common.py) --------------------------------------

FULL = {
    "elements": ["hexahedron", "tetra", "tetra10", "wedge", "pyramid"],
    "laws": ["hooke", "stvk"],
    "quadratures": {"tetra": ["gauss1", "gauss2"]},          # others: gauss2
    "levels": [[6, 1, 1], [12, 2, 2], [24, 4, 4], [48, 8, 8]],
    "levels_quadratic": [[6, 1, 1], [12, 2, 2], [24, 4, 4]],
    "reference": [48, 8, 8],
}
QUICK = {
    "elements": ["hexahedron", "tetra", "tetra10"],
    "laws": ["hooke"],
    "quadratures": {"tetra": ["gauss1"]},
    "levels": [[6, 1, 1], [12, 2, 2]],
    "levels_quadratic": [[6, 1, 1], [12, 2, 2]],
    "reference": [24, 4, 4],
}
QUADRATIC = ("tetra10", "triangle6")


def cantilever_scene(element, law, quadrature, cells):
    L = SIZE[0]
    data = {
        "name": f"accuracy_{element}_{law}_{quadrature}",
        "mesh": {"generate": "bar", "size": list(SIZE), "cells": list(cells), "element": element},
        "material": [{"region": "all", "law": law, "quadrature": quadrature, "E": E_MOD, "nu": NU,
                      "density": RHO}],
        "fixed": [{"box": [[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]}],
        "loads": {"gravity": [0.0, 0.0, -G]},
        "solver": {"kind": "static", "steps": 1},
        "probe": [{"name": "tip", "point": [L, SIZE[1] / 2, SIZE[2] / 2]}],
    }
    return Scene.from_dict(data)


# -- running ---------------------------------------------------------------------------------------
def _measure(scene, trace=True) -> tuple:
    """(Summary, tracemalloc peak in MB or nan) of one run of a validated scene."""
    summary, peak, _ = measure(scene, trace)
    return summary, peak


def _cantilever_combo(element, law, quad, levels) -> tuple:
    """One combination of the cantilever sweep (a task: apps/batch.map_tasks): warm-up on the coarsest
    mesh (compilation, timed apart), then every level; (rows, compile seconds, progress lines)."""
    rows, lines = [], []
    t0 = time.perf_counter()
    _measure(cantilever_scene(element, law, quad, levels[0]), trace=False)    # warm-up: compile
    compile_s = time.perf_counter() - t0
    for cells in levels:
        summary, peak = _measure(cantilever_scene(element, law, quad, cells))
        w = -float(summary.probes["tip"][2])
        rows.append(result_row(element, law, quad, cells, summary, peak, w))
        lines.append(f"  {element:<10} {law:<5} {quad:<6} cells {rows[-1]['cells']:<8} dofs {rows[-1]['dofs']:>6}  "
                     f"tip {w:.5g} m  total {summary.time['total']:.3f} s")
    return rows, compile_s, lines


def _cantilever_reference(ref_cells) -> tuple:
    """The numerical reference of the cantilever sweep (a task): (tip, free dofs, seconds, progress lines)."""
    _measure(cantilever_scene("tetra10", "hooke", "gauss2", [6, 1, 1]), trace=False)
    summary, _ = _measure(cantilever_scene("tetra10", "hooke", "gauss2", ref_cells), trace=False)
    return (-float(summary.probes["tip"][2]), summary.n_free_dofs, summary.time["total"],
            [f"reference: tetra10 hooke gauss2 cells {'x'.join(map(str, ref_cells))} ..."])


def _benchmark_task(name, quick, sweep) -> tuple:
    """One of the other built-in benchmarks as a task: (its result dict, its progress lines)."""
    BENCHMARKS = {**CLASSIC, **ADAPTIVE, "cook": cook, "block": block, "hybmss": hybmss, "cylinder": cylinder,
                  "incompressible": incompressible, "dynamics": dynamics, "tissue": tissue}
    lines = []
    return BENCHMARKS[name](quick, lines.append, sweep), lines


def _case(kind, *args):
    """The task function of the accuracy sweep's cases (module level: dask pickles it by name)."""
    return {"combo": _cantilever_combo, "reference": _cantilever_reference, "benchmark": _benchmark_task}[kind](*args)


def _builtin_tasks(quick, sweep) -> tuple:
    """The cantilever sweep's tasks: (config, combinations, [task]); the reference first (the longest)."""
    cfg = copy.deepcopy(QUICK if quick else FULL)
    if sweep:
        cfg.update(sweep)
    combos = [(e, l, q) for e in cfg["elements"] for l in cfg["laws"]
              for q in cfg["quadratures"].get(e, ["gauss2"])]
    tasks = [("reference", cfg["reference"])]
    tasks += [("combo", e, l, q, cfg["levels_quadratic"] if e in QUADRATIC else cfg["levels"]) for e, l, q in combos]
    return cfg, combos, tasks


def _builtin_result(cfg, outcomes) -> tuple:
    """rows, reference, compile seconds of the cantilever sweep from its tasks' results (task order)."""
    eb, timo = analytic_tip()
    (w_ref, ref_dofs, ref_time, _), *combos = outcomes
    rows, compile_s = [], {}
    for (r, seconds, _), (element, law, quad) in combos:
        rows += r
        compile_s[(element, law, quad)] = seconds
    ref_cells = cfg["reference"]
    for r in rows:
        r["error_analytic"] = abs(r["value"] - timo) / timo
        r["error_reference"] = abs(r["value"] - w_ref) / abs(w_ref)
    reference = {
        "numerical": f"tetra10 / hooke / gauss2 on {'x'.join(map(str, ref_cells))} cells "
                     f"({ref_dofs} free dofs, {ref_time:.2f} s): tip deflection {w_ref:.6g} m",
        "analytic": f"Euler-Bernoulli {eb:.6g} m + Timoshenko shear term (kappa = 5/6) = {timo:.6g} m; "
                    f"the numerical reference differs from it by {abs(w_ref - timo) / timo:.2%}",
        "subject": "cantilever 1.2 x 0.2 x 0.2 m, rho = 800 kg/m^3, E = 100 MPa, nu = 0.3, clamped at x = 0, "
                   "gravity 9.81 m/s^2 along -z; value = tip deflection = -u_z at the centre of the free end",
    }
    return rows, reference, compile_s


def _builtin(quick, progress, sweep, workers=1, scheduler=None) -> tuple:
    """The cantilever sweep alone (its tasks through apps/batch.map_tasks)."""
    cfg, combos, tasks = _builtin_tasks(quick, sweep)
    outcomes = _map(tasks, progress, workers, scheduler)
    return _builtin_result(cfg, [(outcomes[0]), *zip(outcomes[1:], combos)])


def _map(tasks, progress, workers, scheduler) -> list:
    """Run the tasks (apps/batch.map_tasks: in this process, or on dask), print each task's progress
    lines in task order, return the results in task order (a task's exception propagates)."""

    def show(i, outcome):
        for line in outcome[1][-1]:
            progress(line)
    outcomes = map_tasks(_case, tasks, workers=workers, scheduler=scheduler, label="case", capture=False,
                         progress=workers > 1 or scheduler is not None, on_result=show)
    return [value for _, value in outcomes]


def _settings(data, element, law, quad):
    """A copy of the scene dict with the mesh element and every material's law / quadrature replaced
    (None keeps the scene's own)."""
    d = copy.deepcopy(data)
    d.pop("output", None)
    if element is not None:
        d["mesh"]["element"] = element
    for m in d.get("material", []) if isinstance(d.get("material"), list) else []:
        if law is not None:
            m["law"] = law
        if quad is not None:
            m["quadrature"] = quad
    return d


def _user_scene(scene_path, quick, progress, sweep, settings=None) -> tuple:
    """Sweep a scene over element x law x quadrature (settings: elements / laws / quadratures lists,
    None = the scene's own) x resolution (cells x 1, 2, 4, ...; settings["levels"] of them)."""
    path = Path(scene_path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise TensormassError(f"scene file not found: {path}") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise TensormassError(f"cannot read scene file {path}: {exc}") from None
    data = {**data, "name": data.get("name", path.stem)}
    base = Scene.from_dict(data, base_dir=path.parent)
    if not base.probes:
        raise TensormassError(f"{path}: the accuracy sweep compares the first probe's displacement; add a [[probe]]")
    settings = settings or {}
    levels = settings.get("levels")
    if levels is not None and (not isinstance(levels, int) or levels < 1):
        raise TensormassError(f"--levels must be a positive integer, got {levels!r}")
    factors = (sweep or {}).get("factors") or [2 ** i for i in range(levels if levels else (2 if quick else 3))]
    probe = base.probes[0].name
    files = None                          # a mesh file: levels by uniform refinement (file_levels.py)
    if base.mesh.file is not None:
        files = FileLevels(base, path, settings.get("elements"), levels, default_levels=len(factors))
        factors = [2 ** i for i in range(files.n_levels)]
        progress(f"accuracy: {files.note}")
    elements = files.elements if files is not None else list(dict.fromkeys(settings.get("elements") or [None]))
    laws_ = list(dict.fromkeys(settings.get("laws") or [None]))
    quads = list(dict.fromkeys(settings.get("quadratures") or [None]))
    combos = [(e, l, q) for e in elements for l in laws_ for q in quads]
    progress(f"accuracy: {path}, {len(combos)} element/law/quadrature combination(s), cells x "
             f"{', '.join(map(str, factors))}; reference: the finest run of the most accurate-looking combination, "
             f"probe {probe!r}")
    rows, vectors, compile_s, notes, finest = [], [], {}, [], []
    for e, l, q in combos:
        d0 = _settings(data, e if files is None else None, l, q)
        try:
            scene0 = Scene.from_dict(d0, base_dir=path.parent) if files is None else \
                files.scene(d0, e, 0, path.parent)
        except SceneError as exc:
            own = (base.mesh.element if files is None else "+".join(files.solid_types(files.mesh0)),
                   "+".join(dict.fromkeys(m.law for m in base.materials)),
                   "+".join(dict.fromkeys(m.quadrature for m in base.materials)))
            label = " / ".join(x if x is not None else o for x, o in zip((e, l, q), own))
            notes.append(f"- skipped {label}: {exc}")
            progress(f"  skipped {label}: {exc}")
            continue
        element = scene0.mesh.element if files is None else "+".join(files.solid_types(files.mesh(e, 0)))
        law = "+".join(dict.fromkeys(m.law for m in scene0.materials))
        quad = "+".join(dict.fromkeys(m.quadrature for m in scene0.materials))
        analytic = _scene_analytic(scene0)
        n0 = len(rows)
        try:
            t0 = time.perf_counter()
            _measure(scene0, trace=False)                              # warm-up: compile / load kernels
            compile_s[(element, law, quad)] = time.perf_counter() - t0
            for level, k in enumerate(factors):
                if files is None:
                    d = copy.deepcopy(d0)
                    cells = [int(c) * int(k) for c in base.mesh.cells]
                    d["mesh"]["cells"] = cells
                    scene_k = Scene.from_dict(d, base_dir=path.parent)
                else:
                    scene_k = files.scene(d0, e, level, path.parent)
                    cells = [scene_k.load_mesh().n_cells]                 # the cells column: the count
                summary, peak = _measure(scene_k)
                u = [float(x) for x in summary.probes[probe]]
                vectors.append(u)
                rows.append(result_row(element, law, quad, cells, summary, peak, math.sqrt(sum(x * x for x in u))))
                if analytic is not None:
                    rows[-1]["error_analytic"] = abs(-u[2] - analytic) / analytic
                progress(f"  {element:<10} {law:<5} {quad:<6} cells {rows[-1]['cells']:<10} "
                         f"dofs {rows[-1]['dofs']:>7}  |u| {rows[-1]['value']:.5g} m  "
                         f"total {summary.time['total']:.3f} s")
        except Exception as exc:  # noqa: BLE001 - a failed setting is a result, reported
            notes.append(f"- failed {element} / {law} / {quad}: {type(exc).__name__}: {exc}"
                         + (" (coarser levels kept)" if len(rows) > n0 else ""))
            progress(f"  {element} / {law} / {quad} FAILED: {exc}")
        if len(rows) > n0:
            finest.append(len(rows) - 1)
    if not rows:
        raise TensormassError(f"{path}: no valid element / law / quadrature combination to sweep:\n"
                              + "\n".join(notes))
    # reference: quadratic elements first, then the highest quadrature order, then the most free dofs;
    # ties go to the first listed combination
    def _rank(i):
        r = rows[i]
        order = max((99 if part == "exact" else int("".join(c for c in part if c.isdigit()) or 0)
                     for part in r["quadrature"].split("+")), default=0)
        return (r["element"] in QUADRATIC, order, r["dofs"])
    ref_i = max(finest, key=_rank)           # max() keeps the first of equal keys
    ref = vectors[ref_i]
    nref = math.sqrt(sum(x * x for x in ref))
    for r, u in zip(rows, vectors):
        diff = math.sqrt(sum((a - b) ** 2 for a, b in zip(u, ref)))
        r["error_reference"] = diff / nref if nref > 0 else float("nan")
    rr = rows[ref_i]
    reference = {
        "numerical": f"the finest run of {rr['element']} / {rr['law']} / {rr['quadrature']} ({rr['cells']} cells, "
                     f"{rr['dofs']} free dofs; chosen as the most accurate-looking combination: quadratic element, "
                     f"then highest quadrature, then most dofs): probe {probe!r} "
                     f"u = [{', '.join(f'{x:.6g}' for x in ref)}] m (its own error_reference is 0)",
        "analytic": ("Euler-Bernoulli + Timoshenko shear (kappa = 5/6) tip deflection, where the scene is a 3D bar "
                     "under gravity along -z probed at x = L"
                     if any(math.isfinite(r["error_analytic"]) for r in rows)
                     else "none (not a 3D bar under gravity along -z probed at x = L)"),
        "subject": f"scene {path}; value is |u| of probe {probe!r}" + (f"; {files.note}" if files is not None else ""),
    }
    for r in rows:
        r["benchmark"] = "scene"
    if notes:
        notes = ["### Combinations skipped (not in the catalogue for this mesh) or failed", ""] + notes + [""]
    return rows, reference, compile_s, notes


def _scene_analytic(scene):
    """Beam-theory tip deflection when the scene is a 3D gravity-loaded bar probed at its end, else None."""
    if scene.mesh.file is not None:
        return None
    try:
        if len(scene.mesh.size) != 3 or len(scene.materials) != 1 or scene.loads.nodal:
            return None
        gx, gy, gz = scene.loads.gravity
        m = scene.materials[0]
        if gx or gy or gz >= 0 or m.E is None or m.nu is None:
            return None
        L = scene.mesh.size[0]
        if abs(scene.probes[0].point[0] - (scene.mesh.origin[0] + L)) > 1e-9 * L:
            return None
        return analytic_tip(tuple(scene.mesh.size), m.E, m.nu, m.density, -gz)[1]
    except (TypeError, ValueError, IndexError, AttributeError):
        return None


# -- analysis and output ---------------------------------------------------------------------------
def pareto_front(rows, x="time_total", y="error_reference") -> list:
    """Indices of the rows that no other row beats in both x and y (lower is better), by x."""
    ok = [i for i, r in enumerate(rows) if math.isfinite(r[x]) and math.isfinite(r[y])]
    front = []
    for i in ok:
        xi, yi = rows[i][x], rows[i][y]
        dominated = any(rows[j][x] <= xi and rows[j][y] <= yi and (rows[j][x] < xi or rows[j][y] < yi)
                        for j in ok if j != i)
        if not dominated:
            front.append(i)
    return sorted(front, key=lambda i: rows[i][x])


def _csv_bytes(rows) -> bytes:
    buf = io.StringIO()
    columns = (COLUMNS + (MODEL_COLUMNS if any("model" in r for r in rows) else [])
               + (DYNAMICS_COLUMNS if any("setting" in r for r in rows) else []))
    w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{r[k]:.6g}" if isinstance(r.get(k), float) else r.get(k, "")) for k in columns})
    return buf.getvalue().encode("utf-8")


def _combo(r) -> str:
    """element / law / quadrature (/ formulation, when not the displacement one) of a row."""
    form = r.get("formulation", "displacement")
    return f"{r['element']} / {r['law']} / {r['quadrature']}" + ("" if form == "displacement" else f" / {form}")


def _series(rows) -> dict:
    out = {}
    for i, r in enumerate(rows):
        out.setdefault(_combo(r), []).append(i)
    return out


def _groups(rows) -> dict:
    """benchmark -> indices of its rows, in order of first appearance."""
    out = {}
    for i, r in enumerate(rows):
        out.setdefault(r.get("benchmark", ""), []).append(i)
    return out


def _fronts(rows) -> dict:
    """benchmark -> Pareto front (indices into rows) over its main rows with finite errors."""
    fronts = {}
    for bench, idx in _groups(rows).items():
        main = [i for i in idx if rows[i].get("main", True)]
        fronts[bench] = [main[j] for j in pareto_front([rows[i] for i in main])]
    return fronts


def _plot(rows, x, ylabel_title, fronts=None) -> bytes:
    # deferred: matplotlib costs ~0.3 s; only the plots of a finished sweep need it
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    groups = [(b, [i for i in idx if rows[i].get("main", True)]) for b, idx in _groups(rows).items()]
    groups = [(b, idx) for b, idx in groups
              if any(math.isfinite(rows[i]["error_reference"]) and rows[i]["error_reference"] > 0 for i in idx)]
    groups = groups or [("", [])]
    fig = Figure(figsize=(8 * min(len(groups), 2), 5.5 * ((len(groups) + 1) // 2)))
    FigureCanvasAgg(fig)
    markers = "osD^vP*Xh<>p"
    cols = min(len(groups), 2)
    for g, (bench, idx) in enumerate(groups):
        ax = fig.add_subplot((len(groups) + 1) // 2, cols, g + 1)
        sub = [rows[i] for i in idx]
        for k, (label, sidx) in enumerate(_series(sub).items()):
            sidx = sorted(sidx, key=lambda i: sub[i]["dofs"])          # lines follow refinement
            pts = [(sub[i][x], sub[i]["error_reference"]) for i in sidx
                   if sub[i][x] > 0 and sub[i]["error_reference"] > 0 and math.isfinite(sub[i]["error_reference"])]
            if pts:          # a dynamics series is settings, not a refinement: no line between them
                ax.plot([p[0] for p in pts], [p[1] for p in pts], marker=markers[k % len(markers)], label=label,
                        ls="none" if "setting" in sub[sidx[0]] else "-")
        front = (fronts or {}).get(bench, [])
        pts = [(rows[i][x], rows[i]["error_reference"]) for i in front
               if rows[i][x] > 0 and rows[i]["error_reference"] > 0]
        if pts:
            ax.step([p[0] for p in pts], [p[1] for p in pts], where="post", color="black", lw=1, ls="--")
            ax.scatter([p[0] for p in pts], [p[1] for p in pts], s=160, facecolors="none", edgecolors="black",
                       linewidths=1.5, label="Pareto front", zorder=5)
        if idx:
            ax.set_xscale("log")
            ax.set_yscale("log")
        ax.set_xlabel(ylabel_title[0])
        ax.set_ylabel("relative error against the numerical reference")
        ax.set_title(f"{ylabel_title[1]}: {bench}" if bench else ylabel_title[1])
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def _fmt(v, spec=".3g") -> str:
    return "n/a" if isinstance(v, float) and not math.isfinite(v) else format(v, spec)


def _section(bench, rows, idx, front, reference, notes) -> list:
    lines = [f"## Benchmark `{bench}`", "",
             f"- Subject: {reference['subject']}.",
             f"- Reference (`error_reference`): {reference['numerical']}.",
             f"- Analytic / published reference (`error_analytic`): {reference['analytic']}.", ""]
    lines += list(notes)
    lines += [f"### Pareto front of `{bench}` (time_total against error_reference)", "",
              "Settings that no other run of this benchmark beats in both total run time and error against "
              "the numerical reference:", ""]
    for i in front:
        r = rows[i]
        lines.append(f"- {_combo(r)}, cells {r['cells']} "
                     f"({r['dofs']} dofs): error {_fmt(r['error_reference'])} in {r['time_total']:.3g} s")
    if not front:
        lines.append("- (none: no finite errors against a numerical reference)")
    lines += ["", f"### All runs of `{bench}`", "",
              "| element | law | quadrature | cells | case | dofs | value | error analytic | error reference "
              "| setup [s] | assembly [s] | solve [s] | total [s] | peak memory [MB] | Pareto |",
              "|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    on = set(front)
    for i in idx:
        r = rows[i]
        lines.append(f"| {r['element']} | {r['law']} | {r['quadrature']} | {r['cells']} | {r['case']} | {r['dofs']} | "
                     f"{r['value']:.5g} | {_fmt(r['error_analytic'])} | {_fmt(r['error_reference'])} | "
                     f"{r['time_setup']:.3g} | {r['time_assembly']:.3g} | {r['time_solve']:.3g} | "
                     f"{r['time_total']:.3g} | {_fmt(r['peak_memory_mb'], '.1f')} | {'yes' if i in on else ''} |")
    lines.append("")
    return lines


def _report_md(rows, fronts, results, quick, scene_path, elapsed) -> str:
    mode = "quick" if quick else "full"
    what = (f"scene `{scene_path}`" if scene_path else
            "built-in benchmark" + ("s " if len(results) > 1 else " ") + ", ".join(f"`{b}`" for b in results))
    lines = [f"# Accuracy report ({what}, {mode} sweep)", "",
             f"{len(rows)} runs in {elapsed:.1f} s. Each benchmark has its own references and Pareto front "
             "(Pareto front = settings no other run of the same benchmark beats in both run time and error).", ""]
    groups = _groups(rows)
    compile_s = {}
    for bench, res in results.items():
        idx = groups.get("scene" if scene_path else bench, [])
        lines += _section(bench if not scene_path else "scene", rows, idx, fronts.get("scene" if scene_path else bench, []),
                          res["reference"], res.get("notes", []))
        for key, t in res["compile_s"].items():
            compile_s[(bench,) + tuple(key)] = t
    lines += ["## What the columns measure", "",
              "- `benchmark`: which benchmark; `case`: the load case within it (volume: nu and compression); "
              "`value`: the benchmark's measured quantity (tip deflection in m; volume: relative volume loss in %; "
              "shear: lateral reaction force on the top face in N; torsion: torque on the top face in N m; "
              "user scene: |u| of the first probe).",
              "- Times are from the run summary: `time_setup` = model build, kernel loading and assembly pattern "
              "(each combination was warmed up once on a coarse mesh first, so one-off compilation is "
              "excluded), `time_assembly` = assembly of forces/stiffness, `time_solve` = linear solves, "
              "`time_total` = setup + steps.",
              "- `peak_memory_mb` = tracemalloc peak while building and running the model: memory allocated "
              "through Python and numpy (arrays, sparse matrices); memory that compiled libraries allocate "
              "themselves (sparse factorisation, numba runtime) is not included.",
              "- `dofs` = free (unconstrained) degrees of freedom.", "",
              "Warm-up runs (first load or compilation of each combination's kernels, coarse mesh):", ""]
    for (b, e, l, q), t in compile_s.items():
        lines.append(f"- {b}: {e} / {l} / {q}: {t:.2f} s")
    lines += ["", "Plots: `error_vs_time.png` (error against total time, one panel per benchmark with a numerical "
              "reference, Pareto front circled), `convergence.png` (error against free dofs).", ""]
    return "\n".join(lines)


# -- entry points ----------------------------------------------------------------------------------
BENCHMARK_NAMES = ("cantilever", "beam2d", "volume", "mixed", "large_deflection", "shear", "torsion",
                   "adaptive_beam", "refinement", "cook", "block", "hybmss", "cylinder", "incompressible",
                   "dynamics", "tissue")


def _resolve(benchmarks) -> list:
    if not benchmarks:
        return ["cantilever"]
    if isinstance(benchmarks, str):
        benchmarks = [benchmarks]
    names = []
    for b in benchmarks:
        if b == "all":
            names += list(BENCHMARK_NAMES)
        elif b in BENCHMARK_NAMES:
            names.append(b)
        else:
            raise TensormassError(f"unknown benchmark {b!r}; choose from {', '.join(BENCHMARK_NAMES)} or all")
    return list(dict.fromkeys(names))


def run_accuracy(out_dir, scene_path=None, quick: bool = False, progress=print, _sweep: dict | None = None,
                 benchmarks=None, elements=None, laws=None, quadratures=None, levels=None,
                 workers: int = 1, scheduler: str | None = None) -> list:
    """Run the sweep and write results.csv, error_vs_time.png, convergence.png and report.md to out_dir.

    benchmarks: names from BENCHMARK_NAMES or "all" (default: cantilever); ignored with scene_path.
    elements / laws / quadratures (lists) and levels (int): the user-scene sweep (SCENE only); each
    None keeps the scene's own setting, levels defaults to 3 (2 with quick).
    _sweep (tests): overrides of the sweep (cantilever: elements, laws, quadratures, levels,
    levels_quadratic, reference; user scene: factors; the other benchmarks: a dict under their
    name, see benchmarks.py).  Returns the result rows (dicts with COLUMNS and "main").
    workers / scheduler: the built-in benchmarks' independent cases (each cantilever combination, its
    reference, each other benchmark) run as tasks through apps/batch.map_tasks: in this process
    (workers 1), or on a local dask cluster of that many single-threaded workers, or on the cluster at
    scheduler; the rows come back in the same order with the same values (only the time_* and
    peak_memory_mb columns are measurements). A SCENE sweep runs in this process.
    """
    progress = progress or (lambda *_: None)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise TensormassError(f"--out {out}: exists and is not a folder")
    settings = {"elements": elements, "laws": laws, "quadratures": quadratures, "levels": levels}
    if scene_path is None and any(v is not None for v in settings.values()):
        raise TensormassError("--elements / --laws / --quadratures / --levels sweep a SCENE; give a scene file")
    names = _resolve(benchmarks) if scene_path is None else []
    start = time.perf_counter()
    rows, results = [], {}
    if scene_path is not None:
        r, reference, compile_s, notes = _user_scene(scene_path, quick, progress, _sweep, settings)
        rows += r
        results["scene"] = {"reference": reference, "compile_s": compile_s, "notes": notes}
    tasks, spans = [], {}
    for name in names:                    # every case of every benchmark: one list of tasks
        if name == "cantilever":
            sweep = {k: v for k, v in (_sweep or {}).items() if k not in BENCHMARK_NAMES}
            cfg, combos, more = _builtin_tasks(quick, sweep)
            eb, timo = analytic_tip()
            progress(f"accuracy: cantilever under self weight, {len(combos)} element/law/quadrature combinations; "
                     f"analytic tip deflection {timo:.5g} m (Euler-Bernoulli {eb:.5g} m + shear)")
        else:
            more = [("benchmark", name, quick, (_sweep or {}).get(name))]
        spans[name] = (len(tasks), len(tasks) + len(more))
        tasks += more
    outcomes = _map(tasks, progress, workers, scheduler) if tasks else []
    for name in names:
        got = outcomes[slice(*spans[name])]
        if name == "cantilever":
            r, reference, compile_s = _builtin_result(cfg, [got[0], *zip(got[1:], combos)])
            results[name] = {"reference": reference, "compile_s": compile_s, "notes": []}
        else:
            res = got[0][0]
            r = res["rows"]
            results[name] = res
        rows += r
    elapsed = time.perf_counter() - start
    fronts = _fronts(rows)
    out.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(out / "results.csv", _csv_bytes(rows))
    write_bytes_atomic(out / "error_vs_time.png",
                  _plot(rows, "time_total", ("total run time [s]", "Error against run time"), fronts))
    write_bytes_atomic(out / "convergence.png",
                  _plot(rows, "dofs", ("free degrees of freedom", "Convergence under mesh refinement")))
    if any("setting" in r for r in rows):
        write_bytes_atomic(out / "dynamics.png", dynamics_plot([r for r in rows if "setting" in r]))
    write_bytes_atomic(out / "report.md", _report_md(rows, fronts, results, quick, scene_path, elapsed).encode("utf-8"))
    for bench, front in fronts.items():
        if not front:
            continue
        progress(f"Pareto front of {bench} (total time vs error against the numerical reference):")
        for i in front:
            r = rows[i]
            progress(f"  {_combo(r)} cells {r['cells']}: "
                     f"error {_fmt(r['error_reference'])}, {r['time_total']:.3g} s")
    progress(f"wrote {out / 'results.csv'}, error_vs_time.png, convergence.png, report.md ({elapsed:.1f} s)")
    return rows


def cmd_accuracy(args) -> int:
    kwargs = {"benchmarks": args.benchmark} if getattr(args, "benchmark", None) else {}
    for key in ("elements", "laws", "quadratures", "levels"):
        if getattr(args, key, None) is not None:
            kwargs[key] = getattr(args, key)
    workers, scheduler = workers_of(args), getattr(args, "scheduler", None)
    if workers > 1 or scheduler is not None:      # only then: the defaults are run_accuracy's own
        kwargs.update(workers=workers, scheduler=scheduler)
    run_accuracy(args.out, scene_path=args.scene, quick=args.quick, **kwargs)
    return 0


def workers_of(args) -> int:
    workers = getattr(args, "workers", None) or 1
    if workers < 1:
        raise TensormassError(f"--workers must be at least 1, got {workers}")
    if workers > 1 or getattr(args, "scheduler", None):
        if not dask_available():
            raise TensormassError(DASK_MISSING)
    return workers


def add_workers_options(p) -> None:
    """--workers N / --scheduler ADDRESS of the reports (apps/batch.map_tasks)."""
    p.add_argument("--workers", type=int, metavar="N", default=None,
                   help="run the independent cases on a local dask cluster of N single-threaded worker processes "
                        "(default 1: in this process; the results are the same, only timings differ)")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="run the independent cases on an existing dask cluster (tcp://host:8786)")


def add_accuracy_command(subparsers) -> None:
    """Add `accuracy [SCENE] [--benchmark NAME...] [--quick] --out DIR` to an argparse subparsers object."""
    p = subparsers.add_parser("accuracy", help="sweep element x law x quadrature x resolution: error against "
                                               "run time (results.csv, plots, report.md)")
    p.add_argument("scene", nargs="?", default=None,
                   help="scene file (.toml) to refine: a generated bar (mesh.cells scaled) or a mesh file (triangle/"
                        "tetra meshes refined uniformly and raised to quadratic); default: the built-in cantilever "
                        "benchmark")
    p.add_argument("--benchmark", nargs="+", metavar="NAME", choices=BENCHMARK_NAMES + ("all",), default=None,
                   help="built-in benchmarks to run: " + ", ".join(BENCHMARK_NAMES) + " or all (default: cantilever)")
    p.add_argument("--elements", nargs="+", metavar="ELEMENT", default=None,
                   help="SCENE sweep: mesh elements to try (default: the scene's own; a tetra / triangle mesh file: "
                        "it and tetra10 / triangle6)")
    p.add_argument("--laws", nargs="+", metavar="LAW", default=None,
                   help="SCENE sweep: material laws to try, applied to every material (default: the scene's own)")
    p.add_argument("--quadratures", nargs="+", metavar="QUAD", default=None,
                   help="SCENE sweep: quadratures to try, applied to every material (default: the scene's own)")
    p.add_argument("--levels", type=int, metavar="N", default=None,
                   help="SCENE sweep: resolution levels, cells x 1, 2, 4, ... or a mesh file refined 0, 1, 2, ... "
                        "times (default 3, 2 with --quick)")
    p.add_argument("--quick", action="store_true", help="a small sweep (well under 2 minutes)")
    p.add_argument("--out", required=True, help="output folder")
    add_workers_options(p)
    p.set_defaults(run=cmd_accuracy)
