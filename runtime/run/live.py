"""A simulation stepped live: by hand, or by its own thread while a viewer or a haptic loop watches.

    live = Live(scene)              # built and started (Simulation.start), paused at step 0
    live.step(10)                   # ten steps in the caller's thread
    live.play(); live.pause()       # steps in a thread of its own until paused (play(speed=1): real time)
    live.grab(point); live.drag(target); live.release()     # a spring pulls the body (runtime.physics.grab)
    live.move_obstacle("tool", shift)                       # a tool moved by the mouse (penalty contact)
    snap = live.snapshot()          # the state after the last step: an immutable copy, read from any thread
    live.reset()                    # the scene again from step 0
    live.close()

Every step runs under one lock, so commands from other threads (a browser's buttons and mouse) land
between steps. A drag only records where the mouse is; before each step the grab's target moves toward
it by at most the grabbed cell's size (runtime.physics.grab), so a fast mouse cannot tear the cell
apart in one step. The step thread publishes a Snapshot after each step; a viewer takes the latest
when it draws and skips those it had no time for: it never holds the steps up.

What the steps compute never depends on the clock: play(speed) only waits between steps. The mouse
acts at whatever step it reaches, as in any interactive loop; a script that grabs and drags between
step() calls repeats bit for bit.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from ..base.errors import RunStopped, TensormassError
from ..physics.grab import GRAB_KINDS
from .simulation import Simulation

__all__ = ["Live", "Snapshot", "CURVE_POINTS", "drawable_fields", "describe_body", "field_values"]

# Rows of the curves a Snapshot carries (time, probes, energies, grab force): the latest this many steps.
CURVE_POINTS = 2000
# The step rate a Snapshot reports is the mean over this many of the last steps' wall times.
RATE_WINDOW = 20
# A tool the mouse moves (move_obstacle) goes at most this share of the body's size per step (on the
# organ of examples/organ/live_tool.toml 0.1 mm a step, 1 cm/s): a penalty contact pushed by larger
# jumps rings, the body bouncing off the tool at the jumps' pace.
TOOL_REACH = 0.001


@dataclass(frozen=True)
class Snapshot:
    """The state after one step, copied: what a viewer draws."""
    step: int
    time: float
    displacement: np.ndarray             # (n_points, dim) [m]
    dofs: np.ndarray                     # (n_points, dofs_per_node): every nodal unknown
    probes: dict                         # name -> [dim values] [m]
    status: str                          # "paused" | "playing" | "stopped" (a step failed: message says why)
    message: str | None
    step_wall: float                     # mean wall time of the recent steps [s] (RATE_WINDOW)
    grab: dict | None                    # {"point", "target", "force", "stiffness"} while grabbed
    curves: dict = field(default_factory=dict)     # name -> np.ndarray over the last CURVE_POINTS steps
    model: object = None                 # the Model of this state (None from a LiveProcess)
    version: int = 0                     # counts the models (reset, cut, refinement): body() changes with it
    values: tuple | None = None          # snapshot(field): (values per point or cell, "point" | "cell")
    obstacles: tuple = ()                # snapshot(field): each obstacle's vertices where it is now
    tools: dict = field(default_factory=dict)      # obstacle name -> the body's force on it [N] (contact)

    @property
    def steps_per_second(self) -> float:
        return 1.0 / self.step_wall if self.step_wall > 0 else 0.0


class Live:
    """A Scene stepped live (see the module doc). The scene's solver must take a grab: implicit_euler
    or explicit (runtime.physics.grab.GRAB_KINDS); nothing is written to disk."""

    def __init__(self, scene, *, stiffness: float | None = None):
        kind = scene.solver.kind
        if kind not in GRAB_KINDS:
            raise TensormassError(f"live: solver.kind = {kind!r} cannot be stepped live; use "
                                  f"{' or '.join(repr(k) for k in GRAB_KINDS)} (a dynamic step a mouse can pull)")
        if getattr(scene.solver, "device", "cpu") != "cpu":
            raise TensormassError("live: solver.device = \"cuda\" cannot be stepped live (the grab's spring runs on "
                                  "the cpu); remove solver.device")
        self.scene, self.stiffness = scene, stiffness
        self._lock = threading.RLock()
        self._playing = threading.Event()
        self._closed = False
        self._thread = None
        self._speed = None
        self._mouse = None                   # where a drag wants the grab's target
        self._new()

    # -- state --------------------------------------------------------------------------------------------
    def _new(self) -> None:
        for obstacle in getattr(self.scene, "obstacles", None) or []:
            obstacle.shift = None            # the scene's obstacles: where their motion has them again
        sim = Simulation(self.scene, output=False)
        self.sim = sim
        sim.start()
        self._stopped = None
        self._evaluator = None
        self._walls = deque(maxlen=RATE_WINDOW)
        self._curves = {}
        self._mouse = None
        self._tools = {}                     # obstacle name -> the shift the mouse wants
        self._publish()
        self._record()

    def snapshot(self, field: str | None = None, curves: bool = False) -> Snapshot:
        """The state after the last step (a new object each step; safe to keep and read anywhere).
        field: with that field's values (one of body()["fields"]) and the obstacles' poses; curves: with
        the curves of the last CURVE_POINTS steps; both computed now, in the calling thread."""
        snap = self._snapshot
        if curves:
            with self._lock:
                snap = replace(self._snapshot, curves={k: np.asarray(v) for k, v in self._curves.items()})
        if field is None:
            return snap
        if self._evaluator is None or self._evaluator[0] is not snap.model:
            from ..physics.fields import FieldEvaluator
            self._evaluator = (snap.model, FieldEvaluator(snap.model))
        return replace(snap, values=field_values(snap, field, self._evaluator[1]),
                       obstacles=obstacle_poses(snap.model))

    def body(self) -> dict:
        """What a viewer draws the state on: the mesh, the fields it can colour by, the probes, the
        obstacles at rest ({"name", "dim", "mesh", "fields", "probes", "obstacles", "version"})."""
        return describe_body(self._snapshot.model, self._snapshot.version)

    @property
    def playing(self) -> bool:
        return self._playing.is_set()

    def _publish(self) -> None:
        sim, grab = self.sim, self.sim.ctx.grab
        g = None
        if grab is not None:
            u = sim.ctx.u
            g = {"point": grab.position(u), "target": grab.target.copy(), "force": grab.force(u),
                 "stiffness": grab.stiffness}
        status = "stopped" if self._stopped else ("playing" if self.playing else "paused")
        contact = (sim._history.last.get("contact") if sim.step else None) or {}
        tools = {name: np.asarray(o["force"], dtype=float) for name, o in (contact.get("obstacles") or {}).items()}
        dofs = sim.dofs                      # one copy of the state: the displacement is its first columns
        self._snapshot = Snapshot(
            step=sim.step, time=sim.time, displacement=np.array(sim.model.split_dofs(dofs.ravel())[0]), dofs=dofs,
            probes=sim.probes(),
            status=status, message=self._stopped, step_wall=float(np.mean(self._walls)) if self._walls else 0.0,
            grab=g, model=sim.model, tools=tools,
            version=self._model_changes(sim.model))

    def _model_changes(self, model) -> int:
        """A cut or a refinement replaces the Simulation's model: the snapshot's version counts it."""
        if getattr(self, "_last_model", None) is not model:
            self._changes = getattr(self, "_changes", -1) + 1
            self._last_model = model
        return self._changes

    def _record(self) -> None:
        """One row of the curves from the snapshot just published: time, each probe's components, the
        grab's force, the kinetic energy."""
        snap, sim = self._snapshot, self.sim
        row = {"time": snap.time}
        for name, value in snap.probes.items():
            for c, x in zip("xyz", value):
                row[f"{name} u{c}"] = x
        row["grab force"] = 0.0 if snap.grab is None else float(np.linalg.norm(snap.grab["force"]))
        last = sim._history.last if sim.step else {}
        row["kinetic energy"] = last.get("kinetic") or 0.0
        for key, x in row.items():
            self._curves.setdefault(key, deque(maxlen=CURVE_POINTS)).append(x)

    # -- stepping --------------------------------------------------------------------------------------
    def step(self, n: int = 1) -> Snapshot:
        """n steps now, in this thread (waits for the play thread's step in progress). A step that fails
        stops the live run (snapshot().status "stopped", .message why; reset() starts again) and raises
        RunStopped."""
        for _ in range(int(n)):
            with self._lock:
                self._one()
        return self._snapshot

    def _one(self) -> None:
        if self._stopped:
            raise TensormassError(f"live: stopped at step {self.sim.step}: {self._stopped}; reset() starts again")
        self._follow_mouse()
        self._follow_tools()
        start = time.perf_counter()
        try:
            self.sim.advance(1)
        except RunStopped as stopped:
            self._stopped = str(stopped)
            self._playing.clear()
            self._publish()
            raise
        self._walls.append(time.perf_counter() - start)
        self._publish()
        self._record()

    def _follow_mouse(self) -> None:
        """Move the grab's target toward the mouse by at most the grabbed cell's size."""
        grab, mouse = self.sim.ctx.grab, self._mouse
        if grab is None or mouse is None:
            return
        d = mouse - grab.target
        reach = grab.cell_size or np.inf
        distance = float(np.linalg.norm(d))
        self.sim.drag(grab.target + (d if distance <= reach else d * (reach / distance)))

    def play(self, speed: float | None = None) -> None:
        """Step in a thread of this object until pause(); speed: simulated seconds per wall second (1: real
        time, waiting between steps that run faster), None: as fast as the steps go."""
        if self._stopped:
            raise TensormassError(f"live: stopped at step {self.sim.step}: {self._stopped}; reset() starts again")
        if speed is not None and not (float(speed) > 0):
            raise TensormassError(f"live: play(speed) must be > 0 or None, got {speed!r}")
        self._speed = None if speed is None else float(speed)
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="tensormass-live", daemon=True)
            self._thread.start()
        self._playing.set()
        with self._lock:
            self._publish()

    def pause(self) -> None:
        """Stop stepping: once this returns no step runs until play() or step()."""
        self._playing.clear()
        with self._lock:                     # the step in progress ends first
            self._publish()

    def _run(self) -> None:
        next_at = None
        while not self._closed:
            if not self._playing.wait(timeout=0.1):
                next_at = None
                continue
            with self._lock:
                if not self._playing.is_set() or self._closed:
                    continue
                try:
                    self._one()
                except (RunStopped, TensormassError):
                    continue                 # stopped: the snapshot says why; the loop waits for reset()
                dt = getattr(self.sim.integrator, "dt", 0.0)
            if self._speed is not None and dt > 0:
                now = time.perf_counter()
                next_at = (now if next_at is None else next_at) + dt / self._speed
                if next_at > now:
                    time.sleep(next_at - now)
                else:
                    next_at = now            # behind: no catching up in a burst

    def reset(self) -> Snapshot:
        """The scene again from step 0 (paused; the model rebuilt, so a cut body is whole again)."""
        self._playing.clear()
        with self._lock:
            self._new()
        return self._snapshot

    def close(self) -> None:
        self._closed = True
        self._playing.clear()
        if self._thread is not None:
            self._thread.join(timeout=5)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- the mouse -------------------------------------------------------------------------------------
    def grab(self, point, stiffness: float | None = None):
        """Hold the body at `point` (where it is now) with a spring (stiffness None: the Live's, else
        runtime.physics.grab.default_stiffness); drag() moves it, release() lets go."""
        with self._lock:
            grab = self.sim.grab(point, None, stiffness if stiffness is not None else self.stiffness)
            self._mouse = None
            self._publish()
            return grab

    def drag(self, target) -> None:
        """Where the mouse is: the grab's target walks there step by step (returns at once)."""
        t = np.asarray(target, dtype=float).reshape(-1)
        if self.sim.ctx.grab is None:
            raise TensormassError("live: nothing is grabbed (grab(point) first)")
        if t.size != self.sim.model.dim or not np.all(np.isfinite(t)):
            raise TensormassError(f"live: drag target must be {self.sim.model.dim} finite numbers, got {list(t)}")
        self._mouse = t

    def release(self) -> None:
        with self._lock:
            self.sim.release()
            self._mouse = None
            self._publish()

    def move_obstacle(self, name: str, shift) -> None:
        """Where the mouse wants the obstacle `name`: `shift` [m] from where its motion has it. It walks
        there by at most TOOL_REACH of the body's size per step (penalty contact: Simulation.move_obstacle)."""
        d = np.asarray(shift, dtype=float).reshape(-1)
        with self._lock:
            self.sim.move_obstacle(name, self._shift_of(name))        # the name and the method checked, no move
            if d.size != 3 or not np.all(np.isfinite(d)):
                raise TensormassError(f"live: obstacle shift must be 3 finite numbers, got {list(d)}")
            self._tools[name] = d

    def _shift_of(self, name) -> np.ndarray:
        for obstacle in self._obstacles():
            if obstacle.name == name and obstacle.shift is not None:
                return np.asarray(obstacle.shift, dtype=float)
        return np.zeros(3)

    def _obstacles(self) -> list:
        return list(getattr(getattr(self.sim.model, "contact", None), "obstacles", None) or [])

    def _follow_tools(self) -> None:
        """Move each obstacle the mouse holds toward where it wants it, by at most TOOL_REACH x the body's size."""
        if not self._tools:
            return
        reach = TOOL_REACH * float(np.linalg.norm(np.ptp(self.sim.model.mesh.points, axis=0)))
        for name, wanted in self._tools.items():
            now = self._shift_of(name)
            d = wanted - now
            distance = float(np.linalg.norm(d))
            self.sim.move_obstacle(name, now + (d if distance <= reach else d * (reach / distance)))


# ============================================================================== what a viewer draws

# Scalar fields a viewer colours by, after the displacement's magnitude, where the kernels give them.
_DRAWABLE = ("von_mises", "pressure", "energy_density", "det_F_min", "principal_stretches")


def drawable_fields(model) -> list:
    """'displacement', then the stress and strain fields (runtime.physics.fields) this model evaluates."""
    from ..physics import fields as _fields
    names = ["displacement"]
    for name in _DRAWABLE:
        try:
            _fields.check_available(model, (name,), {})
        except TensormassError:
            continue
        names.append(name)
    return names


def describe_body(model, version: int = 0) -> dict:
    from ..physics.fields import FIELDS
    contact = getattr(model, "contact", None)
    obstacles = []
    if contact is not None and getattr(contact, "obstacles", None):
        size = float(np.linalg.norm(np.ptp(model.mesh.points, axis=0)))
        for obstacle in contact.obstacles:
            V, F = obstacle.triangles(2.0 * size, size / 40)
            obstacles.append((obstacle.name, np.asarray(V, float), np.asarray(F, np.int64)))
    fields = drawable_fields(model)
    return {"name": model.name, "dim": model.dim, "mesh": model.mesh, "fields": fields,
            "units": {f: ("m" if f == "displacement" else FIELDS[f].unit) for f in fields},
            "probes": model.probe_info(), "obstacles": obstacles, "version": version}


def field_values(snap, field_name: str, evaluator) -> tuple:
    """(values, "point" | "cell") of a drawable field at the snapshot's state; a vector or tensor field
    as its magnitude, undefined values (det F = 0) as 0."""
    if field_name == "displacement":
        return np.linalg.norm(snap.displacement, axis=1), "point"
    point, cell = evaluator.evaluate(snap.dofs.ravel(), (field_name,), {})
    where = "point" if field_name in point else "cell"
    values = np.asarray(point.get(field_name, cell.get(field_name)), dtype=float)
    if values.ndim > 1:
        values = np.linalg.norm(values.reshape(len(values), -1), axis=1)
    return np.where(np.isfinite(values), values, 0.0), where


def obstacle_poses(model) -> tuple:
    """Each obstacle's vertices at its current pose (the order of describe_body's obstacles)."""
    contact = getattr(model, "contact", None)
    if contact is None or not getattr(contact, "obstacles", None):
        return ()
    size = float(np.linalg.norm(np.ptp(model.mesh.points, axis=0)))
    return tuple(o.placed(np.asarray(o.triangles(2.0 * size, size / 40)[0], float), contact.amplitude(o, contact.s))
                 for o in contact.obstacles)
