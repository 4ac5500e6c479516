"""GPU benchmark: the cuda backend and solver.device = "cuda" against the CPU, measured in the same run.

    tensormass bench gpu [--json FILE] [--quick] [--host] [--organ-mesh FILE]

Each line is a target of the GPU work: the device's number, the CPU baseline measured beside it, their
ratio and the target:
  kernels   forces + stiffness rates (elements/s) on device arrays (no transfers): tetra neo-Hookean
            gauss1, tetra10 and hexahedron gauss2; the CPU: the C backend on one thread
  assembly  the fused f + K into CSR of the 384 000-tetra cube: colour launches on the device; the CPU:
            the run's Assembler on every core
  step      the tetra organ's implicit Euler step (h = 6 mm): the device step alone (DeviceStep) and a
            run's step with solver.device = "cuda", against the CPU run's step (PARDISO or SuperLU); and
            the largest difference of the two runs' displacements over 10 steps, relative
  large     the device step of a 1 000 000-tetra body
  scaling   device and CPU step time over body size (the thesis' B15 curve): JSON, and a PNG beside it
  threads   what one thread of each kernel uses on sm_90 (registers, spills, stack), from NVRTC's ptxas
            report: no GPU needed (printed wherever NVRTC is installed)
--host runs every line on the host shim (numpy arrays, the CUDA files compiled as C) at small sizes:
it checks that the benchmark runs, on a machine without a GPU. Its times are not GPU times.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..runtime.base.errors import TensormassError
from ..runtime.base.files import write_json_atomic
from ..runtime.run.simulation import Simulation
from ..runtime.scene.scene import Scene
from ..runtime.solve import device as device_module
from .machine import machine_info

E, NU, DENSITY, DT = 3.0e3, 0.45, 1000.0, 0.01          # the organ's material (apps.bench_organ)
KERNELS = (("tetra", "neohookean", "gauss1", 2_000_000), ("tetra10", "neohookean", "gauss2", 200_000),
           ("hexahedron", "neohookean", "gauss2", 200_000))
CPU_ELEMENTS = 50_000              # the CPU baseline's batch (its rate does not depend on the count)
CUBE = 40                          # 40 x 40 x 40 x 6 = 384 000 tetra
LARGE = (70, 70, 34)               # x 6 = 999 600 tetra
SCALING = ((8, 4, 4), (16, 8, 8), (24, 12, 12), (32, 16, 16), (48, 24, 24))
TARGETS = {"tetra_neohookean_gauss1": 300e6, "tetra10_neohookean_gauss2": 40e6,
           "hexahedron_neohookean_gauss2": 40e6, "assembly_s": 5e-3, "organ_step_s": 2e-3, "large_step_s": 50e-3,
           "trajectory": 1e-8}
QUICK = {"kernel_elements": 2000, "cube": 6, "large": None, "scaling": ((4, 2, 2), (6, 3, 3)), "repeats": 2}


def _device(host: bool):
    return device_module.host_device() if host else device_module.get_device("cuda")


def _timed(call, device, repeats: int) -> float:
    """Best wall time of call() over repeats, the device drained after each."""
    best = np.inf
    for _ in range(repeats):
        device.synchronize()
        t0 = time.perf_counter()
        call()
        device.synchronize()
        best = min(best, time.perf_counter() - t0)
    return best


def _elements(element, n, seed=0):
    from ..runtime.base.samples import random_elements
    return random_elements(element, n, seed=seed, distortion=0.0)      # affine images: never inverted


def kernel_rates(device, n_elements: int | None, repeats: int) -> list:
    import tensormass as tm
    rows = []
    for element, law, quadrature, full in KERNELS:
        n = n_elements or full
        c = tm.load_kernel(element, law, quadrature, backend="c")
        module = device.load(element, law, quadrature)
        X = _elements(element, min(n, CPU_ELEMENTS))
        D_cpu = c.constants(X, E=E, nu=NU)
        u_cpu = 0.01 * np.random.default_rng(1).standard_normal((len(X), c.n_dofs))
        cpu = _timed(lambda: c.forces_and_stiffness(D_cpu, u_cpu), device_module.host_device(), repeats)
        xp = device.xp
        reps = -(-n // len(X))
        D = xp.asarray(np.tile(D_cpu, (reps, 1))[:n])
        u = xp.asarray(np.tile(u_cpu, (reps, 1))[:n])
        f, K, flags = xp.zeros((n, c.n_dofs)), xp.zeros((n, c.n_dofs, c.n_dofs)), xp.zeros(n, dtype=np.int32)
        gpu = _timed(lambda: module.forces_and_stiffness(D, u, f, K, flags), device, repeats)
        name = f"{element}_{law}_{quadrature}"
        rows.append({"name": name, "elements": n, "device_rate": n / gpu, "cpu_rate": len(X) / cpu,
                     "ratio": (n / gpu) / (len(X) / cpu), "target": TARGETS[name]})
    return rows


def _bar_scene(cells, element="tetra", steps=10, device=None, linear=None, size=None) -> str:
    size = size or (0.04 * cells[0] / max(cells), 0.04 * cells[1] / max(cells), 0.04 * cells[2] / max(cells))
    solver = ['kind = "implicit_euler"', f"dt = {DT}", f"steps = {steps}"]
    solver += [f'device = "{device}"', "cg_tolerance = 1e-12", "cg_max_iterations = 20000"] if device else []
    solver += [f'linear = "{linear}"'] if linear else []
    return f"""
name = "gpu_bar"
[mesh]
generate = "bar"
size = {list(size)}
cells = {list(cells)}
element = "{element}"
[[material]]
law = "neohookean"
quadrature = "gauss1"
E = {E}
nu = {NU}
density = {DENSITY}
[[fixed]]
box = [[-1e-9, -1, -1], [1e-9, 1, 1]]
[loads]
gravity = [0.0, 0.0, -9.81]
[solver]
""" + "\n".join(solver) + "\n"


def _run(text: str, device, on_step=None) -> tuple:
    """(simulation, summary) of a finished run of text whose device (solver.device) is the benchmark's
    (the host shim with --host)."""
    from ..runtime.physics.device_euler import DeviceImplicitEuler
    saved = DeviceImplicitEuler.__dict__["device_factory"]
    DeviceImplicitEuler.device_factory = staticmethod(lambda name: device)
    try:
        sim = Simulation(Scene.from_string(text), output=False, on_step=on_step)
        summary = sim.run()
    finally:
        DeviceImplicitEuler.device_factory = saved
    return sim, summary


def assembly(device, cube: int, repeats: int) -> dict:
    sim, _ = _run(_bar_scene((cube, cube, cube), steps=1, device="cuda"), device)
    system = sim.integrator.system
    u = 1e-4 * np.random.default_rng(2).standard_normal(sim.model.n_dofs)
    ud = device.xp.asarray(u)
    gpu = _timed(lambda: system.assemble(ud), device, repeats)
    asm = sim.ctx.asm
    cpu = _timed(lambda: asm.forces_and_stiffness(u), device_module.host_device(), repeats)
    f_dev, data_dev = system.assemble(ud)
    f, data = asm.forces_and_stiffness(u)
    difference = float(np.abs(device_module._host(data_dev) - data).max() / np.abs(data).max())
    return {"cells": int(sim.model.n_elements), "dofs": int(sim.model.n_dofs), "device_s": gpu, "cpu_s": cpu,
            "ratio": cpu / gpu, "colours": [p.n_colours for p in system.parts], "K_difference": difference,
            "target_s": TARGETS["assembly_s"]}


def _run_steps(text: str, device):
    """(displacement after each step, per-step walls) of a run of text."""
    frames = []
    _, summary = _run(text, device, on_step=lambda sim: frames.append(np.array(sim.dofs).reshape(-1)))
    return frames, list(summary.per_step["wall"])


def step_case(device, text_cpu: str, text_device: str, name: str, steps: int = 10) -> dict:
    """The run's step on the device and on the CPU (same scene), their displacements compared, and the
    device step alone (DeviceStep on the same mesh)."""
    cpu_frames, cpu_walls = _run_steps(text_cpu, device)
    dev_frames, dev_walls = _run_steps(text_device, device)
    scale = max(float(np.abs(f).max()) for f in cpu_frames)
    difference = max(float(np.abs(a - b).max()) for a, b in zip(cpu_frames, dev_frames)) / scale
    alone = device_step_time(device, text_device, repeats=max(steps - 1, 1))
    return {"name": name, "steps": steps, "cpu_step_s": float(np.median(cpu_walls[1:])),
            "run_step_s": float(np.median(dev_walls[1:])), "device_step_s": alone["device_step_s"],
            "cells": alone["cells"], "dofs": alone["dofs"], "cg_iterations": alone["cg_iterations"],
            "trajectory_difference": difference}


def device_step_time(device, text: str, repeats: int) -> dict:
    """DeviceStep.advance on the scene's mesh (clamped, gravity, lumped masses): every array on the device."""
    import tensormass as tm
    model = Simulation(Scene.from_string(text), output=False).model
    part = model.parts[0]
    k = part.kernel
    params = k._params(part.n_active, E, NU, {})
    mass = model.mass_matrix.lumped.reshape(-1, model.dofs_per_node)[:, 0]
    fixed = np.unique(model.fixed_dofs // model.dofs_per_node)
    step = device_module.DeviceStep(device, model.mesh.points, part.cells_active, tm.load_kernel(
        k.element, k.law, k.quadrature, backend="c"), params, fixed, mass, DT, (0.0, 0.0, -9.81), tolerance=1e-8)
    step.advance()                                  # the first: graphs captured, caches warm
    seconds = _timed(step.advance, device, repeats)
    return {"cells": int(part.n_active), "dofs": int(model.n_dofs), "device_step_s": seconds,
            "cg_iterations": int(step.iterations[-1])}


def scaling(device, bodies, repeats: int) -> list:
    rows = []
    for cells in bodies:
        text_cpu = _bar_scene(cells, steps=repeats + 1)
        _, walls = _run_steps(text_cpu, device)
        alone = device_step_time(device, _bar_scene(cells, device="cuda"), repeats)
        rows.append({"cells": alone["cells"], "dofs": alone["dofs"], "cpu_step_s": float(np.median(walls[1:])),
                     "device_step_s": alone["device_step_s"]})
    return rows


def organ_texts(mesh: Path) -> tuple[str, str]:
    from .bench_organ import organ_text
    base = {"kind": "implicit_euler", "steps": 10, "dt": DT}
    return (organ_text("organ_cpu", mesh, "gauss1", base),
            organ_text("organ_device", mesh, "gauss1", {**base, "device": "cuda", "cg_tolerance": 1e-12,
                                                        "cg_max_iterations": 20000}))


def organ_mesh_file(path: str | None) -> Path | None:
    if path:
        return Path(path)
    from .bench_organ import CASES, GmshMissing, organ_mesh
    try:
        return organ_mesh(next(c for c in CASES if c.name == "tetra_h6_implicit_euler"))[0]
    except GmshMissing:
        return None


def thread_resources(arch: str = "sm_90") -> list | None:
    """Registers, spills and stack of forces_and_stiffness and the fused scatter of each KERNELS entry
    and of the CG's kernels, compiled by NVRTC for arch (None without NVRTC)."""
    import tempfile
    from .. import backends
    from ..backends.cuda import loader
    from ..runtime.kernels.kernels import kernel_source
    rows = []
    try:
        with tempfile.TemporaryDirectory(prefix="tensormass-nvrtc-") as folder:
            for element, law, quadrature, _ in KERNELS:
                _, record = loader.compile_cubin(kernel_source(element, law, quadrature, "cuda"), arch, Path(folder))
                for kind in ("forces_and_stiffness", "forces_and_stiffness_scatter"):
                    rows.append({"kernel": f"{element}_{law}_{quadrature}", "function": kind,
                                 "seconds": record["seconds"], **record["resources"][kind]})
            _, record = loader.compile_cubin(loader.PCG_SOURCE, arch, Path(folder), name="tm_pcg")
            for name, r in sorted(record["resources"].items()):
                rows.append({"kernel": "device CG", "function": name, "seconds": record["seconds"], **r})
    except backends.BackendError:
        return None
    return rows


def run_gpu_bench(quick=False, host=False, organ_mesh=None, json_path=None, progress=print) -> dict:
    device = _device(host)
    small = quick or host
    repeats = QUICK["repeats"] if small else 5
    report = {"machine": machine_info(), "device": device.name, "quick": small}
    progress(f"device: {device.name}" + (" (times are the host's, not a GPU's)" if host else ""))
    report["kernels"] = kernel_rates(device, QUICK["kernel_elements"] if small else None, repeats)
    for r in report["kernels"]:
        progress(f"kernels  {r['name']:<30} {r['device_rate'] / 1e6:9.2f} M el/s  CPU one thread "
                 f"{r['cpu_rate'] / 1e6:7.2f}  x{r['ratio']:7.1f}  (target {r['target'] / 1e6:g} M el/s)")
    a = report["assembly"] = assembly(device, QUICK["cube"] if small else CUBE, repeats)
    progress(f"assembly {a['cells']} tetra, {a['dofs']} dofs: {1e3 * a['device_s']:.2f} ms  CPU "
             f"{1e3 * a['cpu_s']:.2f} ms  x{a['ratio']:.1f}  ({len(a['colours'])} part(s), colours {a['colours']}; "
             f"K differs by {a['K_difference']:.1e}; target {1e3 * a['target_s']:g} ms)")
    mesh = None if small else organ_mesh_file(organ_mesh)
    if mesh is not None:
        text_cpu, text_device = organ_texts(mesh)
        name = f"organ {mesh.name}"
    else:
        cells = (12, 3, 5) if small else (24, 6, 12)
        text_cpu, text_device = _bar_scene(cells), _bar_scene(cells, device="cuda")
        name = f"bar {cells} (no organ mesh: gmsh missing and no --organ-mesh)" if not small else f"bar {cells}"
    s = report["step"] = step_case(device, text_cpu, text_device, name)
    progress(f"step     {s['name']}: {s['cells']} cells, {s['dofs']} dofs: device step {1e3 * s['device_step_s']:.2f} ms "
             f"({s['cg_iterations']} CG iterations), run step {1e3 * s['run_step_s']:.2f} ms, CPU run step "
             f"{1e3 * s['cpu_step_s']:.2f} ms; displacements differ by {s['trajectory_difference']:.1e} "
             f"(targets {1e3 * TARGETS['organ_step_s']:g} ms, {TARGETS['trajectory']:g})")
    large = None if small else LARGE
    if large is not None:
        r = report["large"] = device_step_time(device, _bar_scene(large, device="cuda"), repeats)
        progress(f"large    {r['cells']} tetra, {r['dofs']} dofs: device step {1e3 * r['device_step_s']:.1f} ms "
                 f"({r['cg_iterations']} CG iterations; target {1e3 * TARGETS['large_step_s']:g} ms)")
    report["shells"] = "not built: the co-rotational shell step runs on the CPU"
    progress(f"shells   {report['shells']}")
    report["scaling"] = scaling(device, QUICK["scaling"] if small else SCALING, repeats)
    for r in report["scaling"]:
        progress(f"scaling  {r['cells']:>8} tetra: device step {1e3 * r['device_step_s']:9.2f} ms, CPU run step "
                 f"{1e3 * r['cpu_step_s']:9.2f} ms, x{r['cpu_step_s'] / r['device_step_s']:.1f}")
    report["threads"] = thread_resources()
    for r in report["threads"] or []:
        progress(f"threads  {r['kernel']:<30} {r['function']:<30} {r['registers']:>4} registers, "
                 f"{r['spill_bytes']:>5} B spilled, {r['stack_bytes']:>5} B stack (sm_90)")
    if report["threads"] is None:
        progress("threads  NVRTC is not installed: no ptxas report (pip install 'tensormass[cuda]')")
    if json_path:
        write_json_atomic(json_path, report)
        _plot(report["scaling"], Path(json_path).with_suffix(".png"), device.name)
    return report


def _plot(rows, path: Path, device_name: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cells = [r["cells"] for r in rows]
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    ax.loglog(cells, [1e3 * r["cpu_step_s"] for r in rows], "o-", label="CPU (run step)")
    ax.loglog(cells, [1e3 * r["device_step_s"] for r in rows], "s-", label=f"{device_name} (device step)")
    ax.set_xlabel("tetrahedra")
    ax.set_ylabel("implicit Euler step (ms)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def cmd_gpu(args) -> int:
    try:
        run_gpu_bench(quick=args.quick, host=args.host, organ_mesh=args.organ_mesh, json_path=args.json)
    except TensormassError as error:
        print(f"tensormass: error: {error}")
        return 2
    return 0


def add_gpu_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("gpu", help="the cuda backend and solver.device = \"cuda\" against the CPU "
                                    "(kernel rates, assembly, implicit Euler step, scaling)")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON (and the scaling plot as FILE.png)")
    p.add_argument("--quick", action="store_true", help="small bodies")
    p.add_argument("--host", action="store_true", help="run on the host shim (no GPU needed; times are not a GPU's)")
    p.add_argument("--organ-mesh", metavar="FILE", help="the h = 6 mm tetra organ mesh (else made with gmsh)")
    p.set_defaults(run=cmd_gpu)
