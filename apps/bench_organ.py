"""`tensormass bench organ`: unstructured organ meshes from gmsh, static and implicit Euler, every solver.

    tensormass bench organ [--quick] [--json FILE] [--cases NAME ...] [--solvers NAME ...] [--threads N ...]

Cases (the scene of examples/organ/scene.toml: neo-Hookean, E 5 kPa, nu 0.45,
density 1050, gravity and a 400 Pa traction on the top patch, clamped underneath;
the organ scaled 2.2x, semi-axes 88 x 66 x 66 mm, meshed by tensormass.apps.organ_mesh):

    tetra10_h8_static        tetra10, h = 8 mm, static, one load step
    tetra10_h6_static        tetra10, h = 6 mm, static, one load step
    tetra_h6_implicit_euler  tetra (gauss1), h = 6 mm, implicit Euler, 10 steps of 10 ms
    tetra_h6_1s              the same for 1 s (100 steps), the auto solver only; and _interactive
                             ([solver] mode = "interactive") and _kept (K kept the whole run) beside
                             it, each with its speed-up per step over the exact case and its probe
                             trajectory's error against the exact case's
    tetra10_h8_1s            tetra10 (gauss2), h = 8 mm, the same 1 s; and _interactive
    hex_cantilever_48x8x8    the neo-Hookean hexahedral cantilever of `bench steps` (48 x 8 x 8,
                             gauss2, E 1 MPa, nu 0.3, gravity), static, one load step: a
                             Newton iteration of a real run

Every case runs through the public API (Scene from TOML text, Simulation.run)
once per linear solver of `tensormass.runtime.solve.solvers.METHODS` (read at run time;
a solver whose module reports it unavailable is skipped) and per thread count,
each in a fresh subprocess with TENSORMASS_THREADS set, so that no run inherits
another's caches, factors or thread pools.  Reported per run: total wall time
(setup included), setup, Newton iterations, assembly and linear-solve seconds
(the runtime's Summary.time), ms per Newton iteration (static) or per step after
the first (dynamic), the process's peak resident memory, the solver actually used,
and a displacement probe (the mesh node nearest the organ's top pole / the
cantilever's free end).

FElupe (`pip install tensormass[compare]`) solves the static cases in the same
run, in its own subprocess: the same mesh (points and cells as tensormass read
them), NeoHookeCompressible (the same energy as tensormass' neohookean), the same
quadrature (tetra10: 4 points, tetra: 1, hexahedron: 2 x 2 x 2), the same clamped
dofs and the same external force vector (tensormass' consistent gravity and
traction loads, handed over as nodal forces), plain Newton with FElupe's assembly
and default linear solver (SciPy spsolve) to tensormass' convergence test
(|residual on free dofs| <= 1e-8 max(|load on free dofs|, |reactions|)).  The report
gives FElupe's Newton time over ours and the probe of both.

The meshes are generated once into the user cache (runtime.base.cache.cache_dir()/organ,
named by the script's hash and the options; gmsh runs single-threaded, so the
same options give the same file).  Without gmsh the command stops with a message
saying how to install it.  A case whose memory estimate (runtime.scene.resources) is
above what the machine has is skipped with a note.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..runtime.base.errors import TensormassError
from ..runtime.base.files import write_json_atomic
from .machine import format_machine, machine_info
from . import organ_mesh as mesh_maker
from ..runtime.base import parallel
from ..runtime.base.cache import cache_dir, writable_cache_dir
from ..runtime.model.model import Model
from ..runtime.run.simulation import Simulation
from ..runtime.scene import resources
from ..runtime.scene.scene import Scene
from ..runtime.solve import solvers
from .bench_steps import E as E_BAR, NEWTON_CASE, NU as NU_BAR, scene_text as bar_text

MAKE_ORGAN = Path(__file__).resolve().with_name("organ_mesh.py")      # the mesh maker (its hash names the meshes)
ORGAN_SCALE = 2.2                      # liver-sized: semi-axes 88 x 66 x 66 mm
E, NU, DENSITY = 5.0e3, 0.45, 1050.0
GRAVITY = (0.0, 0.0, -9.81)
TRACTION = (0.0, 0.0, -400.0)
DT = 0.01
NEWTON_TOLERANCE = 1e-8                # the scene default (runtime.scene.types.Solver.newton_tolerance)
RESULT_TAG = "TM-ORGAN-RESULT "
DEFAULT_THREADS = (1, 2)
DEFAULT_TIMEOUT = 900.0


@dataclass(frozen=True)
class Case:
    name: str
    body: str                          # "organ" | "cantilever"
    element: str                       # tetra | tetra10 | hexahedron
    kind: str                          # static | implicit_euler
    steps: int
    size: float = 0.0                  # organ: mesh size (m)
    scale: float = ORGAN_SCALE         # organ: geometry scale
    cells: tuple = ()                  # cantilever: cells along x, y, z
    solver: tuple = ()                 # extra [solver] keys, (key, value) pairs: the budgeted step
    exact: str = ""                    # a budgeted case: the exact case it is compared with

    @property
    def order(self) -> int:
        return 2 if self.element == "tetra10" else 1

    @property
    def title(self) -> str:
        if self.body == "cantilever":
            return f"hexahedral cantilever {'x'.join(map(str, self.cells))}, {self.kind}"
        return f"organ x{self.scale:g} {self.element} h = {1e3 * self.size:g} mm, {self.kind}"


INTERACTIVE = (("mode", "interactive"),)
KEPT = (("stiffness_every", 10 ** 8), ("stiffness_tolerance", math.inf), ("factor_tolerance", 1e-4))
CASES = (
    Case("tetra10_h8_static", "organ", "tetra10", "static", 1, size=0.008),
    Case("tetra10_h6_static", "organ", "tetra10", "static", 1, size=0.006),
    Case("tetra_h6_implicit_euler", "organ", "tetra", "implicit_euler", 10, size=0.006),
    Case("hex_cantilever_48x8x8", "cantilever", "hexahedron", "static", 1, cells=(48, 8, 8)),
    # 1 s of falling, exact and budgeted (runtime.physics.integrators.ImplicitEuler): the auto solver only
    Case("tetra_h6_1s", "organ", "tetra", "implicit_euler", 100, size=0.006),
    Case("tetra_h6_1s_interactive", "organ", "tetra", "implicit_euler", 100, size=0.006, solver=INTERACTIVE,
         exact="tetra_h6_1s"),
    Case("tetra_h6_1s_kept", "organ", "tetra", "implicit_euler", 100, size=0.006, solver=KEPT, exact="tetra_h6_1s"),
    Case("tetra10_h8_1s", "organ", "tetra10", "implicit_euler", 100, size=0.008),
    Case("tetra10_h8_1s_interactive", "organ", "tetra10", "implicit_euler", 100, size=0.008, solver=INTERACTIVE,
         exact="tetra10_h8_1s"),
)
QUICK_CASES = (
    Case("quick_tetra10_h12_static", "organ", "tetra10", "static", 1, size=0.012, scale=1.0),
    Case("quick_tetra_h9_implicit_euler", "organ", "tetra", "implicit_euler", 4, size=0.009, scale=1.0),
    Case("quick_tetra_h9_interactive", "organ", "tetra", "implicit_euler", 4, size=0.009, scale=1.0,
         solver=INTERACTIVE, exact="quick_tetra_h9_implicit_euler"),
    Case("quick_hex_cantilever_12x2x4", "cantilever", "hexahedron", "static", 1, cells=(12, 2, 4)),
)
# the 1 s cases run with the default solver only (their point is the step, not the solver)
LONG_STEPS = 100
QUICK_SOLVERS = ("auto",)
QUICK_THREADS = (1,)


# -- meshes -----------------------------------------------------------------------------------
class GmshMissing(TensormassError):
    """gmsh is not installed: the organ meshes cannot be made."""


def load_make_organ():
    """The organ mesh maker (tensormass.apps.organ_mesh, installed with the package)."""
    return mesh_maker


def require_gmsh() -> None:
    try:
        import gmsh  # noqa: F401
    except ImportError:
        raise GmshMissing("bench organ: the gmsh package is not installed, so the organ meshes cannot be made; "
                          "install it with `pip install tensormass[mesh]` (or `pip install gmsh`)") from None


def mesh_path(case: Case, folder: Path | None = None) -> Path:
    """Where the case's mesh lives in the cache (named by the script's hash and the options)."""
    digest = hashlib.sha256(MAKE_ORGAN.read_bytes()).hexdigest()[:12]
    folder = Path(folder) if folder is not None else cache_dir() / "organ"
    return folder / f"organ-{digest}-x{case.scale:g}-h{1e3 * case.size:g}mm-o{case.order}.msh"


def organ_mesh(case: Case, folder: Path | None = None) -> tuple[Path, float]:
    """(path, seconds spent generating: 0 when it was in the cache already)."""
    path = mesh_path(case, folder)
    if path.is_file():
        return path, 0.0
    require_gmsh()
    writable_cache_dir(path.parent, "bench organ (the organ meshes)")
    maker = load_make_organ()
    t0 = time.perf_counter()
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".organ-", suffix=".msh")
    os.close(fd)
    try:
        maker.make(tmp, size=case.size, order=case.order, scale=case.scale)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path, time.perf_counter() - t0


# -- scenes -----------------------------------------------------------------------------------
def organ_scene_text(case: Case, mesh_file: Path, nu: float = NU, formulation: str = "displacement") -> str:
    quadrature = "gauss2" if case.element == "tetra10" else "gauss1"
    solver = {"kind": case.kind, "steps": case.steps, "dt": DT, "newton_tolerance": NEWTON_TOLERANCE, **dict(case.solver)}
    return organ_text(case.name, mesh_file, quadrature, solver, nu, formulation)


def organ_text(name: str, mesh_file, quadrature: str, solver: dict, nu: float = NU,
               formulation: str = "displacement") -> str:
    """The organ scene (the material, clamp and loads of examples/organ/scene.toml) on a mesh file of
    the organ, with these [solver] keys (also the scene of `report accuracy --benchmark dynamics`);
    nu and formulation: the material's (the incompressible and tissue reports change them)."""
    return f"""
name = "{name}"
[mesh]
file = {json.dumps(str(mesh_file))}
[[material]]
region = "organ"
law = "neohookean"
quadrature = "{quadrature}"
{"" if formulation == "displacement" else f'formulation = "{formulation}"{chr(10)}'}E = {E}
nu = {nu}
density = {DENSITY}
[[fixed]]
region = "attached"
[loads]
gravity = {list(GRAVITY)}
[[loads.traction]]
region = "loaded"
value = {list(TRACTION)}
[solver]
""" + "".join(f"{k} = {_toml(v)}\n" for k, v in solver.items())


def _toml(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    return "inf" if isinstance(v, float) and math.isinf(v) else repr(v)


def scene_text(case: Case, mesh_file: Path | None) -> str:
    if case.body == "organ":
        return organ_scene_text(case, mesh_file)
    size = NEWTON_CASE[3]
    return bar_text("hexahedron", case.cells, size, "neohookean", case.kind, "auto", case.steps)


def probe_point(case: Case) -> tuple:
    """Where the displacement is compared: the organ's top pole, the cantilever's free end (top middle)."""
    if case.body == "organ":
        return (0.0, 0.0, 0.030 * case.scale)
    lx, ly, lz = NEWTON_CASE[3]
    return (lx, ly / 2, lz)


def make_scene(text: str, method: str):
    """Scene from TOML text with [solver] linear = method (the scene keys take every solvers.METHODS name)."""
    text = re.sub(r'(?m)^linear = .*\n', "", text)
    return Scene.from_string(text.replace('[solver]\n', f'[solver]\nlinear = "{method}"\n', 1))


def available_solvers(requested=None) -> tuple[list, dict]:
    """(methods to run, {method: why skipped}) from solvers.METHODS, read now."""
    methods, skipped = [], {}
    offered = list(solvers.METHODS)
    for name in (requested or offered):
        if name not in offered:
            raise TensormassError(f"unknown linear solver {name!r}; runtime.solve.solvers offers {', '.join(offered)}")
        reason = solvers.unavailable(name)
        if reason:
            skipped[name] = reason
        else:
            methods.append(name)
    return methods, skipped


# -- one run (subprocess) ---------------------------------------------------------------------
def _nearest_node(points: np.ndarray, point) -> int:
    return int(np.argmin(np.linalg.norm(points - np.asarray(point, dtype=float), axis=1)))


def _peak_mb() -> float | None:
    try:
        import resource
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0     # kB on Linux
    except (ImportError, OSError):
        return None


def _threads_in_use() -> dict:
    import numba
    out = {"numba": int(numba.get_num_threads())}
    out["runtime"] = int(parallel.worker_threads())
    return out


def run_tensormass(spec: dict) -> dict:
    """One configuration, in this process: Simulation.run of the case's scene with the given solver."""
    case = Case(**{k: tuple(v) if k == "cells" else v for k, v in spec["case"].items()})
    scene = make_scene(scene_text(case, spec.get("mesh")), spec["method"])
    t0 = time.perf_counter()
    node, trajectory = None, []

    def record(s):                     # the probe node's displacement after every step
        trajectory.append([float(x) for x in s.displacement[node]])

    dynamic = case.kind != "static"
    sim = Simulation(scene, output=False, on_step=record if dynamic else None)
    try:
        node = _nearest_node(sim.model.mesh.points, probe_point(case))
        summary = sim.run().to_dict()
    except TensormassError as error:
        summary = getattr(error, "summary", None)
        return {"status": "failed", "message": str(error).splitlines()[0],
                "wall_s": time.perf_counter() - t0, "peak_mb": _peak_mb(), "threads_in_use": _threads_in_use(),
                "used": getattr(getattr(sim, "ctx", None), "linear", None) and sim.ctx.linear.last,
                "summary_time": None if summary is None else dict(summary.time)}
    wall = time.perf_counter() - t0
    t, it = summary["time"], summary["iterations"]
    steps_wall = summary["per_step"]["wall"]
    newton = int(it["newton"])
    stepping = t["total"] - t["setup"]
    u = sim.displacement
    walls = [float(w) for w in steps_wall[1:]]
    out = {"status": summary["status"], "wall_s": wall, "total_s": t["total"], "setup_s": t["setup"],
           "stepping_s": stepping, "assembly_s": t["assembly"], "solve_s": t["linear_solve"],
           "newton": newton, "linear_iterations": int(it["linear"]), "steps": summary["steps"],
           "elements": summary["n_elements"], "free_dofs": summary["n_free_dofs"],
           "used": sim.ctx.linear.last, "peak_mb": _peak_mb(), "threads_in_use": _threads_in_use(),
           "probe_node": node, "probe": [float(x) for x in u[node]], "max_u": float(np.abs(u).max()),
           "per_iteration_ms": 1e3 * stepping / newton if newton else None,
           "first_step_ms": 1e3 * steps_wall[0] if steps_wall else None,
           "later_steps_ms": 1e3 * float(np.mean(walls)) if walls else None,
           "p95_steps_ms": 1e3 * float(np.percentile(walls, 95)) if walls else None,
           "trajectory": trajectory if dynamic else None,
           "budget": summary["iterations"].get("budget")}
    return out


def run_felupe(spec: dict) -> dict | None:
    """The same static problem in FElupe (see the module docstring); None without FElupe."""
    try:
        import felupe as fem
    except ImportError:
        return None
    case = Case(**{k: tuple(v) if k == "cells" else v for k, v in spec["case"].items()})
    scene = make_scene(scene_text(case, spec.get("mesh")), "auto")
    model = Model.from_scene(scene)                  # not timed: only the mesh, the clamp and the loads
    if len(model.parts) != 1:
        raise TensormassError("bench organ: FElupe comparison expects one material part")
    part = model.parts[0]
    e, nu = (E, NU) if case.body == "organ" else _cantilever_material()
    mu, lam = e / (2 * (1 + nu)), e * nu / ((1 + nu) * (1 - 2 * nu))
    regions = {"tetra10": "RegionQuadraticTetra", "tetra": "RegionTetra", "hexahedron": "RegionHexahedron"}
    f_ext = np.asarray(model.f_ext, dtype=float)
    fixed, free = np.asarray(model.fixed_dofs), np.asarray(model.free_dofs)
    t0 = time.perf_counter()
    mesh = fem.Mesh(np.array(model.mesh.points, dtype=float), np.array(part.cells), part.element)
    region = getattr(fem, regions[part.element])(mesh)          # default quadratures: 4 / 1 / 8 points
    field = fem.FieldContainer([fem.Field(region, dim=3)])
    solid = fem.SolidBody(fem.NeoHookeCompressible(mu=mu, lmbda=lam), field)
    setup = time.perf_counter() - t0
    ext0 = np.zeros(fixed.size)
    load = max(float(np.linalg.norm(f_ext[free])), 1e-30)
    assembly = solve = 0.0
    iterations = 0
    t0 = time.perf_counter()
    while True:
        ta = time.perf_counter()
        r = np.asarray(solid.assemble.vector(field).todense()).ravel() - f_ext
        assembly += time.perf_counter() - ta
        res = float(np.linalg.norm(r[free]))
        if res <= NEWTON_TOLERANCE * max(load, float(np.linalg.norm(r[fixed]))) or not np.isfinite(res):
            break
        if iterations >= 25:
            break
        ta = time.perf_counter()
        K = solid.assemble.matrix(field)
        tb = time.perf_counter()
        du = fem.solve.solve(*fem.solve.partition(field, K, free, fixed, r), ext0=ext0)
        tc = time.perf_counter()
        assembly += tb - ta
        solve += tc - tb
        field += du
        iterations += 1
    newton_s = time.perf_counter() - t0
    u = np.asarray(field[0].values)
    node = _nearest_node(model.mesh.points, probe_point(case))
    converged = bool(np.isfinite(res) and res <= NEWTON_TOLERANCE * max(load, float(np.linalg.norm(r[fixed]))))
    return {"version": fem.__version__, "elements": int(mesh.ncells), "free_dofs": int(free.size),
            "setup_s": setup, "newton_s": newton_s, "total_s": setup + newton_s, "assembly_s": assembly,
            "solve_s": solve, "newton": iterations, "converged": converged, "residual": res,
            "per_iteration_ms": 1e3 * newton_s / iterations if iterations else None,
            "peak_mb": _peak_mb(), "probe_node": node, "probe": [float(x) for x in u[node]],
            "max_u": float(np.abs(u).max())}


def _cantilever_material():
    return E_BAR, NU_BAR


def _subprocess(role: str, spec: dict, threads: int | None, timeout: float) -> dict:
    env = dict(os.environ)
    if threads is not None:
        env["TENSORMASS_THREADS"] = str(threads)
    command = [sys.executable, "-m", "tensormass.apps.bench_organ", role, json.dumps(spec)]
    t0 = time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, env=env, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"status": "timeout", "message": f"stopped after {timeout:g} s (--timeout)",
                "process_s": time.perf_counter() - t0}
    for line in done.stdout.splitlines():
        if line.startswith(RESULT_TAG):
            result = json.loads(line[len(RESULT_TAG):])
            if result is not None:
                result["process_s"] = time.perf_counter() - t0
            return result
    tail = "\n".join((done.stdout + done.stderr).strip().splitlines()[-8:])
    killed = done.returncode < 0 or done.returncode == 137
    return {"status": "crashed", "message": (f"killed (signal {-done.returncode}; out of memory?) " if killed else
                                            f"exit code {done.returncode}: ") + tail,
            "process_s": time.perf_counter() - t0}


# -- the benchmark ----------------------------------------------------------------------------
def _memory_note(text: str, method: str) -> str | None:
    """A note when the run's memory estimate exceeds what the machine can give (runtime.scene.resources)."""
    try:
        scene = make_scene(text, method)          # reading the scene checks the estimate already
        resources.check(resources.estimate(scene), None, what="this case")
    except resources.ResourceError as error:
        return str(error)
    return None


def _git_commit() -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(MAKE_ORGAN.parents[1]), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, timeout=10)
        return done.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def select_cases(names, quick: bool) -> list:
    table = QUICK_CASES if quick else CASES
    if not names:
        return list(table)
    known = {c.name: c for c in CASES + QUICK_CASES}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise TensormassError(f"unknown case {', '.join(unknown)}; known: {', '.join(known)}")
    return [known[n] for n in names]


def run_organ_bench(quick=False, cases=None, solvers=None, threads=None, felupe=True, json_path=None,
                    progress=print, timeout=DEFAULT_TIMEOUT, mesh_folder=None) -> dict:
    """Run the organ benchmark; returns the report dict (also written to json_path)."""
    log = progress or (lambda text: None)
    selected = select_cases(cases, quick)
    methods, skipped_solvers = available_solvers(solvers or (QUICK_SOLVERS if quick else None))
    threads = tuple(int(n) for n in (threads or (QUICK_THREADS if quick else DEFAULT_THREADS)))
    if any(n < 1 for n in threads):
        raise TensormassError("--threads: every thread count must be >= 1")
    if not timeout > 0:
        raise TensormassError(f"--timeout must be a positive number of seconds, got {timeout}")
    import numba
    cores = int(numba.config.NUMBA_NUM_THREADS)        # the most threads the runtime's switch accepts
    skipped_threads = {n: f"numba sees {cores} core(s)" for n in threads if n > cores}
    threads = tuple(n for n in threads if n <= cores)
    if any(not mesh_path(c, mesh_folder).is_file() for c in selected if c.body == "organ"):
        require_gmsh()                   # before anything runs: a clear message, not a failure halfway
    report = {"benchmark": "organ", "machine": machine_info(), "commit": _git_commit(),
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
              "settings": {"quick": bool(quick), "solvers": methods, "skipped_solvers": skipped_solvers,
                           "threads": list(threads), "skipped_threads": skipped_threads,
                           "felupe": bool(felupe), "timeout_s": timeout,
                           "thread_switch": "TENSORMASS_THREADS"},
              "cases": []}
    for name, why in skipped_solvers.items():
        log(f"solver {name}: skipped ({why})")
    for n, why in skipped_threads.items():
        log(f"{n} threads: skipped ({why})")
    for case in selected:
        entry = {"case": case.name, "title": case.title, "spec": asdict(case), "runs": [], "felupe": None,
                 "skipped": None}
        report["cases"].append(entry)
        mesh = None
        if case.body == "organ":
            path, seconds = organ_mesh(case, mesh_folder)
            mesh = str(path)
            entry["mesh"] = {"path": mesh, "generate_s": seconds}
        text = scene_text(case, mesh)
        note = _memory_note(text, "auto")
        if note:
            entry["skipped"] = note
            log(f"{case.name}: skipped: {note}")
            continue
        spec = {"case": asdict(case), "mesh": mesh}
        log(f"{case.name}: {case.title}")
        for method in (methods if case.steps < LONG_STEPS else [m for m in methods if m == "auto"]):
            for n in threads:
                r = _subprocess("--worker", dict(spec, method=method), n, timeout)
                r.update(method=method, threads=n)
                entry["runs"].append(r)
                log("  " + _run_line(case, r))
        if felupe and case.kind == "static":
            fe = _subprocess("--felupe-worker", spec, None, timeout)
            entry["felupe"] = fe
            if fe is None:
                log("  FElupe: not installed (pip install tensormass[compare]); comparison skipped")
            else:
                log("  " + _felupe_line(fe))
        _compare(entry)
    _budgets(report["cases"])
    if json_path:
        write_json_atomic(json_path, report)
    return report


def _compare(entry: dict) -> None:
    """Ratios to FElupe (its Newton time / ours, per iteration too) and the probe difference, per run."""
    fe = entry.get("felupe")
    ok = fe is not None and fe.get("newton_s") is not None
    for r in entry["runs"]:
        if not ok or r.get("stepping_s") is None:
            r["felupe_ratio"] = r["felupe_ratio_total"] = r["felupe_ratio_per_iteration"] = r["probe_difference"] = None
            continue
        r["felupe_ratio"] = fe["newton_s"] / max(r["stepping_s"], 1e-12)
        r["felupe_ratio_total"] = fe["total_s"] / max(r["total_s"], 1e-12)
        r["felupe_ratio_per_iteration"] = (fe["per_iteration_ms"] / r["per_iteration_ms"]
                                           if fe.get("per_iteration_ms") and r.get("per_iteration_ms") else None)
        a, b = np.asarray(r["probe"]), np.asarray(fe["probe"])
        r["probe_difference"] = float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300))


def _budgets(entries) -> None:
    """Each budgeted case's runs against its exact case's run with the same solver and threads: the
    speed-up per step and the probe trajectory's error (the largest difference over the largest
    displacement)."""
    by_name = {e["case"]: e for e in entries}
    for entry in entries:
        exact = by_name.get(entry["spec"].get("exact") or "")
        for r in entry["runs"]:
            twin = next((x for x in (exact or {}).get("runs", []) if x["method"] == r["method"]
                         and x["threads"] == r["threads"] and x.get("trajectory")), None)
            r["exact_ratio"] = r["error_vs_exact"] = None
            if twin is None or not r.get("trajectory") or not r.get("later_steps_ms"):
                continue
            a, b = np.asarray(r["trajectory"]), np.asarray(twin["trajectory"])
            r["exact_ratio"] = twin["later_steps_ms"] / r["later_steps_ms"]
            r["error_vs_exact"] = float(np.linalg.norm(a - b, axis=1).max() / max(np.linalg.norm(b, axis=1).max(), 1e-300))


def _budget_line(entry, r) -> str:
    b = r.get("budget") or {}
    return (f"{entry['case']} {r['method']} {r['threads']} thread(s): {_ms(r['later_steps_ms'])} ms per step "
            f"(95th percentile {_ms(r.get('p95_steps_ms'))}): {r['exact_ratio']:.2f}x the speed of {entry['spec']['exact']}; "
            f"trajectory within {100 * r['error_vs_exact']:.3g} % of its (estimated "
            f"{100 * float(b.get('error_estimate') or 0):.2g} %); K assembled {b.get('refreshes')} times")


def _ms(x) -> str:
    return "-" if x is None else f"{x:.1f}"


def _s(x) -> str:
    return "-" if x is None else f"{x:.2f}"


def _run_line(case: Case, r: dict) -> str:
    head = f"{r['method']:8s} {r['threads']} thread{'s' if r['threads'] > 1 else ' '}"
    if r.get("total_s") is None:
        return f"{head}: {r.get('status')}: {r.get('message', '')}"
    per = (f"{_ms(r['later_steps_ms'])} ms per step after the first ({_ms(r['first_step_ms'])} first)"
           if case.kind != "static" else f"{_ms(r['per_iteration_ms'])} ms per Newton iteration")
    return (f"{head}: total {_s(r['total_s'])} s (setup {_s(r['setup_s'])}, assembly {_s(r['assembly_s'])}, "
            f"solve {_s(r['solve_s'])} with {r['used']}), {r['newton']} Newton iterations, {per}, "
            f"peak {r['peak_mb']:.0f} MB, {r['free_dofs']} free dofs")


def _felupe_line(fe: dict) -> str:
    if fe.get("newton_s") is None:
        return f"FElupe: {fe.get('status')}: {fe.get('message', '')}"
    return (f"FElupe {fe['version']}: setup {_s(fe['setup_s'])} s, Newton {_s(fe['newton_s'])} s "
            f"(assembly {_s(fe['assembly_s'])}, solve {_s(fe['solve_s'])}), {fe['newton']} iterations, "
            f"{_ms(fe['per_iteration_ms'])} ms per iteration{'' if fe['converged'] else ' (NOT converged)'}, "
            f"peak {fe['peak_mb']:.0f} MB")


def _table(rows) -> str:
    widths = [max(len(str(row[i])) for row in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(str(c).ljust(w) if i < 2 else str(c).rjust(w)
                               for i, (c, w) in enumerate(zip(row, widths))) for row in rows)


def format_organ_report(report: dict) -> str:
    s = report["settings"]
    out = [format_machine(report["machine"]),
           f"commit {report.get('commit') or '?'}, {report['date']}; solvers {', '.join(s['solvers'])}; "
           f"threads {', '.join(map(str, s['threads']))} (TENSORMASS_THREADS, one process per run)"]
    for name, why in s["skipped_solvers"].items():
        out.append(f"solver {name} skipped: {why}")
    for n, why in s.get("skipped_threads", {}).items():
        out.append(f"{n} threads skipped: {why}")
    rows = [("case", "solver (used)", "thr", "dofs", "total s", "setup s", "Newton", "assembly s", "solve s",
             "ms/it or /step", "peak MB", "FElupe/ours", "per it", "probe diff")]
    notes = []
    for entry in report["cases"]:
        if entry["skipped"]:
            notes.append(f"{entry['case']}: skipped: {entry['skipped']}")
            continue
        dynamic = entry["spec"]["kind"] != "static"
        for r in entry["runs"]:
            label = f"{r['method']} ({r.get('used') or '-'})"
            if r.get("total_s") is None:
                rows.append((entry["case"], label, r["threads"], "-", r.get("status"), "-", "-", "-", "-", "-",
                             "-", "-", "-", "-"))
                notes.append(f"{entry['case']} {r['method']} {r['threads']} thread(s): {r.get('message')}")
                continue
            per = r["later_steps_ms"] if dynamic else r["per_iteration_ms"]
            rows.append((entry["case"], label, r["threads"], r["free_dofs"], _s(r["total_s"]), _s(r["setup_s"]),
                         r["newton"], _s(r["assembly_s"]), _s(r["solve_s"]), _ms(per),
                         "-" if r["peak_mb"] is None else f"{r['peak_mb']:.0f}",
                         "-" if r.get("felupe_ratio") is None else f"{r['felupe_ratio']:.1f}x",
                         "-" if r.get("felupe_ratio_per_iteration") is None else f"{r['felupe_ratio_per_iteration']:.1f}x",
                         "-" if r.get("probe_difference") is None else f"{r['probe_difference']:.1e}"))
        notes += [_budget_line(entry, r) for r in entry["runs"] if r.get("exact_ratio") is not None]
        fe = entry.get("felupe")
        if fe is not None and fe.get("newton_s") is not None:
            rows.append((entry["case"], f"FElupe {fe['version']}", 1, fe["free_dofs"], _s(fe["total_s"]),
                         _s(fe["setup_s"]), fe["newton"], _s(fe["assembly_s"]), _s(fe["solve_s"]),
                         _ms(fe["per_iteration_ms"]), "-" if fe["peak_mb"] is None else f"{fe['peak_mb']:.0f}",
                         "1.0x", "1.0x", "-"))
            best = min((r for r in entry["runs"] if r.get("probe") is not None),
                       key=lambda r: r["stepping_s"], default=None)
            if best is not None:
                notes.append(f"{entry['case']}: probe (node {fe['probe_node']}) tensormass {best['method']} "
                             f"{_vec(best['probe'])} m, FElupe {_vec(fe['probe'])} m "
                             f"(relative difference {best['probe_difference']:.1e})")
        elif fe is not None:
            notes.append(f"{entry['case']}: FElupe {fe.get('status')}: {fe.get('message')}")
        elif entry["spec"]["kind"] == "static" and s["felupe"]:
            notes.append(f"{entry['case']}: FElupe not installed (pip install tensormass[compare])")
    out += ["", _table(rows),
            "total: wall time of the run, setup included; ms/it: (total - setup) / Newton iterations (static), "
            "ms per implicit step after the first (dynamic); FElupe/ours: FElupe's Newton time over ours "
            "(setup excluded on both sides), per it: the same per Newton iteration; peak MB: the process's peak resident memory."]
    used = [r.get("threads_in_use") for e in report["cases"] for r in e["runs"] if r.get("threads_in_use")]
    if used and all(t.get("runtime") is None for t in used):
        notes.append("this runtime has no thread switch (runtime.base.parallel): TENSORMASS_THREADS was ignored, "
                     f"numba ran with {sorted({t['numba'] for t in used})} thread(s) in every run")
    if notes:
        out += [""] + notes
    return "\n".join(out)


def _vec(v) -> str:
    return "[" + ", ".join(f"{x:.6e}" for x in v) + "]"


# -- command line -----------------------------------------------------------------------------
def cmd_organ(args) -> int:
    report = run_organ_bench(quick=args.quick, cases=args.cases, solvers=args.solvers, threads=args.threads,
                             felupe=not args.no_felupe, json_path=args.json, timeout=args.timeout)
    print(format_organ_report(report))
    if args.json:
        print(f"wrote {args.json}")
    return 0


def add_organ_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("organ", help="gmsh organ meshes (tetra10 static, tetra implicit Euler) and "
                                    "the hexahedral cantilever with every linear solver, 1 and 2 threads, "
                                    "against FElupe")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="small meshes, the auto solver, one thread (CI smoke test)")
    p.add_argument("--cases", nargs="+", metavar="NAME",
                   help=f"cases to run (default: {' '.join(c.name for c in CASES)}; quick: "
                        f"{' '.join(c.name for c in QUICK_CASES)})")
    p.add_argument("--solvers", nargs="+", metavar="NAME", help="linear solvers (default: every one of "
                   "runtime.solve.solvers.METHODS that is available)")
    p.add_argument("--threads", nargs="+", type=int, metavar="N", help="thread counts (default: 1 2)")
    p.add_argument("--no-felupe", action="store_true", help="do not run FElupe even when it is installed")
    p.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT, metavar="S",
                   help=f"seconds allowed to each run's process (default {DEFAULT_TIMEOUT:g})")
    p.set_defaults(run=cmd_organ)


def _worker_main(argv) -> int:
    role, spec = argv[0], json.loads(argv[1])
    try:
        result = run_tensormass(spec) if role == "--worker" else run_felupe(spec)
    except TensormassError as error:
        result = {"status": "failed", "message": str(error).splitlines()[0]}
    print(RESULT_TAG + json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] in ("--worker", "--felupe-worker"):
        sys.exit(_worker_main(sys.argv[1:]))
    import argparse
    parser = argparse.ArgumentParser(prog="python -m tensormass.apps.bench_organ")
    add_organ_command(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["organ"] + sys.argv[1:])
    sys.exit(args.run(args))
