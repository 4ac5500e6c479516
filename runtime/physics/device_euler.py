"""Linearised implicit Euler with its Newton system on a device ([solver] device = "cuda").

The step is ImplicitEuler's, (M' + (h beta + h^2) K) dv = h (f - h K v), with K assembled by the cuda
backend's fused kernels colour by colour and solved by Jacobi-preconditioned CG on the device
(runtime.solve.device). The stiffness stays on the device; per step the state (u, v), the external
forces and the fixed dofs' velocities go up, and dv and the step's residual (the reactions) come back,
so probes, history, health checks and frames run on the host as in any run.
"""
from __future__ import annotations

import time

import numpy as np

from ..base.errors import TensormassError
from .integrators import ImplicitEuler, make_integrator as make_cpu_integrator


class DeviceImplicitEuler(ImplicitEuler):
    kind = "implicit_euler"

    # device_factory(name) -> the Device to run on: runtime.solve.device.get_device when None (tests and
    # `bench gpu --host` point it at the host shim); imported here, not at the top: runs without a
    # device never load the device system
    device_factory = None

    def __init__(self, ctx):
        super().__init__(ctx)
        from ..solve import device as _device
        s = self.model.solver
        self.device = (self.device_factory or _device.get_device)(s.device)
        self.system = None
        self._cg_tolerance, self._cg_max = float(s.cg_tolerance), int(s.cg_max_iterations)

    def _build(self):
        from ..solve import device as _device
        ctx, model = self.ctx, self.model
        asm = ctx.asm
        parts = []
        for part, plan in zip(model.parts, asm.plans):
            if not part.n_active:
                continue
            k = part.kernel
            if getattr(k, "module", None) is None or plan.blocks is None:
                raise TensormassError(f"solver.device: law {part.law!r} on {k.element} has no generated fused kernel "
                                      "(hand-written kernels run on the CPU)")
            module = self.device.load(k.element, k.law, k.quadrature)
            parts.append((module, plan.D, plan.cells, plan.blocks, part.cell_ids_active))
        mass = self.mass.add_to(np.zeros(asm.pattern.nnz), asm.pattern, 1.0)
        return _device.DeviceSystem(self.device, asm.pattern, parts, mass, model.fixed_dofs,
                                    self._cg_tolerance, self._cg_max)

    def single(self, u, v, t, h):
        ctx = self.ctx
        if self.system is None:
            self.system = self._build()
        f_ext = self.external_force((t + h) / self.duration)
        dv_c = self.boundary_velocity(u, t, h) - v[self.model.fixed_dofs]
        start = time.perf_counter()
        dv, residual, its = self.system.implicit_euler(u, v, f_ext, dv_c, h, self.alpha, self.beta)
        ctx.linear.time += time.perf_counter() - start      # statistics only
        ctx.linear.counts["device-cg"] = ctx.linear.counts.get("device-cg", 0) + 1
        ctx.linear_iterations += its
        ctx.newton_iterations += 1
        v1 = v + dv
        u1 = u + h * v1
        ctx.residual = (u1, ctx.reduce(residual))
        return u1, v1


def make_integrator(ctx):
    """The run's integrator: the device step where solver.device names a device, else the CPU's
    integrator of solver.kind (the scene parser allows a device with implicit_euler only)."""
    if getattr(ctx.model.solver, "device", "cpu") != "cpu":
        return DeviceImplicitEuler(ctx)
    return make_cpu_integrator(ctx)
