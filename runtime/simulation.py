"""Run a scene (or a ready Model) from setup to summary.

    sim = Simulation(scene, progress=lambda k, n: ..., writer=vtu_writer)
    summary = sim.run()                  # Summary; summary.to_dict() for JSON
    sim.displacement                     # (n_points, dim) at the end

Setup (model, kernel loading and compilation, sparsity pattern, colouring,
stable step estimate) is timed apart from stepping, so reports can tell
one-off costs from per-step costs.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np

from .adapt import MAX_STATIC_PASSES, Adapter
from .errors import TensormassError
from .integrators import Context, Explicit, make_integrator, stable_time_step
from .model import Model

__all__ = ["Simulation", "Summary"]


@dataclass
class Summary:
    """What a run did and what it cost; dict-like (summary["probes"]) and JSON-ready via to_dict()."""
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
    energy: float | None                  # final elastic energy (None: explicit loads no energy kernel)
    kinetic_energy: float | None          # final, dynamic solvers only
    stable_dt: float | None               # explicit only: estimated critical step at rest
    per_step: dict = field(default_factory=dict)
    adapt: dict | None = None             # [[adapt]] rules: switches, splits and their events

    def to_dict(self) -> dict:
        return asdict(self)

    def __getitem__(self, key):
        return getattr(self, key)

    def keys(self):
        return self.to_dict().keys()


class Simulation:
    """One run: `Simulation(scene_or_model).run()`.

    writer: optional object with write_frame(step, time, points, displacement,
    fields) and close(), called at step 0, every output.every steps and at the
    last step (and closed even when the run fails).  progress(step, n_steps) is
    called after every step.  u0 / v0: optional initial displacement and velocity
    ((n_points, dim) or flat).
    """

    def __init__(self, scene_or_model, progress=None, writer=None, u0=None, v0=None):
        start = time.perf_counter()
        if isinstance(scene_or_model, Model):
            self.model = scene_or_model
            self._setup = scene_or_model.build_time
        else:
            self.model = Model.from_scene(scene_or_model)
            self._setup = time.perf_counter() - start
        self.progress, self.writer = progress, writer
        self.adapter = Adapter(self.model) if self.model.adapt else None
        self._u0, self._v0 = self._initial(u0), self._initial(v0)
        self.ctx = None
        self.stable_dt = None
        self.summary = None

    def _initial(self, x):
        if x is None:
            return None
        x = np.asarray(x, dtype=float).reshape(-1)
        if x.size != self.model.n_dofs or not np.all(np.isfinite(x)):
            raise TensormassError(f"initial state must be {self.model.n_points} x {self.model.dim} finite values")
        return x.copy()

    # -- state ------------------------------------------------------------------------------------
    @property
    def displacement(self) -> np.ndarray:
        u = self.ctx.u if self.ctx is not None else (self._u0 if self._u0 is not None else np.zeros(self.model.n_dofs))
        return u.reshape(self.model.n_points, self.model.dim).copy()

    @property
    def velocity(self) -> np.ndarray:
        v = self.ctx.v if self.ctx is not None else np.zeros(self.model.n_dofs)
        return v.reshape(self.model.n_points, self.model.dim).copy()

    # -- run --------------------------------------------------------------------------------------
    def _prepare(self):
        """Everything before the first step: assembly pattern, compilation, initial state."""
        model = self.model
        self.ctx = ctx = Context(model)
        model.warm_up()
        ctx.asm.warm_up()
        self.integrator = make_integrator(ctx)
        if self._u0 is not None:
            ctx.u = self._u0.copy()
        if self._v0 is not None:
            ctx.v = self._v0.copy()
        if isinstance(self.integrator, Explicit):
            self.stable_dt = self.integrator.stable_dt = stable_time_step(ctx)
        ctx.asm.time = ctx.linear.time = 0.0         # stepping costs only from here on

    def run(self) -> Summary:
        start = time.perf_counter()
        try:
            self._prepare()
            setup = self._setup + time.perf_counter() - start
            history = self._loop()
        finally:
            if self.writer is not None:
                self.writer.close()
        total = setup + sum(history["wall"])
        self.summary = self._summarise(setup, total, history)
        return self.summary

    def _loop(self) -> dict:
        integ, model = self.integrator, self.model
        history = {k: [] for k in ("time", "newton", "wall", "elastic", "kinetic", "external_work")}
        self._write(0)
        for k in range(1, integ.n_steps + 1):
            t0 = time.perf_counter()
            info = integ.step(k)
            if self.adapter is not None:
                self._adapt(k)
                integ, model = self.integrator, self.model      # refinement rebuilds both
            history["wall"].append(time.perf_counter() - t0)
            history["time"].append(info["time"])
            history["newton"].append(info["newton"])
            for key, value in self._energies().items():
                history[key].append(value)
            if k % max(model.output.every, 1) == 0 or k == integ.n_steps:
                self._write(k)
            if self.progress is not None:
                self.progress(k, integ.n_steps)
        return history

    # -- adaptation -----------------------------------------------------------------------------
    def _adapt(self, k: int) -> None:
        """Apply the [[adapt]] rules after step k.

        Static: the last load step is re-solved until nothing changes (the answer is the
        equilibrium of the adapted model); earlier load steps only pass their switches on
        to the next step, which costs no extra Newton iterations.
        """
        static = self.model.solver.kind == "static" and k == self.integrator.n_steps
        for _ in range(MAX_STATIC_PASSES if static else 1):
            change = self.adapter.update(self.ctx, k)
            if change.model is not None:
                self._rebuild(change.model, change.parents)
            if not change or not static:
                return
            self.integrator.step(k)          # equilibrium of the adapted model at the same load

    def _rebuild(self, model, parents) -> None:
        """Carry the state and the counters over to a refined model (new pattern, masses, constants)."""
        from .refine import interpolate_nodal
        old, dim = self.ctx, model.dim
        ctx = Context(model)
        model.warm_up()
        ctx.asm.warm_up()
        ctx.u = interpolate_nodal(old.u.reshape(-1, dim), parents).ravel()
        ctx.v = interpolate_nodal(old.v.reshape(-1, dim), parents).ravel()
        ctx.t = old.t
        ctx.newton_iterations, ctx.linear_iterations = old.newton_iterations, old.linear_iterations
        ctx.asm.time, ctx.linear.time = old.asm.time, old.linear.time
        self.model, self.ctx = model, ctx
        self.integrator = make_integrator(ctx)
        if isinstance(self.integrator, Explicit):
            self.stable_dt = self.integrator.stable_dt = stable_time_step(ctx)
        if self.writer is not None and hasattr(self.writer, "set_mesh"):
            self.writer.set_mesh(model.mesh)

    def _energies(self) -> dict:
        """Elastic, kinetic and external work at the current state (not counted as assembly time)."""
        ctx, model = self.ctx, self.model
        saved = ctx.asm.time
        elastic = ctx.asm.energy(ctx.u) if "energy" in model.outputs else None
        ctx.asm.time = saved
        kinetic = 0.5 * float(ctx.v @ (model.mass * ctx.v)) if model.solver.kind != "static" else None
        return {"elastic": elastic, "kinetic": kinetic, "external_work": float(model.f_ext @ ctx.u)}

    def _write(self, step: int):
        if self.writer is None:
            return
        fields = {} if self.model.solver.kind == "static" else {"velocity": self.velocity}
        if self.adapter is None:
            self.writer.write_frame(step, self.ctx.t, self.model.mesh.points, self.displacement, fields)
        else:                                # watch the criteria and the law of each cell in ParaView
            self.writer.write_frame(step, self.ctx.t, self.model.mesh.points, self.displacement, fields,
                                    cell_fields=self.adapter.cell_fields(self.ctx))

    def _summarise(self, setup, total, history) -> Summary:
        ctx, model = self.ctx, self.model
        last = lambda key: history[key][-1] if history[key] else None  # noqa: E731
        return Summary(
            name=model.name, solver=model.solver.kind, steps=self.integrator.n_steps,
            n_dofs=model.n_dofs, n_free_dofs=int(model.free_dofs.size),
            n_elements=model.n_elements, kernels=model.kernel_info(),
            time={"setup": setup, "first_step": history["wall"][0] if history["wall"] else 0.0,
                  "assembly": ctx.asm.time, "linear_solve": ctx.linear.time, "total": total},
            iterations={"newton": ctx.newton_iterations, "linear": ctx.linear_iterations},
            probes=model.probe_values(ctx.u), energy=last("elastic"), kinetic_energy=last("kinetic"),
            stable_dt=self.stable_dt, per_step=history,
            adapt=None if self.adapter is None else self.adapter.summary(model))
