"""Motions over time: amplitude tables, prescribed rigid motions, time-varying loads.

    amp = Amplitude("press", "time", (0.0, 0.5, 1.0), (0.0, 1.0, 0.0))
    amp.value(time=0.25, fraction=0.1)          # 0.5: piecewise linear, end values held outside
    motion = Motion(model, fixed, amplitudes)   # built by the Model (model.motion)
    motion.displacement(s)                      # prescribed values of model.fixed_dofs at run fraction s
    motion.forces(s)                            # external force vector at run fraction s
    motion.factor("press", s)                   # an amplitude's value at run fraction s (any other load)

The run fraction s (the *load factor*) runs from 0 to 1 over a run: static runs step it
k / steps, dynamic runs have s = t / T with T = steps * dt.  Static runs have a pseudo-time
t = s (period 1, as in Abaqus static steps), so a `time` table and a `factor` table mean the
same there; in dynamic runs `time` is in seconds and `factor` in fractions of the run.

Defaults (no amplitude named): a prescribed displacement or rigid motion follows the linear
ramp a = s (clamped to [0, 1]); loads follow the ramp in static runs and are constant (a = 1)
in dynamic runs.  The built-in names "ramp" and "constant" select these explicitly.

A [[fixed]] entry with `rotation = {axis, point, angle}` and/or `translation` prescribes, with
the amplitude a(s) of the entry,

    u(X, s) = R(a angle) (X - p) + p + a t - X

at every step: true rotations, not chords.  The nodes an entry holds come from the Model's own
selection (`model.fixed_owner`, what runtime.mesh.regions.prescribed_values returned), so however
[[fixed]] selects nodes (boxes, regions), motions follow.  Dynamic integrators that move fixed
dofs by a velocity use `boundary_velocity(u, s1, h)`, the finite difference over the step,
so the fixed nodes land exactly on u(X, s1).

Static runs turn a rotation by at most MAX_STATIC_ROTATION_STEP (45 degrees) per load step, or
are refused naming the steps they need.  Equilibrium under a turned clamp depends on the path, not
only on where the clamp ends: a bar twisted by a full turn has its end face back where it started,
yet holds a full turn of twist; only a path of small increments tells the solver which of these
equilibria the motion means (from the previous one, a step of 180 degrees or more is closer to
the equilibrium of a smaller or opposite twist, and Newton lands there without a message).
Measured on a stable neo-Hookean bar (1 x 0.1 x 0.1 m, 8 x 2 x 2 hexahedra) turned 360 degrees:
steps of 7.5, 30 and 45 degrees give the same twisted equilibrium (mid-length section at 180
degrees); steps of 60 or 90 degrees fail in Newton; steps of 180 or 360 degrees return the
untwisted bar with status ok.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..base import integrator_kinds
from ..base.errors import SceneError, TensormassError

__all__ = ["Amplitude", "Rotation", "Motion", "BUILTIN_AMPLITUDES", "parse_amplitude", "parse_rotation",
           "rotation_matrix", "rigid_displacement", "check_amplitude_use", "MAX_STATIC_ROTATION_STEP"]

ABSCISSAE = ("time", "factor")
_AMPLITUDE_KEYS = ("name", "time", "factor", "value")
_ROTATION_KEYS = ("axis", "point", "angle")
# degrees a prescribed rotation may turn in one static load step (see the module doc)
MAX_STATIC_ROTATION_STEP = 45.0


@dataclass(frozen=True)
class Amplitude:
    """A named piecewise-linear table a(x); x is the run time ("time") or the run fraction ("factor")."""
    name: str
    abscissa: str                         # "time" | "factor"
    x: tuple
    y: tuple

    def value(self, time: float, fraction: float) -> float:
        """a at this time / run fraction; the end values are held outside the table."""
        at = time if self.abscissa == "time" else fraction
        return float(np.interp(at, self.x, self.y))

    def peak(self) -> float:
        return max(abs(v) for v in self.y)


# value = run fraction (clamped), and 1: the defaults, also usable by name
BUILTIN_AMPLITUDES = {"ramp": Amplitude("ramp", "factor", (0.0, 1.0), (0.0, 1.0)),
                      "constant": Amplitude("constant", "factor", (0.0,), (1.0,))}


@dataclass(frozen=True)
class Rotation:
    """A rotation by `angle` degrees about the line through `point` along `axis` (2D: in the plane)."""
    point: tuple
    angle: float                          # degrees
    axis: tuple | None = None             # None in 2D


def rotation_matrix(axis, angle_rad: float, dim: int) -> np.ndarray:
    """The proper rotation by angle_rad about the unit axis (Rodrigues); 2D: about z."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    if dim == 2:
        return np.array([[c, -s], [s, c]])
    n = np.asarray(axis, dtype=float)
    n = n / np.linalg.norm(n)
    K = np.array([[0.0, -n[2], n[1]], [n[2], 0.0, -n[0]], [-n[1], n[0], 0.0]])
    return np.eye(3) * c + s * K + (1.0 - c) * np.outer(n, n)


def rigid_displacement(X, a: float, rotation: Rotation | None, translation) -> np.ndarray:
    """u = R(a angle)(X - p) + p + a t - X for the points X (n, dim)."""
    X = np.asarray(X, dtype=float)
    u = np.zeros_like(X)
    if rotation is not None:
        p = np.asarray(rotation.point, dtype=float)
        R = rotation_matrix(rotation.axis, math.radians(a * rotation.angle), X.shape[1])
        d = X - p
        u += d @ R.T - d
    if translation is not None:
        u += a * np.asarray(translation, dtype=float)
    return u


# ============================================================================== scene parsing


def parse_amplitude(parser, t, key) -> Amplitude:
    """One [[amplitude]] table (parser: runtime.scene.scene's _Parser, for its checks and messages)."""
    t = parser.table(t, key)
    parser.keys(t, key, _AMPLITUDE_KEYS)
    if "name" not in t:
        raise SceneError(f"{key}.name: missing (loads and [[fixed]] refer to the table by amplitude = \"name\")")
    name = parser.string(t["name"], f"{key}.name")
    if not name.strip():
        raise SceneError(f"{key}.name: must not be empty")
    if name in BUILTIN_AMPLITUDES:
        raise SceneError(f"{key}.name: {name!r} is a built-in amplitude ({', '.join(BUILTIN_AMPLITUDES)}); "
                         "choose another name")
    given = [k for k in ABSCISSAE if k in t]
    if len(given) != 1:
        raise SceneError(f"{key}: give exactly one of time = [...] (seconds; the load factor in static runs) "
                         f"or factor = [...] (the load factor, 0 to 1 over the run)"
                         + (", not both" if len(given) == 2 else ""))
    abscissa = given[0]
    if "value" not in t:
        raise SceneError(f"{key}.value: missing (the amplitude at each {abscissa})")
    x = _numbers(parser, t[abscissa], f"{key}.{abscissa}")
    y = _numbers(parser, t["value"], f"{key}.value")
    if len(x) != len(y):
        raise SceneError(f"{key}.value: {len(y)} value(s) for {len(x)} {abscissa} point(s); the lengths must agree")
    for i in range(1, len(x)):
        if not x[i] > x[i - 1]:
            raise SceneError(f"{key}.{abscissa}[{i}]: {abscissa} must increase strictly "
                             f"({x[i - 1]:g} then {x[i]:g})")
    if x[0] < 0:
        raise SceneError(f"{key}.{abscissa}[0]: must be >= 0 (got {x[0]:g}); runs start at 0")
    if abscissa == "factor" and x[-1] > 1:
        raise SceneError(f"{key}.factor[{len(x) - 1}]: must be <= 1 (got {x[-1]:g}); the load factor runs "
                         "from 0 to 1 over the run (use time = [...] for seconds)")
    return Amplitude(name, abscissa, x, y)


def _numbers(parser, raw, key) -> tuple:
    if not isinstance(raw, list) or not raw:
        raise SceneError(f"{key}: expected a non-empty array of numbers")
    return tuple(parser.number(v, f"{key}[{i}]") for i, v in enumerate(raw))


def parse_rotation(parser, raw, key, dim) -> Rotation:
    """rotation = { axis = [...], point = [...], angle = <degrees> } (2D: no axis)."""
    t = parser.table(raw, key)
    parser.keys(t, key, _ROTATION_KEYS)
    for k in ("point", "angle"):
        if k not in t:
            raise SceneError(f"{key}.{k}: missing (rotation = {{ axis = [...], point = [...], angle = degrees }})")
    point = parser.vector(t["point"], f"{key}.point", dim=dim)
    angle = parser.number(t["angle"], f"{key}.angle")
    if len(point) == 2:
        if "axis" in t:
            raise SceneError(f"{key}.axis: a 2D rotation turns in the plane about point; leave axis out")
        return Rotation(point=point, angle=angle)
    if "axis" not in t:
        raise SceneError(f"{key}.axis: missing (the direction of the rotation axis, e.g. [1.0, 0.0, 0.0])")
    axis = parser.vector(t["axis"], f"{key}.axis", dim=3)
    if not np.linalg.norm(axis) > 0:
        raise SceneError(f"{key}.axis: must not be the zero vector")
    return Rotation(point=point, angle=angle, axis=axis)


def check_amplitude_use(amplitudes, fixed, loads, obstacles=()) -> None:
    """Every amplitude named by a [[fixed]] entry, a load or an [[obstacle]] exists, and every table is
    used (SceneError)."""
    known = {a.name: a for a in amplitudes}
    used = set()
    references = list(_references(fixed, loads))
    references += [(f"obstacle[{i}].amplitude", o.amplitude) for i, o in enumerate(obstacles) if o.amplitude is not None]
    for key, name in references:
        if name in BUILTIN_AMPLITUDES:
            continue
        if name not in known:
            listed = ", ".join(list(known) + list(BUILTIN_AMPLITUDES))
            raise SceneError(f"{key}: unknown amplitude {name!r}; known: {listed}")
        used.add(name)
    for i, a in enumerate(amplitudes):
        if a.name not in used:
            raise SceneError(f"amplitude[{i}]: {a.name!r} is used by no [[fixed]] entry, load or obstacle; remove it, or "
                             f"refer to it with amplitude = {a.name!r}")


def _references(fixed, loads):
    """(key, amplitude name) of every [[fixed]] entry and load that names one (loads: any list of
    items with an `amplitude` attribute, so load kinds added later are covered)."""
    for i, f in enumerate(fixed):
        if getattr(f, "amplitude", None) is not None:
            yield f"fixed[{i}].amplitude", f.amplitude
    if getattr(loads, "gravity_amplitude", None) is not None:
        yield "loads.gravity_amplitude", loads.gravity_amplitude
    counts: dict = {}
    for field in dataclasses.fields(loads):
        items = getattr(loads, field.name)
        if not isinstance(items, list):
            continue
        for item in items:
            kind = getattr(item, "kind", field.name)
            i = counts.get(kind, 0)
            counts[kind] = i + 1
            if getattr(item, "amplitude", None) is not None:
                yield f"loads.{kind}[{i}].amplitude", item.amplitude


# ============================================================================== the model's motion


def _moves(entry) -> bool:
    return getattr(entry, "rotation", None) is not None or getattr(entry, "translation", None) is not None


class Motion:
    """Prescribed displacements and external loads of a Model as functions of the run fraction s."""

    def __init__(self, model, fixed=(), amplitudes=()):
        self.model = model
        self.amplitudes = dict(BUILTIN_AMPLITUDES)
        self.amplitudes.update({a.name: a for a in amplitudes})
        self.fixed = list(fixed)
        for i, f in enumerate(self.fixed):
            self._amplitude(getattr(f, "amplitude", None), f"fixed[{i}]")
        # the default path (no motion, no amplitude on any [[fixed]]): the linear ramp of model.prescribed
        self.moving = any(_moves(f) or getattr(f, "amplitude", None) is not None for f in self.fixed)
        self._groups = self._fixed_groups() if self.moving else []
        self._loads = self._load_groups(model.loads)
        if self.static:
            self._check_static_rotation_steps()

    @property
    def static(self) -> bool:
        return not integrator_kinds.get(self.model.solver.kind).dynamic

    @property
    def duration(self) -> float:
        """The run's length T: steps x dt (dynamic), 1 (static: the pseudo-time is the load factor)."""
        s = self.model.solver
        return 1.0 if self.static else float(s.dt) * int(s.steps)

    # -- amplitudes -------------------------------------------------------------------------------
    def _amplitude(self, name, where) -> Amplitude | None:
        if name is None:
            return None
        try:
            return self.amplitudes[name]
        except KeyError:
            raise TensormassError(f"{where}.amplitude: unknown amplitude {name!r}; known: "
                                  f"{', '.join(self.amplitudes)}") from None

    def factor(self, name: str | None, fraction: float, load: bool = False) -> float:
        """The amplitude `name` at run fraction s; None: the default (ramp; loads in dynamic runs: 1)."""
        if name is None:
            if load and not self.static:
                return 1.0
            return min(max(fraction, 0.0), 1.0)
        amp = self._amplitude(name, "amplitude")
        return amp.value(fraction * self.duration, fraction)

    def _factors(self, name: str | None, fractions: np.ndarray) -> np.ndarray:
        """factor(name, s) at many run fractions (fixed dofs: the clamped ramp by default)."""
        if name is None:
            return np.clip(fractions, 0.0, 1.0)
        amp = self._amplitude(name, "amplitude")
        at = fractions * self.duration if amp.abscissa == "time" else fractions
        return np.interp(at, amp.x, amp.y)

    def _check_static_rotation_steps(self) -> None:
        """Refuse a static run whose load steps turn a prescribed rotation by more than
        MAX_STATIC_ROTATION_STEP degrees (from the rest state to the first step, then step to step)."""
        steps = int(self.model.solver.steps)
        limit = MAX_STATIC_ROTATION_STEP
        for i, f in enumerate(self.fixed):
            rot = getattr(f, "rotation", None)
            if rot is None or not rot.angle:
                continue
            name, angle = getattr(f, "amplitude", None), abs(float(rot.angle))
            turn = self._largest_turn(name, angle, steps)
            if turn <= limit * (1 + 1e-12):
                continue
            head = (f"fixed[{i}].rotation: a static run turns a prescribed rotation by at most {limit:g} degrees "
                    f"per load step (equilibrium under a turned clamp depends on the path: a clamp turned by "
                    f"360 degrees in one step is back where it started and the bar comes out untwisted); "
                    f"angle = {rot.angle:g} degrees")
            first = abs(float(self._factors(name, np.array([0.0]))[0])) * angle
            if first > limit:
                raise TensormassError(f"{head}, and its amplitude {name!r} is already "
                                      f"{first / angle:g} at the start: the first step turns it by {first:g} "
                                      f"degrees whatever the number of steps; start the amplitude at 0")
            need = self._steps_needed(name, angle, steps)
            raise TensormassError(f"{head} over {steps} load step(s) is up to {turn:g} degrees in one "
                                  f"step: use solver.steps >= {need}"
                                  + ("" if name is None else f" (with amplitude {name!r})")
                                  + ", or a dynamic run")

    def _largest_turn(self, name, angle: float, steps: int) -> float:
        """The largest rotation (degrees) of one load step of a static run of `steps` steps."""
        a = np.concatenate([[0.0], self._factors(name, np.arange(1, steps + 1) / steps)])
        return float(np.abs(np.diff(a)).max()) * angle

    def _steps_needed(self, name, angle: float, steps: int) -> int:
        """The fewest load steps (> steps) whose every step turns at most the limit: from the
        amplitude's steepest slope, then checked (and raised) against the steps themselves."""
        limit = MAX_STATIC_ROTATION_STEP
        if name is None:
            slope = 1.0
        else:
            amp = self._amplitude(name, "amplitude")
            x = np.asarray(amp.x, float) / (self.duration if amp.abscissa == "time" else 1.0)
            y = np.asarray(amp.y, float)
            slope = float(np.max(np.abs(np.diff(y)) / np.diff(x))) if len(x) > 1 else 0.0
        need = max(steps + 1, math.ceil(slope * angle / limit * (1 - 1e-12)))
        for _ in range(64):
            if need > 10_000_000 or self._largest_turn(name, angle, need) <= limit * (1 + 1e-12):
                return need
            need = math.ceil(need * 1.25)
        return need

    # -- prescribed displacements -----------------------------------------------------------------
    def _fixed_groups(self) -> list:
        """[(positions in fixed_dofs, entry or None, nodes, components)] for every entry that holds a dof."""
        model = self.model
        owner = getattr(model, "fixed_owner", None)
        if owner is None:
            raise TensormassError("rigid motions and amplitudes on [[fixed]] need model.fixed_owner")
        dofs = model.fixed_dofs
        who = np.asarray(owner).reshape(-1)[dofs]
        groups = []
        for i in np.unique(who):
            pos = np.flatnonzero(who == i)
            entry = None if i < 0 else self.fixed[int(i)]
            nodes, comps = dofs[pos] // model.dim, dofs[pos] % model.dim
            if entry is not None and _moves(entry):
                self._check_dims(entry, int(i))
                # the value at amplitude 1 replaces the zero regions.prescribed_values gave it
                full = rigid_displacement(model.mesh.points[nodes], 1.0, entry.rotation, entry.translation)
                model.prescribed[pos] = full[np.arange(pos.size), comps]
            groups.append((pos, entry, nodes, comps))
        return groups

    def _check_dims(self, entry, i) -> None:
        dim = self.model.dim
        rot, tr = entry.rotation, entry.translation
        if rot is not None and (len(rot.point) != dim or (dim == 3) != (rot.axis is not None)):
            what = "point needs 2 coordinates and no axis" if dim == 2 else "point and axis need 3 coordinates"
            raise TensormassError(f"fixed[{i}].rotation: the mesh is {dim}D: {what}")
        if tr is not None and len(tr) != dim:
            raise TensormassError(f"fixed[{i}].translation: the mesh is {dim}D: give {dim} components")

    def displacement(self, fraction: float) -> np.ndarray:
        """Values of the fixed dofs (model.fixed_dofs order) at run fraction s."""
        model = self.model
        if not self.moving:
            return min(max(fraction, 0.0), 1.0) * model.prescribed
        out = np.empty(model.fixed_dofs.size)
        for pos, entry, nodes, comps in self._groups:
            a = self.factor(None if entry is None else getattr(entry, "amplitude", None), fraction)
            if entry is not None and _moves(entry):
                u = rigid_displacement(model.mesh.points[nodes], a, entry.rotation, entry.translation)
                out[pos] = u[np.arange(pos.size), comps]
            else:
                out[pos] = a * model.prescribed[pos]
        return out

    def boundary_velocity(self, u, s1: float, h: float) -> np.ndarray:
        """Velocity of the fixed dofs over a step of h seconds from the state u to run fraction s1.

        Default path: the constant velocity of the ramp, model.prescribed / T.  Otherwise the
        finite difference from the fixed dofs' current values to their values at s1, so a
        step u + h v puts them exactly on the motion.
        """
        model = self.model
        if not self.moving:
            return model.prescribed / self.duration
        return (self.displacement(s1) - u[model.fixed_dofs]) / h

    # -- loads ------------------------------------------------------------------------------------
    def _load_groups(self, loads) -> list:
        """[(amplitude name or None, force vector)]: the loads of each amplitude, None for those without.

        Empty when no load names an amplitude (then model.f_ext is used as it always was)."""
        names = []
        for _, name in _references([], loads):
            self._amplitude(name, "loads")
            if name not in names:
                names.append(name)
        if not names:
            return []
        return [(name, self._forces_of(self._only(loads, name))) for name in [None] + names]

    @staticmethod
    def _only(loads, name):
        """The loads that follow amplitude `name` (a copy of the Loads with every other load left out)."""
        changes = {}
        for field in dataclasses.fields(loads):
            value = getattr(loads, field.name)
            if isinstance(value, list):
                changes[field.name] = [x for x in value if getattr(x, "amplitude", None) == name]
        if getattr(loads, "gravity_amplitude", None) != name:
            changes["gravity"] = tuple(0.0 for _ in loads.gravity)
        return dataclasses.replace(loads, **changes)

    def _forces_of(self, loads) -> np.ndarray:
        """The model's own load vector for a subset of its loads (the model builds it as always)."""
        model = self.model
        saved = model.loads
        model.loads = loads
        try:
            return model._external_forces()
        finally:
            model.loads = saved

    def forces(self, fraction: float) -> np.ndarray:
        """External force vector at run fraction s (static default: s f_ext; dynamic default: f_ext)."""
        model = self.model
        if not self._loads:
            return fraction * model.f_ext if self.static else model.f_ext
        out = np.zeros_like(model.f_ext)
        for name, f in self._loads:
            # no amplitude: the load factor itself (static, not clamped, as before) or 1 (dynamic)
            a = (fraction if self.static else 1.0) if name is None else self.factor(name, fraction, load=True)
            out += a * f
        return out

    def work(self, u, time: float) -> float:
        """f . u of the loads acting now (default: the full loads f_ext, as the energy balance always used)."""
        model = self.model
        with np.errstate(over="ignore", invalid="ignore"):
            if not self._loads:
                return float(model.f_ext @ u)
            return float(self.forces(self.fraction(time)) @ u)

    def fraction(self, time: float) -> float:
        return time / self.duration

    # -- scales (health monitor) ------------------------------------------------------------------
    def _samples(self) -> np.ndarray:
        """Run fractions where the motion's extremes are sought: every table point and 64 intervals."""
        s = list(np.linspace(0.0, 1.0, 65))
        for a in self.amplitudes.values():
            s.extend(x / self.duration if a.abscissa == "time" else x for x in a.x)
        s = np.unique(np.clip(s, 0.0, 1.0))
        return s

    def peak_forces(self) -> np.ndarray:
        """A load vector as large as any the run applies (each amplitude at its largest |value|)."""
        model = self.model
        if not self._loads:
            return model.f_ext
        out = np.zeros_like(model.f_ext)
        for name, f in self._loads:
            out += (1.0 if name is None else self._amplitude(name, "loads").peak()) * np.abs(f)
        return out

    def peak_displacement(self) -> np.ndarray:
        """The fixed dofs' values at the sampled run fraction where they are largest (default: model.prescribed)."""
        if not self.moving:
            return self.model.prescribed
        values = [self.displacement(s) for s in self._samples()]
        return max(values, key=lambda v: float(np.linalg.norm(v)))

    def peak_velocity(self) -> np.ndarray:
        """The fixed dofs' largest velocity between sampled run fractions (default: model.prescribed / T)."""
        if not self.moving:
            return self.model.prescribed / self.duration
        s = self._samples()
        d = [self.displacement(x) for x in s]
        v = [(d[i + 1] - d[i]) / ((s[i + 1] - s[i]) * self.duration) for i in range(len(s) - 1)]
        return max(v, key=lambda x: float(np.linalg.norm(x))) if v else np.zeros_like(d[0])
