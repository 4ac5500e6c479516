"""Run a scene (or a ready Model) from setup to summary.

    sim = Simulation(scene, progress=lambda k, n: ..., writer=vtu_writer)
    summary = sim.run()                  # Summary; summary.to_dict() for JSON
    sim.displacement                     # (n_points, dim) at the end

Setup (model, kernel loading and compilation, sparsity pattern, colouring,
stable step estimate) is timed apart from stepping, so reports can tell
one-off costs from per-step costs.
"""
from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ..base import parallel as _parallel
from ..change.adapt import MAX_STATIC_PASSES, Adapter
from ..base import integrator_kinds
from ..base.errors import (EXIT_INTERRUPTED, EXIT_OK, EXIT_UNTRUSTED, RunInterrupted, RunStopped,
    TensormassError)
from ..scene import advice as _advice
from ..physics import fields as _fields
from ..kernels import hourglass as _hourglass
from ..physics.health import HealthMonitor
from .history import History, units as _units
from ..physics.newton import Context
from ..physics.device_euler import make_integrator
from ..physics.integrators import Explicit, stable_time_step
from ..model.model import Model
from ..physics import reactions as _reactions
from ..assembly.assembly import Assembler
from ..mesh.refine import interpolate_nodal
from ..change.events import TopologyEvents
from ..physics.volume_constraint import VolumeConstraintError
from .run_files import RunFiles, summary_mapping

__all__ = ["Simulation", "Summary"]


# Per-step history entries kept in memory: past this, every other entry is dropped and the
# stride doubles, so a run of any length keeps between HISTORY_MAX/2 and HISTORY_MAX rows.
HISTORY_MAX = 4096
# Explicit steps are cheap (one forces call): their elastic energy, which a force kernel does not
# give, is evaluated every this many steps, at every frame and the last step, and for every step the
# history keeps (runtime.run.history: all of them until HISTORY_MAX rows, then every stride-th).
EXPLICIT_ENERGY_EVERY = 10
# The budgeted implicit Euler step (solver.stiffness_every): a warning once the trajectory error keeping K
# cost, as StepBudget estimates it, passes this share of the largest displacement (docs/guide/interactive.md)
STEP_ERROR_WARNING = 0.02
# Exit code of each final status (runtime.base.errors: 0 trusted, 3 not trusted, 130 interrupted).
_EXIT = {"ok": EXIT_OK, "warnings": EXIT_OK, "invalid": EXIT_UNTRUSTED, "diverged": EXIT_UNTRUSTED,
         "failed": EXIT_UNTRUSTED, "interrupted": EXIT_INTERRUPTED}


@dataclass
class Summary:
    """What a run did and what it cost. Attributes for the runtime's own fields (summary.probes);
    as a mapping it reads like the summary.json of the run (summary["output"], summary["scene"],
    summary["format"], dict(summary), the same keys and values as the file: runtime.run.run_files),
    also for a run that writes no file. to_dict(): the runtime's fields alone, JSON-ready."""
    name: str
    solver: str
    steps: int
    n_dofs: int
    n_free_dofs: int
    n_elements: int
    kernels: list
    time: dict
    iterations: dict
    probes: dict
    energy: float | None                  # final elastic energy (None: not evaluated at the last step)
    kinetic_energy: float | None          # final, dynamic solvers only
    stable_dt: float | None               # explicit only: estimated critical step at rest
    per_step: dict = field(default_factory=dict)
    adapt: dict | None = None             # [[adapt]] rules: switches, splits and their events
    topology: list | None = None          # [[cut]] / [[remove]] events applied: step, counts, seconds
    status: str = "ok"                    # ok | warnings | invalid | diverged | failed | interrupted
    message: str | None = None            # why the run is not "ok"/"warnings"
    warnings: list = field(default_factory=list)   # [{"step", "time", "kind", "message"}]
    health: dict = field(default_factory=dict)     # runtime.physics.health.HealthMonitor.summary()
    steps_done: int = 0                   # steps finished (== steps unless the run stopped)
    estimate: dict | None = None          # runtime.scene.resources: memory and time estimated before allocating
    probe_points: dict = field(default_factory=dict)   # how each probe reads the body (Model.probe_info)
    reactions: dict = field(default_factory=dict)      # final reaction force/moment/point per [[fixed]] entry
    fields: dict | None = None            # output fields of the frames: names, units, law_ids (runtime.physics.fields)
    units: dict = field(default_factory=dict)      # unit of every per_step key (runtime.run.history.units)
    advice: list = field(default_factory=list)     # setup-time advice (runtime.scene.advice); never changes status
    contact: dict | None = None           # runtime.contact: method, settings, surface and the run's extremes
    incompressible: dict | None = None    # formulation "mixed": the pressures' range and the volume kept (runtime.physics.saddle)
    viscous: dict | None = None           # Prony branches: the energy they dissipated (runtime.physics.viscous)

    @property
    def exit_code(self) -> int:
        return _EXIT[self.status]

    def to_dict(self) -> dict:
        out = asdict(self)
        out["exit_code"] = self.exit_code
        return out

    def attach(self, data: dict) -> None:
        """The summary.json mapping of this run (runtime.run.run_files.summary_mapping), read by [] and keys()."""
        self._mapping = data

    def _data(self) -> dict:
        data = getattr(self, "_mapping", None)
        return data if data is not None else self.to_dict()

    def __getitem__(self, key):
        data = self._data()
        if key not in data:
            raise KeyError(f"{key!r}: not a key of the run summary (its keys: {', '.join(data)})")
        return data[key]

    def __contains__(self, key) -> bool:
        return key in self._data()

    def __iter__(self):
        return iter(self._data())

    def __len__(self) -> int:
        return len(self._data())

    def keys(self):
        return self._data().keys()

    def items(self):
        return self._data().items()

    def values(self):
        return self._data().values()

    def get(self, key, default=None):
        return self._data().get(key, default)


def _History() -> History:
    """The run's per-step history (runtime.run.history), bounded by this module's HISTORY_MAX."""
    return History(HISTORY_MAX)


class Simulation:
    """One run: `Simulation(scene_or_model).run()`.

    Files: a Scene's run writes what its [output] section asks (VTU frames, .pvd and
    summary.json in [output] dir: runtime.run.run_files), as `tensormass run` does.
    output=False writes nothing; output="folder" writes there instead (like --out);
    output=RunFiles(...) gives the files made by the caller. json: one more summary
    file (like --json); overwrite: like --overwrite. A Model (no scene) writes nothing
    unless writer is given: an object with write_frame(step, time, points,
    displacement, fields) and close(), called at step 0, every output.every steps and
    at the last step (and closed even when the run fails). A write_frame that takes
    cell_fields (runtime.run.output.Writer does) also gets the scene's [output] fields
    (runtime.physics.fields): nodal ones in fields, cell ones in cell_fields.

    progress(step, n_steps) is called after every step; on_step(sim) too, after it:
    between steps the live state is readable (sim.step, sim.time, sim.displacement,
    sim.velocity, sim.dofs, sim.probes()) for coupling with a viewer or a haptic loop.
    checks: callables check(sim) run once the model is built, before the first step (the command
    line passes its RunFiles.check_outputs; a scene's own RunFiles is checked without it).
    u0 / v0: optional initial displacement and velocity ((n_points, dim) or flat).
    """

    def __init__(self, scene_or_model, progress=None, writer=None, u0=None, v0=None, *,
                 output=None, json=None, overwrite: bool = False, on_step=None, checks=()):
        start = time.perf_counter()
        self.files = None
        if isinstance(scene_or_model, Model):
            if output not in (None, False) or json is not None:
                raise TensormassError("Simulation(model, output=...): a Model has no scene to take [output] from; "
                                      "give the Scene, or a writer")
            self.model = scene_or_model
            self._setup = scene_or_model.build_time
        else:
            if writer is None:
                self.files = _run_files(scene_or_model, output, json, overwrite)
                writer = None if self.files is None else self.files.writer
            try:
                self.model = Model.from_scene(scene_or_model)
            except BaseException:
                if self.files is not None:
                    self.files.abandon()
                raise
            self._setup = time.perf_counter() - start
        # runtime.scene.advice: what the scene's choices cost in accuracy (a Model alone: none); setup time
        advised = time.perf_counter()
        self.advice = [] if self.model.scene is None else _advice.scene_advice(self.model.scene, self.model.mesh)
        self._setup += time.perf_counter() - advised
        self.progress, self.writer, self.on_step = progress, writer, on_step
        threads = getattr(self.model.solver, "threads", None)
        if threads is not None:                  # [solver] threads (or run --threads): the one switch
            _parallel.set_threads_from(threads, "solver.threads")
        self.adapter = Adapter(self.model) if self.model.adapt else None
        events = getattr(self.model.scene, "topology", None) or []
        # runtime.change.events: [[cut]] / [[remove]], rehearsed on the rest mesh now
        self.topology = TopologyEvents(self.model, events) if events else None
        self._u0, self._v0 = self._initial(u0), self._initial(v0)
        self._rest_mesh = self.model.mesh          # the summary's "scene" counts the mesh the run began with
        self.ctx = None
        self.stable_dt = None
        self.summary = None
        self._evaluator = None                   # runtime.physics.fields.FieldEvaluator of the current model
        # checks(sim) of the outputs that need the model, before the first step (RunFiles.check_outputs)
        self._checks = ([self.files.check_outputs] if self.files is not None else []) + list(checks)

    def _initial(self, x):
        if x is None:
            return None
        x = np.asarray(x, dtype=float).reshape(-1)
        if x.size != self.model.n_dofs or not np.all(np.isfinite(x)):
            raise TensormassError(f"initial state must be {self.model.n_points} x {self.model.dofs_per_node} finite values")
        return x.copy()

    # -- state ------------------------------------------------------------------------------------
    @property
    def dofs(self) -> np.ndarray:
        """(n_points, dofs_per_node): every nodal unknown (the displacement first where it is one)."""
        u = self.ctx.u if self.ctx is not None else (self._u0 if self._u0 is not None else np.zeros(self.model.n_dofs))
        return self.model.nodal(u).copy()

    @property
    def displacement(self) -> np.ndarray:
        """(n_points, dim); zeros where the nodes carry fewer dofs than dim (see Simulation.dofs)."""
        return np.array(self.model.split_dofs(self.dofs.ravel())[0])

    @property
    def step(self) -> int:
        """The last finished step (0 before the first)."""
        return getattr(self, "_step", 0)

    @property
    def time(self) -> float:
        """The simulated time of the current state [s] (static runs: the load factor's step time)."""
        return float(self.ctx.t) if self.ctx is not None else 0.0

    @property
    def velocity(self) -> np.ndarray:
        v = self.ctx.v if self.ctx is not None else np.zeros(self.model.n_dofs)
        return np.array(self.model.split_dofs(v)[0])

    def fields(self, names=None) -> tuple:
        """(point_fields, cell_fields) at the current state: dicts name -> array (runtime.physics.fields:
        names from FIELDS; None: the scene's [output] fields). Cell arrays in the mesh's block order."""
        if self._evaluator is None or self._evaluator.model is not self.model:   # refinement: a new model
            self._evaluator = _fields.FieldEvaluator(self.model)
        names = _fields.resolve(self.model, names)
        return self._evaluator.evaluate(self.dofs.ravel(), names, self._field_providers())

    def _field_providers(self) -> dict:
        """Fields other modules compute: name -> callable() giving the array (nodal, or per cell for a
        cell field) at the current state."""
        providers = {"reaction": lambda: _reactions.reaction_field(self)}      # runtime.physics.reactions
        if self.model.contact is not None:                                     # runtime.contact
            providers["contact_force"] = lambda: self.model.contact.nodal_forces(self.ctx.u)
            providers["contact_pressure"] = lambda: self.model.contact.nodal_pressure(self.ctx.u)
        if any(p.branches is not None for p in self.model.parts):              # runtime.physics.viscous
            providers["viscous_dissipation"] = lambda: self.ctx.history.dissipation_field(self.model.mesh.n_cells)
        return providers

    def _frame_fields(self) -> tuple:
        """The scene's fields for a frame: names, or () when there are none or the writer takes no
        cell_fields (a simple write_frame(step, t, X, u, fields) gets what it always got)."""
        if self.writer is None or not _takes(self.writer.write_frame, "cell_fields"):
            return ()
        return _fields.resolve(self.model, None)

    # -- run --------------------------------------------------------------------------------------
    def _prepare(self):
        """Everything before the first step: assembly pattern, compilation, initial state."""
        model = self.model
        self.ctx = ctx = Context(model)
        model.warm_up()
        ctx.asm.warm_up()
        if "stiffness" in model.outputs:
            ctx.warm_up_solver()
        self.integrator = make_integrator(ctx)
        if self._u0 is not None:
            ctx.u = self._u0.copy()
        if self._v0 is not None:
            ctx.v = self._v0.copy()
        if isinstance(self.integrator, Explicit):
            self.stable_dt = self.integrator.stable_dt = self._explicit_stable_dt(ctx)
        self.monitor = HealthMonitor(ctx, dynamic=integrator_kinds.get(model.solver.kind).dynamic,
                                     duration=getattr(self.integrator, "duration", None))
        _hourglass.check_static(ctx)          # refused: a static stiffness made singular by hourglass modes
        # the frames' fields can be computed (kernels with stress(), providers): refused before step 1
        _fields.check_available(model, self._frame_fields(), self._field_providers())
        for check in self._checks:           # the pictures asked for can be drawn: refused before step 1
            check(self)
        ctx.asm.time = ctx.linear.time = 0.0         # stepping costs only from here on

    def _explicit_stable_dt(self, ctx) -> float:
        """2 / omega_max at rest, the penalty contact's springs (runtime.contact) added: a node on its
        spring is stiffened by it, and omega_max^2 of the sum is at most the sum of the two (Weyl's
        inequality on M^-1/2 (K + K_penalty) M^-1/2), so 1 / dt^2 adds up, not the smaller dt alone."""
        dt = stable_time_step(ctx)
        contact = getattr(self.model, "contact", None)
        springs = np.inf if contact is None else contact.stable_time_step()
        return dt if not np.isfinite(springs) else 1.0 / np.sqrt(1.0 / dt ** 2 + 1.0 / springs ** 2)

    def run(self) -> Summary:
        """Step the scene; the Summary of a run we stand behind (status "ok" or "warnings").

        Raises RunStopped (status "diverged", "failed" or "invalid") or RunInterrupted
        (Ctrl-C), each carrying the Summary up to the last finished step; errors
        before the first step (bad input) are plain TensormassErrors. The files the
        scene asks for are written in both cases (sim.data: the summary as written).
        """
        if self.ctx is not None:
            raise TensormassError("Simulation.run: this Simulation was started by hand (start/advance); "
                                  "call finish() for its summary, or run a new Simulation")
        if self.files is None:
            try:
                summary = self._run()
            except RunStopped as stopped:
                self._attach_mapping(stopped.summary, stopped)
                raise
            self._attach_mapping(summary, None)
            return summary
        try:
            summary = self._run()
        except RunStopped as stopped:
            self.data = self.files.finish(stopped.summary, stopped)
            raise
        except BaseException:
            self.files.abandon()
            raise
        self.data = self.files.finish(summary, sim=self)
        return summary

    def _attach_mapping(self, summary, stopped) -> None:
        """A run that writes no file: its Summary still reads like the summary.json it would have
        written (no "output": None)."""
        if summary is None:
            return
        scene = self.model.scene
        summary.attach(summary_mapping(summary, stopped, scene, self._rest_mesh))

    def probes(self) -> dict:
        """{name: displacement [m] (a list, dim values)} of every [[probe]] at the current state: the
        values the summary's "probes" holds at the end (before the first step: the initial state)."""
        u = self.ctx.u if self.ctx is not None else (self._u0 if self._u0 is not None else np.zeros(self.model.n_dofs))
        return self.model.probe_values(u)

    def _run(self) -> Summary:
        start = time.perf_counter()
        self._step = 0
        self._history = _History()
        stopped = None
        try:
            self._prepare()
            setup = self._setup + time.perf_counter() - start
            try:
                self._loop()
                status, message = self.monitor.verdict()
                if status == "invalid":
                    stopped = RunStopped, status, message + self._explicit_cause()
            except (_WriterFailed, _CallbackFailed) as failure:
                raise failure.error from None    # the environment's (disk full) or the caller's on_step: as it was
            except (_Stop, _Invalid, KeyboardInterrupt, ValueError, ArithmeticError) as exc:
                stopped = self._stopped_by(exc)
            if stopped is not None:
                _, status, message = stopped
                if self.writer is not None and hasattr(self.writer, "mark_stopped"):
                    self.writer.mark_stopped(self._step, f"run {status}: {message}")
        finally:
            if self.writer is not None:
                self.writer.close()
        self.summary = self._summarise(setup, status, message)
        if stopped is not None:
            kind = stopped[0]
            error = kind(message, self.summary) if kind is RunInterrupted else kind(message, self.summary, status)
            raise error
        return self.summary

    def _stopped_by(self, exc) -> tuple:
        """(RunStopped or RunInterrupted, status, message) of what stopped the step after self._step."""
        if isinstance(exc, _Stop):
            return RunStopped, "diverged", exc.message
        if isinstance(exc, _Invalid):
            return RunStopped, "invalid", exc.message
        if isinstance(exc, KeyboardInterrupt):
            return RunInterrupted, "interrupted", f"interrupted (Ctrl-C) after step {self._step}"
        # a TensormassError, a failed step, a LinAlgError; an inverted element in an explicit run: most
        # often dt above the stable step, said here
        return RunStopped, "failed", f"step {self._step + 1} failed: {exc}{self._explicit_cause()}"

    # -- stepping by hand: a viewer, a haptic loop, a notebook ------------------------------------------
    def start(self) -> None:
        """Prepare for stepping by hand (advance): the model's kernels, the assembly pattern, the
        initial state and step 0's frame. run() does this itself; a Simulation is either run() or
        stepped with start() and advance(), not both."""
        if self.ctx is not None:
            raise TensormassError("Simulation.start: already started (a Simulation starts once; make a new one)")
        begun = time.perf_counter()
        self._step, self._history = 0, _History()
        self._released_work = 0.0
        self._prepare()
        self._setup += time.perf_counter() - begun
        self._begin()

    def advance(self, steps: int = 1) -> dict:
        """Take `steps` more steps (after start()) and give the last one's history row (step, time, newton,
        linear, wall, energies). Open-ended: past solver.steps the loads, amplitudes and prescribed
        motions hold their end values. A step the health monitor stops, or that fails, raises RunStopped
        (its .summary up to the last finished step); the state stays the last good one."""
        if self.ctx is None:
            raise TensormassError("Simulation.advance: call start() first")
        if not getattr(self, "_stepping", True):
            raise TensormassError(f"Simulation.advance: the run stopped at step {self._step}: {self._why}")
        for _ in range(int(steps)):
            try:
                self._advance_step(self._step + 1)
            except (_WriterFailed, _CallbackFailed) as failure:
                raise failure.error from None
            except (_Stop, _Invalid, KeyboardInterrupt, ValueError, ArithmeticError) as exc:
                kind, status, message = self._stopped_by(exc)
                self._stepping, self._why = False, message
                summary = self._summarise(self._setup, status, message)
                raise (kind(message, summary) if kind is RunInterrupted else kind(message, summary, status)) from None
        return dict(self._history.last)

    def finish(self) -> Summary:
        """The Summary of the steps taken by hand (the writer closed); status from the health monitor."""
        if self.ctx is None:
            raise TensormassError("Simulation.finish: nothing was stepped (call start() and advance())")
        if self.writer is not None:
            self.writer.close()
        status, message = self.monitor.verdict()
        self.summary = self._summarise(self._setup, status, message)
        return self.summary

    def grab(self, point, target=None, stiffness: float | None = None):
        """Hold the body at `point` (where it is now, on or in the body) with a spring to `target` (None:
        the point itself), stiffness k [N/m] (None: about the body's own there, runtime.physics.grab).
        The spring acts from the next step on, until release(); move it with drag(target). implicit_euler
        and explicit runs take it. Returns the Grab (grab.force(u): its pull)."""
        from ..physics.grab import GRAB_KINDS, Grab
        if self.ctx is None:
            raise TensormassError("Simulation.grab: call start() first")
        kind = self.model.solver.kind
        if kind not in GRAB_KINDS or getattr(self.model.solver, "device", "cpu") != "cpu":
            raise TensormassError(f"Simulation.grab: solver.kind = {kind!r} on device "
                                  f"{getattr(self.model.solver, 'device', 'cpu')!r} takes no grab; "
                                  f"{' and '.join(GRAB_KINDS)} on the cpu do")
        self.release()
        self.ctx.grab = Grab.at(self.ctx.asm, self.ctx.u, point, target, stiffness)
        return self.ctx.grab

    def drag(self, target) -> None:
        """Move the grab's target (takes effect at the next step)."""
        if self.ctx is None or self.ctx.grab is None:
            raise TensormassError("Simulation.drag: nothing is grabbed (grab(point) first)")
        self.ctx.grab.target = target

    def release(self) -> None:
        """Let go of the grab (its work so far stays in the energy balance); nothing grabbed: no-op."""
        if self.ctx is not None and self.ctx.grab is not None:
            self._released_work = getattr(self, "_released_work", 0.0) + self.ctx.grab.work
            self.ctx.grab = None

    def move_obstacle(self, name: str, shift) -> None:
        """Translate the obstacle `name` by `shift` [m] from where its motion has it, from the next step
        on (a viewer's mouse moving a tool). Penalty contact only: an IPC obstacle may not jump between
        steps, which could carry it through the body."""
        contact = getattr(self.model, "contact", None)
        if self.ctx is None:
            raise TensormassError("Simulation.move_obstacle: call start() first")
        obstacles = {o.name: o for o in getattr(contact, "obstacles", None) or []}
        if name not in obstacles:
            raise TensormassError(f"Simulation.move_obstacle: no obstacle {name!r} (the scene's: "
                                  f"{', '.join(obstacles) or 'none'})")
        if contact.method != "penalty":
            raise TensormassError(f"Simulation.move_obstacle: contact.method = {contact.method!r} obstacles move "
                                  "by their motion only (a jump between steps could cross the body); use "
                                  "contact.method = \"penalty\"")
        d = np.asarray(shift, dtype=float).reshape(-1)
        if d.size != 3 or not np.all(np.isfinite(d)):
            raise TensormassError(f"Simulation.move_obstacle: shift must be 3 finite numbers, got {list(d)}")
        obstacles[name].shift = tuple(float(x) for x in d)

    def _loop(self) -> None:
        self._begin()
        for k in range(1, self.integrator.n_steps + 1):
            self._advance_step(k)

    def _begin(self) -> None:
        """Step 0: the initial energies, the health monitor's start and the first frame."""
        energies = self._energies(0)
        self._write(0, self.monitor.start(self.ctx, energies).flag)

    def _advance_step(self, k: int) -> None:
        """Step k: the integrator's step, then what follows it (volume, adapt, cuts, contact record,
        energies, health check, history, frame, callbacks)."""
        integ, model = self.integrator, self.model
        t0 = time.perf_counter()
        linear = self.ctx.linear_iterations
        grab, u_before = self.ctx.grab, self.ctx.u
        info = integ.step(k)
        if grab is not None:
            grab.add_work(u_before, self.ctx.u)
        if k == integ.n_steps:
            self._check_budget(k, info["time"])
        if model.volume_constraint is not None:
            self._preserve_volume(model)
        if self.adapter is not None:
            self._adapt(k)
            integ, model = self.integrator, self.model      # refinement rebuilds both
            self.monitor.model = model
        if self.topology is not None and self.topology.due(k):
            self._change_topology(k)
            integ, model = self.integrator, self.model
            self.monitor.model = model
        wall = time.perf_counter() - t0
        frame = k % max(model.output.every, 1) == 0 or k == integ.n_steps
        keep = self._history.keeps(k)
        # the contact's record first: it adds the obstacles' work of the step to the balance
        contact_row = None if model.contact is None else self._contact(model.contact, k, info["time"])
        if getattr(integ, "budget", None) is not None:      # the budgeted step: the frames written
            energies = self._energies(k, k == integ.n_steps or (frame and self.writer is not None))
        else:
            energies = self._energies(k, frame or keep)
        if model.contact is not None and self.monitor.energy_scale is not None:
            # the obstacles' work so far scales the balance too (runtime.contact.base.add_work)
            self.monitor.energy_scale = max(self.monitor.energy_scale, getattr(model.contact, "work_scale", 0.0))
        check = self.monitor.check(self.ctx, k, energies)
        if check.stop:
            raise _Stop(check.stop + self._hint(k))
        self._step = k
        row = {"step": k, "time": info["time"], "newton": info["newton"],
               "linear": self.ctx.linear_iterations - linear, "wall": wall, **energies}
        if model.contact is not None:
            row["contact"] = contact_row
        if keep:             # probes and reactions only for the rows the history keeps
            row["probes"] = model.probe_values(self.ctx.u)
            row["reactions"] = _as_lists(self.reactions(), ("force", "moment"))
        self._history.add(row)
        if frame:
            self._write(k, check.flag)
        if self.progress is not None:
            self.progress(k, integ.n_steps)
        if self.on_step is not None:
            try:
                self.on_step(self)
            except Exception as exc:
                raise _CallbackFailed(exc) from exc

    def _contact(self, contact, k: int, t: float) -> dict:
        """The step's contact record (runtime.contact); IPC: the intersection test every check_every steps
        (a state that intersects is a bug, and the run stops "invalid"); penalty: the penetration warning."""
        record = contact.record(self.ctx.u)
        contact.note(record)
        if contact.method == "ipc" and k % contact.spec.check_every == 0:
            why = contact.intersecting(self.ctx.u)
            if why is not None:
                raise _Invalid(f"step {k}: {why}")
        depth = record.get("penetration")
        if depth is not None and depth > contact.max_penetration:
            self.monitor.warn(k, t, "penetration", f"penalty contact: a vertex is {depth:.3g} m inside an obstacle "
                              f"(contact.max_penetration {contact.max_penetration:.3g} m); raise contact.stiffness "
                              "or use contact.method = \"ipc\"")
        return record

    def _preserve_volume(self, model) -> None:
        """Project the closed shell back onto its rest volume (positions only, along the vertex
        normals, prescribed nodes held; runtime.physics.volume_constraint) and keep the worst relative
        volume error seen after a projection in self.volume_error."""
        constraint, free = model.volume_constraint
        U = self.ctx.u.reshape(model.n_points, model.dofs_per_node)
        x = model.mesh.points + U[:, :model.dim]
        try:
            x_new, _ = constraint.project(x, free=free)
        except VolumeConstraintError as exc:
            raise TensormassError(f"solver.preserve_volume: {exc}") from None
        U[:, :model.dim] += x_new - x
        error = abs(constraint.volume(model.mesh.points + U[:, :model.dim]) / constraint.rest_volume - 1.0)
        self.volume_error = max(getattr(self, "volume_error", 0.0), error)
        if integrator_kinds.get(model.solver.kind).dynamic:
            self._tangent_velocities(model, constraint, free, x_new)

    def _tangent_velocities(self, model, constraint, free, x) -> None:
        """Make the velocities tangent to the volume constraint too: v <- v - mu M^-1 g, g = dV/dx at the
        projected positions (free components), mu such that g . v = 0 (RATTLE's velocity step).

        Moving the positions alone leaves velocities that keep pointing across the constraint: the next
        step moves the nodes in, the projection out again, and the kinetic energy grows without bound
        (the squeezed ball of `report squeeze`: 220 J at the end against 2.5 J without the constraint).
        M^-1 weighting keeps the momentum: sum_i m_i M^-1 g_i = sum_i g_i = 0 on a closed surface."""
        dim = model.dim
        V = self.ctx.v.reshape(model.n_points, model.dofs_per_node)
        m = model.mass.reshape(model.n_points, model.dofs_per_node)[:, :dim]
        w = np.divide(free, m, out=np.zeros_like(free), where=m > 0)
        g = constraint.vertex_normals(x)
        denominator = float(np.sum(g * w * g))
        if denominator > 0:
            V[:, :dim] -= (float(np.sum(g * V[:, :dim])) / denominator) * w * g

    def _explicit_cause(self) -> str:
        """The explicit step against the stable step, for a failure of an explicit run ("" otherwise):
        an element that inverts there is the usual sign of a dt above 2 / omega_max."""
        hint = getattr(getattr(self, "integrator", None), "instability_hint", None)
        return f"; explicit integration: {hint()}" if hint is not None else ""

    def _hint(self, k: int) -> str:
        """What the integrator can say about a divergence (explicit: dt against the stable step)."""
        hint = getattr(self.integrator, "instability_hint", None)
        return f"; explicit integration unstable at step {k}: {hint()}" if hint is not None else ""

    # -- adaptation -----------------------------------------------------------------------------
    def _adapt(self, k: int) -> None:
        """Apply the [[adapt]] rules after step k.

        Static: the last load step is re-solved until nothing changes (the answer is the
        equilibrium of the adapted model); earlier load steps only pass their switches on
        to the next step, which costs no extra Newton iterations.
        """
        static = not integrator_kinds.get(self.model.solver.kind).dynamic and k == self.integrator.n_steps
        for _ in range(MAX_STATIC_PASSES if static else 1):
            change = self.adapter.update(self.ctx, k)
            if change.model is not None:
                self._rebuild(change.model, change.parents)
            if not change or not static:
                return
            self.integrator.step(k)          # equilibrium of the adapted model at the same load

    def _rebuild(self, model, parents, u=None, v=None, colours=None) -> None:
        """Carry the state and the counters over to a refined model (new pattern, masses, constants);
        u, v: the new model's state when the caller has it (a topology change), else interpolated;
        colours: the assembler's colouring to reuse (a cut keeps it valid); then the pattern grows too
        (runtime.assembly.pattern.SparsePattern.grown: the new nodes' couplings added, nothing rebuilt)."""
        old, dim = self.ctx, model.dofs_per_node
        ctx = Context(model, Assembler(model, colours=colours, grow_from=old.asm.pattern)
                      if colours is not None else None)
        model.warm_up()
        ctx.asm.warm_up()
        if "stiffness" in model.outputs:
            ctx.warm_up_solver()
        ctx.u = interpolate_nodal(old.u.reshape(-1, dim), parents).ravel() if u is None else u
        ctx.v = interpolate_nodal(old.v.reshape(-1, dim), parents).ravel() if v is None else v
        ctx.t = old.t
        if ctx.history is not None and old.history is not None:      # a cut or removal of viscous parts
            ctx.history.carry(old.history)
        ctx.newton_iterations, ctx.linear_iterations = old.newton_iterations, old.linear_iterations
        ctx.asm.time, ctx.linear.time = old.asm.time, old.linear.time
        for method, count in old.linear.counts.items():           # the summary counts every solve
            ctx.linear.counts[method] = ctx.linear.counts.get(method, 0) + count
        self.model, self.ctx = model, ctx
        self.integrator = make_integrator(ctx)
        if isinstance(self.integrator, Explicit):
            self.stable_dt = self.integrator.stable_dt = self._explicit_stable_dt(ctx)
        if self.writer is not None and hasattr(self.writer, "set_mesh"):
            self.writer.set_mesh(model.mesh)

    def _change_topology(self, k: int) -> None:
        """Apply the [[cut]] / [[remove]] events due after step k: a model changed only where the mesh
        did (runtime.change.cutting), the state carried over exactly, a new assembly pattern and solver."""
        ctx = self.ctx
        changed = self.topology.apply(self.model, k, ctx.t, ctx.u, ctx.v)
        if changed is None:
            return
        model, u, v = changed
        start = time.perf_counter()
        # only cuts since the last model (same cells): the colouring of the assembly stays valid
        cut_only = all(r["kind"] == "cut" for r in self.topology.records[-self.topology.last_count:])
        same_cells = len(model.parts) == len(self.model.parts) and all(
            a.n_active == b.n_active for a, b in zip(model.parts, self.model.parts))
        self._rebuild(model, None, u=u, v=v, colours=self.ctx.asm.colours() if cut_only and same_cells else None)
        record = self.topology.records[-1]
        record["seconds"]["solver"] = time.perf_counter() - start
        record["seconds"]["total"] = sum(record["seconds"].values())

    def _energies(self, step: int, frame: bool = True) -> dict:
        """Elastic, kinetic and external work at the current state (not counted as assembly time).

        Explicit runs evaluate the elastic energy only every EXPLICIT_ENERGY_EVERY steps, on frames and
        on the steps the history keeps; the budgeted implicit Euler step (solver.stiffness_every > 1) every
        EXPLICIT_ENERGY_EVERY steps and on the frames written (frame=True): an energy costs what the forces do.
        """
        ctx, model = self.ctx, self.model
        sparse = isinstance(self.integrator, Explicit) or getattr(self.integrator, "budget", None) is not None
        due = not sparse or frame or step % EXPLICIT_ENERGY_EVERY == 0
        elastic = None
        if "energy" in self.integrator.outputs and due:
            saved = ctx.asm.time
            try:
                elastic = ctx.asm.energy(ctx.u)
            finally:
                ctx.asm.time = saved
        kinetic = model.mass_matrix.energy(ctx.v) if integrator_kinds.get(model.solver.kind).dynamic else None
        with np.errstate(over="ignore", invalid="ignore"):
            # loads with amplitudes: the loads acting now; follower pressure: its work along the path
            work = model.motion.work(ctx.u, ctx.t) + self._pressure_work(model, ctx.u)
        contact = getattr(model, "contact", None)
        if contact is not None:              # moving obstacles' work on the body (runtime.contact)
            work += getattr(contact, "work", 0.0)
        # a grab's spring (runtime.physics.grab): the work of the released ones and of the one held
        work += getattr(self, "_released_work", 0.0) + (0.0 if ctx.grab is None else ctx.grab.work)
        return {"elastic": elastic, "kinetic": kinetic, "external_work": work}

    def _pressure_work(self, model, u) -> float:
        """Work of the follower pressure (runtime/assembly/pressure.py) along the states' path, step by step."""
        if getattr(model, "pressure", None) is None:
            return 0.0
        last, total = getattr(self, "_pressure_path", (None, 0.0))
        if last is not None and last.shape == u.shape:
            total += model.pressure.work(last, u)
        self._pressure_path = (u.copy(), total)
        return total

    # -- reactions (runtime.physics.reactions) ------------------------------------------------------------
    def reactions(self) -> dict:
        """{name: {"force", "moment", "point"}} of every [[fixed]] entry at the current state.

        force (dim,) [N], moment about point [N m]: (3,) in 3D, the z component (a float) in 2D;
        the force the support exerts on the body (runtime.physics.reactions has the definition).
        """
        if self.ctx is None:
            raise TensormassError("reactions: the run has not started (no state yet)")
        return self._reaction_groups().evaluate(self._reaction_residual(), self.ctx.u)

    def _reaction_groups(self):
        cached = getattr(self, "_reaction_cache", None)
        if cached is None or cached.model is not self.model:          # refinement: a new model
            cached = self._reaction_cache = _reactions.Reactions(self.model)
        return cached

    def _reaction_residual(self):
        ctx, known = self.ctx, getattr(self, "_residual_cache", None)
        if known is not None and known[0] is ctx.u and known[1] is ctx.v and known[2] == ctx.t:
            return known[3]
        r = _reactions.residual(ctx, self.integrator)
        self._residual_cache = (ctx.u, ctx.v, ctx.t, r)
        return r

    def _write(self, step: int, flag):
        if self.writer is None:
            return
        fields = {} if not integrator_kinds.get(self.model.solver.kind).dynamic else {"velocity": self.velocity}
        fields.update(self.model.split_dofs(self.dofs.ravel())[1])      # dofs past the displacement (runtime.base.dofs)
        # only the keywords in use, so simple writers (write_frame(step, t, X, u, fields)) keep working
        extra = {} if flag is None else {"flag": flag}
        if self.adapter is not None:          # watch the criteria and the law of each cell in ParaView
            extra["cell_fields"] = self.adapter.cell_fields(self.ctx)
        names = self._frame_fields()          # [output] fields (runtime.physics.fields): nodal and cell data
        if names:
            point, cell = self.fields(names)
            if flag is not None:
                (point, n_point), (cell, n_cell) = _undefined_as_zero(point), _undefined_as_zero(cell)
                undefined = n_point + n_cell
                if undefined:
                    extra["flag"] = f"{flag}; {undefined} field value(s) undefined there (det F = 0), written as 0"
            fields.update(point)
            extra["cell_fields"] = {**extra.get("cell_fields", {}), **cell}
        try:
            self.writer.write_frame(step, self.ctx.t, self.model.mesh.points, self.displacement, fields, **extra)
        except Exception as exc:
            raise _WriterFailed(exc) from exc

    def _summarise(self, setup, status, message) -> Summary:
        ctx, model, h = self.ctx, self.model, self._history
        last = h.last
        n_steps = self.integrator.n_steps if getattr(self, "integrator", None) is not None else 0
        return Summary(
            name=model.name, solver=model.solver.kind, steps=n_steps,
            n_dofs=model.n_dofs, n_free_dofs=int(model.free_dofs.size),
            n_elements=model.n_elements, kernels=self._kernel_info(),
            time={"setup": setup, "mesh_read": getattr(model.scene, "_mesh_seconds", None),
                  "first_step": h.first_wall or 0.0,
                  "assembly": ctx.asm.time, "linear_solve": ctx.linear.time,
                  "health": self.monitor.time, "total": setup + h.wall_total},
            iterations={"newton": ctx.newton_iterations, "linear": ctx.linear_iterations,
                        "linear_solvers": dict(sorted(ctx.linear.counts.items())), **self._budget()},
            probes=model.probe_values(ctx.u), energy=last.get("elastic"), kinetic_energy=last.get("kinetic"),
            stable_dt=self.stable_dt, per_step=h.to_dict(),
            adapt=None if self.adapter is None else self.adapter.summary(model),
            topology=None if self.topology is None else self.topology.summary(),
            status=status, message=message, warnings=list(self.monitor.warnings),
            health=self.monitor.summary(), steps_done=self._step,
            estimate=_estimate(model), probe_points=model.probe_info(),
            fields=self._fields_summary(), reactions=self._final_reactions(),
            units=_units(model.dim, not integrator_kinds.get(model.solver.kind).dynamic,
                         getattr(model, "contact", None) is not None), advice=list(getattr(self, "advice", [])),
            contact=None if getattr(model, "contact", None) is None else model.contact.summary(),
            incompressible=None if getattr(ctx, "pressures", None) is None else ctx.pressures.summary(ctx.u),
            viscous=None if getattr(ctx, "history", None) is None else {"dissipated": ctx.history.dissipated_energy()})

    def _budget(self) -> dict:
        """{"budget": what the budgeted step kept and its estimated trajectory error} (runtime.physics.
        integrators.StepBudget), or nothing when every step is exact."""
        budget = getattr(getattr(self, "integrator", None), "budget", None)
        return {} if budget is None else {"budget": budget.summary()}

    def _check_budget(self, k, t) -> None:
        """A warning at the last step when the budgeted step's estimated trajectory error, over the run's
        largest displacement, passes STEP_ERROR_WARNING."""
        budget = getattr(self.integrator, "budget", None)
        if budget is None or budget.error <= STEP_ERROR_WARNING:
            return
        self.monitor.warn(k, t, "budget",
                          f"keeping K between steps moved the trajectory by an estimated {100 * budget.error:.2g} % of "
                          f"the largest displacement against exact steps (above {100 * STEP_ERROR_WARNING:g} %): lower "
                          f"solver.stiffness_every ({budget.every}) or solver.stiffness_tolerance ({budget.tolerance:g}), "
                          "or use mode = \"exact\"")

    def _kernel_info(self) -> list:
        """Model.kernel_info with, per part, the colour count of its assembly: segments of one colour
        share no node and run on the threads at once (runtime.assembly.assembly)."""
        info = self.model.kernel_info()
        plans = getattr(getattr(self.ctx, "asm", None), "plans", None) or []
        for row, plan in zip(info, plans):
            row["colours"] = int(len(plan.starts) - 1)
            row["segments"] = int(plan.n_segments)
        return info

    def _final_reactions(self) -> dict:
        """{name: {"force", "moment", "point"}} at the last state (lists), {} before any step."""
        if self.ctx is None or not self._step:
            return {}
        try:
            return _as_lists(self.reactions(), ("force", "moment", "point"))
        except (ValueError, ArithmeticError):        # a state that failed: the history has the last good ones
            return {}

    def _fields_summary(self):
        names = self._frame_fields()
        if not names:
            return None
        return {"names": list(names), "law_ids": self.model.law_names(), "fields": _fields.describe(names)}


def _undefined_as_zero(fields: dict) -> dict:
    """(fields with NaN/Inf entries set to 0, how many there were), for a frame already marked by the
    health monitor: a collapsed element (det F = 0) has no Cauchy stress, and that frame is written
    with its mark rather than refused (unmarked frames keep the writer's NaN refusal)."""
    out, count = {}, 0
    for name, values in fields.items():
        values = np.asarray(values)
        bad = ~np.isfinite(values) if values.dtype.kind in "fc" else np.zeros(values.shape, bool)
        out[name] = np.where(bad, 0.0, values) if bad.any() else values
        count += int(bad.sum())
    return out, count


def _as_lists(reactions: dict, keys) -> dict:
    """Simulation.reactions() as JSON-ready lists (2D moments: a one-element list)."""
    return {name: {k: np.ravel(r[k]).tolist() for k in keys} for name, r in reactions.items()}


def _run_files(scene, output, json, overwrite):
    """The RunFiles of Simulation(scene, output=..., json=...), prepared; None: nothing to write."""
    if isinstance(output, RunFiles):
        output.prepare()
        return output
    if output is False:
        if json is not None:
            raise TensormassError("Simulation(output=False, json=...): output=False writes no file; drop one of them")
        return None
    if output not in (None, True) and not isinstance(output, (str, os.PathLike)):
        raise TensormassError(f"Simulation(output=...) takes a folder, True/None (the scene's [output]) or False, "
                              f"not {type(output).__name__}")
    folder = None if output in (None, True) else output
    if output is True and not scene.output.dir:
        raise TensormassError("Simulation(output=True): the scene has no [output] dir; give output=\"folder\"")
    if folder is None and not scene.output.dir and json is None:
        return None
    files = RunFiles(scene, out=folder, json_path=json, overwrite=overwrite,
                     dir_from=None if folder is None else "given to Simulation(output=...), relative to the working directory")
    files.prepare()
    return files


def _takes(function, keyword: str) -> bool:
    """Whether a callable accepts the keyword argument (by name or through **kwargs)."""
    import inspect
    try:
        params = inspect.signature(function).parameters
    except (TypeError, ValueError):
        return False
    return keyword in params or any(p.kind is p.VAR_KEYWORD for p in params.values())


def _estimate(model):
    est = getattr(model, "estimate", None)
    return None if est is None else dict(est.to_dict(), text=est.describe())


class _Stop(Exception):
    """The health monitor's verdict inside the step loop (becomes RunStopped with the summary)."""

    def __init__(self, message: str):
        super().__init__(message)
        self.message = message


class _Invalid(Exception):
    """A state the run must not go on from (contact: intersecting surfaces): becomes RunStopped "invalid"."""

    def __init__(self, message: str):
        super().__init__(message)
        self.message = message


class _CallbackFailed(Exception):
    """on_step raised: re-raised as it was (not reported as a failed step)."""

    def __init__(self, error: Exception):
        super().__init__(str(error))
        self.error = error


class _WriterFailed(Exception):
    """Writing a frame failed (disk full, permissions): re-raised as it was, not as a failed step."""

    def __init__(self, error: Exception):
        super().__init__(str(error))
        self.error = error
