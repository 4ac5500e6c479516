"""`tensormass run` and `tensormass demo`: simulate a scene file, write VTU frames and a summary.

    tensormass run beam.toml [--out DIR] [--json SUMMARY.json] [--overwrite] [--quiet]
    tensormass demo [--out DIR] [--json SUMMARY.json] [--overwrite]

add_commands(subparsers) adds both to an argparse parser; each sets
``run=callable(args) -> int`` returning the exit code: 0 for a result we stand
behind (warnings, if any, printed and in the summary), 3 when the run stopped
or ended outside the trusted region (RunStopped), 130 when interrupted. Bad
input raises TensormassError (exit code 2 in apps.cli.main); nothing is
written before the scene, its mesh, the --json path and the output folder have
been checked (output.check_summary_path, output.Writer.prepare), and a run that
fails before its first frame leaves no output folder behind. A run that stops
still writes its summary JSON, with "status" and "message" saying why.
"""
from __future__ import annotations

import math
import sys
import time
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from ..backends.c.loader import default_backend
from ..runtime.base.errors import RunInterrupted, RunStopped, TensormassError

# The runtime is imported inside the command functions: `tensormass --help` and `tensormass run --help`
# import this module with the CLI in 0.19 s and skip the scene (runtime.scene: parser, meshes, laws)
# 0.15 s, base.parallel (numba) 0.22 s and the simulation stack (numba, scipy.sparse, pyamg) 0.86 s
# (python -X importtime, 2 shared cores).
if TYPE_CHECKING:
    from ..runtime.scene.scene import Scene

__all__ = ["add_commands", "cmd_run", "cmd_demo", "run_scene", "ProgressBar", "euler_bernoulli_tip",
           "DEMO_OUT", "print_advice", "print_stable_step"]

DEMO_OUT = "tensormass-demo"


# ============================================================================== progress


class ProgressBar:
    """A one-line text progress bar (redrawn with \\r on a terminal, a few lines otherwise)."""

    def __init__(self, stream=None, width: int = 30, label: str = "step"):
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.label = label
        self.t0 = time.perf_counter()
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.open_line = False
        self.last_quarter = -1

    def __call__(self, step, n_steps) -> None:
        n = max(int(n_steps), 1)
        done = min(max(int(step), 0), n)
        frac = done / n
        elapsed = time.perf_counter() - self.t0
        bar = "#" * int(round(frac * self.width))
        line = f"{self.label} {done}/{n} [{bar:<{self.width}}] {100 * frac:5.1f}%  {elapsed:7.2f} s"
        if self.tty:
            self.stream.write("\r" + line)
            self.open_line = done < n
            if done >= n:
                self.stream.write("\n")
        else:
            quarter = int(frac * 4)
            if quarter > self.last_quarter:
                self.last_quarter = quarter
                self.stream.write(line + "\n")
        self.stream.flush()

    def finish(self) -> None:
        """End an unfinished line (after an error)."""
        if self.open_line:
            self.stream.write("\n")
            self.stream.flush()
            self.open_line = False


# ============================================================================== running


def _simulation_class():
    """The runtime's Simulation. Deferred import: the simulation stack (assembly, solvers,
    integrators: 0.86 s) loads only once a checked scene runs, not at every CLI start."""
    try:
        from ..runtime.run.simulation import Simulation
    except ImportError as exc:
        raise TensormassError(f"the simulation runtime is not available ({exc})") from None
    return Simulation


# Failures of a run that are the input's fault or a diverging solve, not bugs: exit code 2.
_RUN_FAILURES = (TensormassError, ValueError, ArithmeticError, RuntimeError)


def run_scene(scene: Scene, out=None, json_path=None, quiet: bool = False, stream=None,
              overwrite: bool = False, dir_from: str | None = None) -> dict:
    """Run a validated scene; returns the summary dict (Summary.to_dict() plus format, status,
    message, exit_code, scene and output), written where runtime.run.run_files says (the output
    folder's summary.json, and json_path when given): the same files as Simulation(scene).run().

    out overrides scene.output.dir; frames go there every scene.output.every steps. dir_from: how
    the folder was chosen, said in the summary (default: given on the command line when out is).
    Everything that can be checked is checked before the first step (the --json path,
    the output folder: see output.Writer.prepare). A run that stops (RunStopped: diverged,
    failed, invalid, interrupted) still writes its summary; data["exit_code"] says how it
    ended (0, 3 or 130). Bad input and unwritable outputs raise TensormassError (exit 2).
    """
    from ..runtime.run.run_files import RunFiles
    stream = stream if stream is not None else sys.stdout
    files = RunFiles(scene, out=out, json_path=json_path, overwrite=overwrite,
                     dir_from=dir_from or ("given on the command line, relative to the working directory"
                                           if out is not None else None))
    files.prepare()
    if not quiet:
        print(backend_note(scene.solver.backend), file=stream)
    Simulation = _simulation_class()
    progress = None if quiet else ProgressBar(label="step" if scene.solver.kind != "static" else "load step")
    advise = None if quiet else (lambda sim: print_advice(getattr(sim, "advice", ()), stream))
    checks = [files.check_outputs] if files.picture else []
    if not quiet and scene.solver.kind == "explicit":      # the stable step, printed before the first step
        checks.append(lambda sim: print_stable_step(sim, stream))
    data, stopped = _simulate(Simulation, scene, files, progress, advise, checks)
    if not quiet:
        print_summary(data, stream=stream, json_path=files.json_path)
    if stopped is not None:
        print(f"tensormass: run {data['status']}: {data['message']}", file=sys.stderr)
    return data


def backend_note(backend: str) -> str:
    """Which kernel backend runs and why: what a first run spends compiling depends on it."""
    if backend == "c":
        return ("kernels: C backend (compiled by the C compiler, about 1 s per kernel the first time, then "
                "taken from the user cache; [solver] backend = \"numba\" for numba)")
    if backend == "cuda":
        return ("kernels: cuda backend (compiled by NVRTC, about 1 s per kernel the first time, then taken from "
                "the user cache; arrays cross to the GPU and back at every call)")
    why = ("no C compiler was found; with gcc, the default C backend compiles a kernel in about 1 s"
           if default_backend() == "numba" else "[solver] backend = \"numba\"; the C backend compiles in about 1 s")
    return f"kernels: numba backend (6 to 40 s per kernel the first time, then cached; {why})"


def print_advice(lines, stream=None) -> list:
    """Setup-time advice lines (runtime.scene.advice, as Simulation.advice holds them), one "advice:" line
    each, before the run; returns the lines."""
    for line in lines:
        print(f"advice: {line}", file=stream if stream is not None else sys.stdout)
    return list(lines)


def print_stable_step(sim, stream=None) -> str | None:
    """The explicit step against the stable step estimated at rest (Simulation.stable_dt), one line
    before the first step; returns it (None when there is no estimate)."""
    crit, dt = getattr(sim, "stable_dt", None), getattr(getattr(sim, "integrator", None), "dt", None)
    if crit is None or dt is None or not math.isfinite(crit):
        return None
    how = "2 / omega_max" + (", penalty springs counted" if getattr(sim.model, "contact", None) is not None
                             and math.isfinite(sim.model.contact.stable_time_step()) else "")
    if dt > crit:
        line = (f"explicit: dt = {_fmt_seconds(dt)} is above the stable step estimated at rest, "
                f"{_fmt_seconds(crit)} ({how}): expect the run to diverge or an element to invert; "
                f"use dt <= {crit:.3g} s or implicit_euler / backward_euler")
    else:
        line = f"explicit: dt = {_fmt_seconds(dt)}, stable step estimated at rest {_fmt_seconds(crit)} ({how})"
    print(f"advice: {line}", file=stream if stream is not None else sys.stdout)
    return line


def _simulate(Simulation, scene, files, progress, advise=None, checks=()):
    """(summary dict, None) for a run we stand behind, (summary dict, RunStopped) otherwise.

    The command line hands the Simulation the frames' writer and writes the summary itself with
    the same RunFiles as Simulation(scene).run() uses. Other failures propagate (exit 2), after
    the files dropped a folder made for nothing."""
    sim = None
    try:
        # checks(sim) once the model is built, before step 1: the picture asked for can be drawn
        sim = Simulation(scene, progress=progress, writer=files.writer, **({"checks": list(checks)} if checks else {}))
        if advise is not None:               # the advice the Simulation computed, before its first step
            advise(sim)
        summary, stopped = sim.run(), None
    except RunStopped as exc:
        summary, stopped = exc.summary, exc
    except KeyboardInterrupt:
        # Simulation turns Ctrl-C during the steps into RunInterrupted; this one came before
        # them (setup): the summary says so all the same.
        stopped = RunInterrupted(f"interrupted (Ctrl-C) after step {_steps_done(sim)}",
                                 getattr(sim, "summary", None))
        summary = stopped.summary
    except BaseException as exc:
        files.abandon()
        if isinstance(exc, _RUN_FAILURES) and not isinstance(exc, TensormassError):
            raise TensormassError(f"simulation failed: {type(exc).__name__}: {exc}") from exc
        raise
    finally:
        if progress is not None:
            progress.finish()
    return files.finish(summary, stopped, sim=sim), stopped


def _steps_done(sim) -> int:
    """Steps the run finished (the runtime's count; 0 before the first)."""
    done = getattr(getattr(sim, "summary", None), "steps_done", None)
    return int(done if done is not None else getattr(sim, "_step", 0) or 0)


def _fmt_seconds(value) -> str:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return "?"
    return f"{v * 1e3:.1f} ms" if v < 1.0 else f"{v:.2f} s"


def _fmt_vec(v) -> str:
    try:
        return "[" + ", ".join(f"{float(x):.4g}" for x in v) + "]"
    except (TypeError, ValueError):
        return str(v)


def _fmt_kernels(kernels) -> str:
    def one(k):
        if isinstance(k, dict) and {"element", "law", "quadrature"} <= set(k):
            extra = ", ".join(str(x) for x in (k.get("backend"), f"{k['elements']} cells" if "elements" in k else None) if x)
            return f"{k['element']}/{k['law']}/{k['quadrature']}" + (f" ({extra})" if extra else "")
        return str(k)
    if isinstance(kernels, dict):
        return ", ".join(f"{k} ({v})" if not isinstance(v, (dict, list)) else str(k) for k, v in kernels.items())
    if isinstance(kernels, (list, tuple)):
        return ", ".join(one(k) for k in kernels)
    return str(kernels)


def _topology_rows(events) -> list:
    """What the [[cut]] / [[remove]] events changed, when, and how long each took to apply."""
    rows = []
    for e in events or []:
        if e.get("kind") == "cut":
            what = (f"{e.get('faces')} face(s) opened, +{e.get('nodes_added')} node(s), "
                    f"{e.get('cells_changed')} cell(s) renumbered")
        elif e.get("kind") == "refine":
            what = (f"{e.get('cells_refined')} hexahedra split 1:8, +{e.get('nodes_added')} node(s), "
                    f"{e.get('hanging_nodes')} hanging (constrained)")
        else:
            what = f"{e.get('cells_removed')} cell(s) removed, {e.get('nodes_orphaned')} node(s) left without a cell"
        seconds = (e.get("seconds") or {}).get("total")
        rows.append((e.get("kind"), f"{e.get('name')} after step {e.get('step')} (t = {e.get('time', 0):.4g}): "
                                    f"{what}; applied in {_fmt_seconds(seconds)}"))
    return rows


def _adapt_rows(adapt) -> list:
    """What the [[adapt]] rules did: counts, the laws at the end, and when things changed."""
    if not adapt:
        return []
    laws = ", ".join(f"{n} {law}" for law, n in (adapt.get("elements_per_law") or {}).items())
    rows = [("adaptation", f"{adapt.get('switched', 0)} switch(es), {adapt.get('switched_back', 0)} back, "
                           f"{adapt.get('split', 0)} cell(s) split; at the end: {laws or '?'} "
                           f"({_fmt_seconds(adapt.get('time'))} evaluating rules)")]
    events = adapt.get("events") or []
    shown = [f"step {e['step']}: {e['count']} {e['action']}" + (f" -> {e['law']}" if e.get("law") else "")
             for e in events[:6]]
    if events:
        rows.append(("adapt events", "; ".join(shown) + (f"; ... ({len(events)} in all)" if len(events) > 6 else "")))
    return rows


def _incompressible_rows(info) -> list:
    """The mixed formulation's row (runtime.physics.saddle.Pressures.summary), or none."""
    if not info:
        return []
    change, error = info.get("volume_change"), info.get("group_volume_error")
    kept = ("volume not evaluated (the last state is not finite)" if change is None else
            f"volume change {change:.2g} of the body, largest per pressure group {error:.2g}")
    return [("incompressible", f"{', '.join(info.get('pairs', []))}: {info.get('unknowns')} pressure unknowns, "
                               f"p from {info.get('pressure_min', 0):.4g} to {info.get('pressure_max', 0):.4g} Pa; {kept}")]


def _status_rows(data: dict) -> list:
    """How the run ended, always shown: a result we stand behind, with warnings, or why not."""
    status = data.get("status") or "ok"
    n_warn = len(data.get("warnings") or [])
    if status in ("ok", "warnings"):
        text = "ok" if not n_warn else f"ok, with {n_warn} warning(s) (below): check the flagged frames"
    else:
        done = data.get("steps_done")
        where = f" after {done} of {data.get('steps', '?')} step(s)" if done is not None else ""
        text = f"{status}{where}: {data.get('message') or 'no message'} (not a result to trust)"
    return [("status", text)]


def _health_rows(health) -> list:
    """What the health monitor measured: the numbers behind the status."""
    if not health or not health.get("monitor"):
        return [("health", "not checked (solver.health_monitor = false)")] if health else []

    def num(key, fmt):
        value = health.get(key)
        return format(value, fmt) if isinstance(value, (int, float)) else "n/a"
    return [("health", f"min det F {num('min_det_F', '.4g')} (final {num('min_det_F_final', '.4g')}), "
                       f"max displacement {num('max_relative_displacement', '.3g')} body sizes, "
                       f"energy balance growth {num('max_energy_growth', '.3g')} x {num('energy_scale', '.3g')} J; "
                       f"{_fmt_seconds(health.get('time'))} checking")]


def _contact_rows(contact, per_step) -> list:
    """What the contact did (runtime.contact): pairs, closest approach, the last force on each obstacle."""
    if not contact:
        return []

    def num(value, fmt):
        return format(value, fmt) if isinstance(value, (int, float)) else "n/a"
    if contact["method"] == "ipc":
        how = (f"ipc, up to {contact.get('max_pairs', 0)} pair(s), closest {num(contact.get('min_distance'), '.3g')} m "
               f"(dhat {num(contact.get('dhat'), '.3g')} m), smallest CCD step {num(contact.get('min_ccd_fraction'), '.3g')}")
    else:
        how = (f"penalty, up to {contact.get('max_pairs', 0)} vertex(es) inside, deepest "
               f"{num(contact.get('max_penetration'), '.3g')} m")
    rows = [("contact", how)]
    steps = per_step.get("step") or []
    for name, parts in (per_step.get("obstacles") or {}).items():
        forces = [(k, f) for k, f in zip(steps, parts.get("force", [])) if f is not None]
        if forces:
            k, peak = max(forces, key=lambda kf: sum(x * x for x in kf[1]))
            text = lambda f: "[" + ", ".join(format(x, ".4g") for x in f) + "] N"   # noqa: E731
            rows.append((f"obstacle {name}", f"F = {text(forces[-1][1])} at the end; largest {text(peak)} "
                                             f"at step {k}"))
    return rows


# At most this many warnings are listed on the terminal (all of them are in the summary JSON).
_WARNINGS_SHOWN = 5


def _warning_rows(warnings, json_path) -> list:
    """One row per health warning: the step, the time, the kind and the message."""
    rows = []
    for w in (warnings or [])[:_WARNINGS_SHOWN]:
        if isinstance(w, dict):
            t = w.get("time")
            when = f"step {w.get('step', '?')}" + (f" (t = {t:.4g} s)" if isinstance(t, (int, float)) else "")
            rows.append(("warning", f"{when}, {w.get('kind', '?')}: {w.get('message', '')}"))
        else:
            rows.append(("warning", str(w)))
    extra = len(warnings or []) - _WARNINGS_SHOWN
    if extra > 0:
        rows.append(("warning", f"... and {extra} more" + (f" in {json_path}" if json_path else " (see --json)")))
    return rows


def print_summary(data: dict, stream=None, json_path=None) -> None:
    """The end-of-run report (the keys of Summary.to_dict(), tolerant of missing ones)."""
    out = stream if stream is not None else sys.stdout
    t = data.get("time") or {}
    steps = int(data.get("steps") or 0)
    sc = data.get("scene") or {}
    cells = ", ".join(f"{n} {k}" for k, n in (sc.get("cells") or {}).items())
    rows = [("scene", f"{sc.get('name', '?')} ({sc.get('solver', '?')}, {steps} step(s), "
                      f"{sc.get('nodes', '?')} nodes, {cells or '?'} cells)")]
    rows += _status_rows(data)
    rows.append(("kernels", _fmt_kernels(data.get("kernels", "?"))))
    setup, first, total = t.get("setup"), t.get("first_step"), t.get("total")
    read = t.get("mesh_read")
    if isinstance(read, (int, float)) and isinstance(setup, (int, float)):
        rows.append(("before 1st step", f"{_fmt_seconds(setup + read)} (reading the mesh {_fmt_seconds(read)}; checks, "
                                        "model, kernel loading/compilation, constants)"))
    else:
        rows.append(("before 1st step", f"{_fmt_seconds(setup)} (mesh, kernel loading/compilation, constants)"))
    rows.append(("first step", _fmt_seconds(first)))
    try:
        per_step = (float(total) - float(setup)) / steps if steps else float("nan")
        after = (float(total) - float(setup) - float(first)) / (steps - 1) if steps > 1 else float("nan")
        line = f"{_fmt_seconds(per_step)} mean"
        if math.isfinite(after):
            line += f", {_fmt_seconds(after)} after the first"
        walls = [float(w) for w in ((data.get("per_step") or {}).get("wall") or [])[1:]]
        if len(walls) >= 20:        # a step much dearer than the mean (a refactorisation) shows here
            line += f", 95th percentile {_fmt_seconds(sorted(walls)[int(0.95 * (len(walls) - 1))])}"
        rows.append(("time per step", line))
    except (TypeError, ValueError):
        pass
    rows.append(("assembly", f"{_fmt_seconds(t.get('assembly'))}; linear solve {_fmt_seconds(t.get('linear_solve'))}; "
                             f"total {_fmt_seconds(total)}"))
    it = data.get("iterations") or {}
    rows.append(("iterations", f"Newton {it.get('newton', '?')}, linear (CG / solves) {it.get('linear', '?')}"))
    if it.get("linear_solvers"):
        rows.append(("linear solver", ", ".join(f"{name} x{n}" for name, n in it["linear_solvers"].items())))
    budget = it.get("budget")
    if isinstance(budget, dict):
        tol = budget.get("stiffness_tolerance")
        rows.append(("budgeted step", f"K kept up to {budget.get('stiffness_every')} steps"
                                      + (f" (or until a step's estimated error passes {tol:g})" if tol else "")
                                      + f": {budget.get('refreshes')} assemblies; trajectory error against exact "
                                        f"steps estimated at {100 * float(budget.get('error_estimate') or 0):.2g} % "
                                        "of the largest displacement"))
    if isinstance(data.get("stable_dt"), (int, float)) and math.isfinite(data["stable_dt"]):
        rows.append(("stable step", f"{_fmt_seconds(data['stable_dt'])} estimated at rest (explicit: 2 / omega_max)"))
    rows += _incompressible_rows(data.get("incompressible"))
    viscous = data.get("viscous")
    if isinstance(viscous, dict) and isinstance(viscous.get("dissipated"), (int, float)):
        rows.append(("viscous", f"{viscous['dissipated']:.6g} J dissipated by the Prony branches since the start"))
    energy = data.get("energy")
    rows.append(("final energy", f"{energy:.6g} J (elastic)" if isinstance(energy, (int, float)) else "n/a"))
    for name, u in (data.get("probes") or {}).items():
        try:
            norm = math.sqrt(sum(float(x) ** 2 for x in u))
            rows.append((f"probe {name}", f"u = {_fmt_vec(u)} m, |u| = {norm:.4g} m"))
        except (TypeError, ValueError):
            rows.append((f"probe {name}", str(u)))
    for name, r in (data.get("reactions") or {}).items():
        try:
            rows.append((f"reaction {name}", f"F = {_fmt_vec(r['force'])} N, M = {_fmt_vec(r['moment'])} N m "
                                             f"about {_fmt_vec(r['point'])}"))
        except (KeyError, TypeError):
            rows.append((f"reaction {name}", str(r)))
    est = data.get("estimate")
    if isinstance(est, dict) and est.get("text"):
        rows.append(("estimate", f"{est['text']} (before the run)"))
    rows += _health_rows(data.get("health"))
    rows += _contact_rows(data.get("contact"), data.get("per_step") or {})
    rows += _warning_rows(data.get("warnings"), json_path)
    rows += _adapt_rows(data.get("adapt"))
    rows += _topology_rows(data.get("topology"))
    o = data.get("output")
    if o:
        where = o.get("pvd") or f"{o['dir']} (no frame written)"
        rows.append(("output", f"{where} ({o.get('frames', 0)} frame(s), every {o.get('every')} step(s)"
                               + (f"; {o['dir_from']})" if o.get("dir_from") else ")")))
    else:
        rows.append(("output", "none (set [output] dir or --out)"))
    written = [str(p) for p in ((o or {}).get("summary"), json_path) if p is not None]
    if written:
        rows.append(("summary", ", ".join(dict.fromkeys(written)) + " (history: the same name with .csv)"))
    for key in ("picture", "plot"):
        if (o or {}).get(key):
            rows.append((key, str(o[key])))
    if (o or {}).get("picture_skipped"):
        rows.append(("picture", f"not drawn: {o['picture_skipped']}"))
    for key in ("picture", "plot"):          # optional files that failed after the run: exit code 0
        if (o or {}).get(f"{key}_error"):
            rows.append((key, f"not written (warning): {o[f'{key}_error']}"))
    width = max(len(r[0]) for r in rows)
    for key, value in rows:
        print(f"{key:<{width}}  {value}", file=out)


# ============================================================================== commands


def cmd_run(args) -> int:
    from ..runtime.scene.parser import set_picture
    from ..runtime.scene.scene import Scene
    scene = Scene.from_toml(args.scene, max_memory=getattr(args, "max_memory", None))
    if getattr(args, "threads", None) is not None:       # --threads overrides [solver] threads
        from ..runtime.base.parallel import parse_threads
        scene.solver.threads = parse_threads(args.threads, "--threads")
    if getattr(args, "picture", None) is not None:      # --picture [FIELD] / --plot override [output]
        set_picture(scene.output, True if args.picture == "" else args.picture, "--picture")
    if getattr(args, "plot", False):
        scene.output.plot = True
    if getattr(args, "view", None) is not None:         # --view overrides [output] view
        from ..runtime.scene.parser import view_text
        scene.output.view = view_text(args.view)
    data = run_scene(scene, out=args.out, json_path=args.json, quiet=args.quiet,
                     overwrite=getattr(args, "overwrite", False))
    return data["exit_code"]


def demo_text() -> str:
    """The embedded demo scene (apps/demo.toml, package data)."""
    return resources.files("tensormass.apps").joinpath("demo.toml").read_text(encoding="utf-8")


def euler_bernoulli_tip(scene: Scene) -> tuple:
    """(Euler-Bernoulli, Timoshenko) tip deflection of a generated 3D bar clamped at x = 0 under
    gravity along -z: rho g A L^4 / (8 E I), I = b h^3 / 12, plus the shear term rho g L^2 / (2 k G)."""
    L, b, h = scene.mesh.size
    mat = scene.materials[0]
    g = -scene.loads.gravity[2]
    E, nu = mat.E, mat.nu
    A, I = b * h, b * h ** 3 / 12.0
    eb = mat.density * g * A * L ** 4 / (8.0 * E * I)
    G = E / (2.0 * (1.0 + nu))
    kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu)     # rectangular section (Cowper)
    return eb, eb + mat.density * g * L ** 2 / (2.0 * kappa * G)


def cmd_demo(args) -> int:
    from ..runtime.scene.scene import Scene
    scene = Scene.from_string(demo_text(), name="demo", source="tensormass demo (apps/demo.toml)",
                              max_memory=getattr(args, "max_memory", None))
    out = Path(args.out or DEMO_OUT)
    size = " x ".join(f"{s:g}" for s in scene.mesh.size)
    mesh = scene.load_mesh()
    types = ", ".join(f"{sum(len(b) for b in mesh.blocks if b.type == t)} {t}" for t in mesh.cell_types())
    laws = "; ".join(f"{m.region}: {m.law}/{m.quadrature}" for m in scene.materials)
    m0 = scene.materials[0]
    print(f"tensormass demo: a {size} m mixed bar ({types}; {mesh.n_points} nodes), rho = {m0.density:g} kg/m^3, "
          f"E = {m0.E:g} Pa, nu = {m0.nu:g}, clamped at x = 0, under gravity; {scene.solver.kind} solve "
          f"({scene.solver.steps} step(s)); laws {laws}")
    given = ("given on the command line (--out), relative to the working directory" if args.out else
             f"the demo's default ./{DEMO_OUT}, relative to the working directory (--out chooses another)")
    data = run_scene(scene, out=out, json_path=args.json, quiet=getattr(args, "quiet", False),
                     overwrite=getattr(args, "overwrite", False), dir_from=given)
    tip = (data.get("probes") or {}).get("tip")
    if tip is not None and data["exit_code"] == 0:      # no comparison for a result we do not trust
        eb, timo = euler_bernoulli_tip(scene)
        w = -float(tip[2])
        print(f"tip deflection: {w:.4g} m; Euler-Bernoulli {eb:.4g} m (ratio {w / eb:.3f}), with Timoshenko's "
              f"shear term {timo:.4g} m (ratio {w / timo:.3f}). Linear elements on this coarse mesh are too "
              "stiff in bending; refine mesh.cells or use tetra10 to converge.")
    o = data.get("output") or {}
    print(f"output: {o.get('pvd') or out} -- open it in ParaView (Warp By Vector on 'displacement')")
    return data["exit_code"]


_OVERWRITE_HELP = ("replace files in the output folder named like this run's outputs (frame.pvd, frame_*.vtu) "
                   "that an earlier tensormass run did not write (refused without it)")
_JSON_HELP = ("write the run summary as JSON to this file (also when the run stops; an existing file "
              "is replaced only when it is an earlier summary)")


# --max-memory (runtime.scene.resources): the run is refused before allocating when its estimate is above it.
_MAX_MEMORY_HELP = ("refuse the run when its estimated peak memory is above SIZE (8G, 500M or bytes; "
                    "default: $TENSORMASS_MAX_MEMORY, else 80%% of the available memory)")


def add_commands(subparsers) -> None:
    """Add `run` and `demo` to an argparse subparsers object."""
    p = subparsers.add_parser("run", help="simulate a scene file (TOML), write VTU frames and a summary")
    p.add_argument("scene", help="scene file (.toml)")
    p.add_argument("--out", help="output folder for the VTU frames and the .pvd (overrides [output] dir)")
    p.add_argument("--json", metavar="SUMMARY", help=_JSON_HELP)
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary on the terminal")
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE_HELP)
    p.add_argument("--max-memory", metavar="SIZE", help=_MAX_MEMORY_HELP)
    p.add_argument("--picture", nargs="?", const="", metavar="FIELD",
                   help="at the end, a PNG of the deformed body coloured by FIELD (default von_mises) in the output folder")
    p.add_argument("--plot", action="store_true", help="the per-step history curves as summary.png in the output folder")
    p.add_argument("--view", metavar="VIEW", help="the picture's camera: top, bottom, front, back, left, right, or "
                   "AZIMUTH,ELEVATION in degrees (overrides [output] view; default -60,20)")
    p.add_argument("--threads", metavar="N", help="assembly threads (overrides [solver] threads and "
                   "$TENSORMASS_THREADS; default: every core); results do not depend on it")
    p.set_defaults(run=cmd_run)

    p = subparsers.add_parser("demo", help="run the built-in demo (a mixed bar bending under its own weight)")
    p.add_argument("--out", help=f"output folder (default: ./{DEMO_OUT})")
    p.add_argument("--json", metavar="SUMMARY", help=_JSON_HELP)
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE_HELP)
    p.add_argument("--max-memory", metavar="SIZE", help=_MAX_MEMORY_HELP)
    p.set_defaults(run=cmd_demo)
