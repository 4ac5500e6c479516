"""`tensormass bench assembly`: full Newton assembly (forces and stiffness of every element added
into the global force vector and CSR values) on unit cubes, three ways, numba and C:

  kernel   the generated forces_and_stiffness into preallocated element buffers (no gather, no
           scatter): the kernel-only rate every assembly is compared with;
  buffers  what the runtime does today: gather u through cells, the kernel into preallocated
           element buffers (n_elem, n_dofs, n_dofs), then runtime.assembly.assembly's serial scatter
           through the per-entry map;
  fused    the generated forces_and_stiffness_scatter: u read through cells, f and K added
           straight into the global arrays through the node-blocked map (runtime/kernels/fused.py);
  runtime  what a run calls: runtime.assembly.assembly.Assembler.forces_and_stiffness of a Model on the
           mesh (it takes the fused path), on one thread and on every thread runtime.base.parallel
           offers (the two must give the same bytes: checked).

Cases: the 40 x 40 x 40 x 6 = 384 000-tetra neo-Hookean cube (SymX's NeoHookean assembly
comparison: 138-174 ms on this machine class; the issue's target is <= 90 ms, or assembly >=
70 % of the kernel-only rate), and tetra10 and hexahedron cubes with about as many dofs.
One thread; every time is the best of a few short runs, all in one run, so ratios compare.
The report says which path is faster per element type (a measurement for the lead's fixed
table: the runtime never chooses from timings).
"""
from __future__ import annotations

import time

import numpy as np

from ..runtime.assembly.assembly import SparsePattern, scatter_matrix, scatter_vector
from ..runtime.base.dofs import node_dofs
from ..runtime.base.errors import TensormassError
from ..runtime.kernels.fused import block_positions
from ..runtime.kernels.kernels import load_kernel
from ..runtime.mesh.bars import generate_bar
from ..runtime.base.files import write_json_atomic
from .machine import machine_info
from ..runtime.base import parallel
from ..runtime.assembly.assembly import Assembler
from ..runtime.model.model import Model
from ..runtime.scene.types import Material, Solver

LAW = "neohookean"
# name: (element, quadrature, cubes per side)
CASES = {
    "tetra_384k": ("tetra", "gauss1", 40),          # 384 000 tetra, 68 921 nodes
    "tetra10_48k": ("tetra10", "gauss2", 20),       # 48 000 tetra10, 68 921 nodes
    "hexahedron_64k": ("hexahedron", "gauss2", 40),  # 64 000 hexahedra, 68 921 nodes
}
QUICK_CASES = {
    "tetra_3k": ("tetra", "gauss1", 8),
    "tetra10_384": ("tetra10", "gauss2", 4),
    "hexahedron_512": ("hexahedron", "gauss2", 8),
}
BACKENDS = ("numba", "c")
PATHS = ("kernel", "buffers", "fused")
REPEATS, QUICK_REPEATS = 3, 2
SYMX_MS = (138.0, 174.0)          # SymX NeoHookean_assembly_comparison, 384k tetra (issue 13)
TARGET_MS = 90.0
TARGET_RATIO = 0.70


def _best(call, repeats: int) -> float:
    call()                                  # compile / warm the caches
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        call()
        best = min(best, time.perf_counter() - t0)
    return best


def run_case(name, element, quadrature, n, backends=BACKENDS, repeats=REPEATS, progress=print) -> dict:
    mesh = generate_bar((1.0, 1.0, 1.0), (n, n, n), element)
    cells = mesh.blocks[0].cells
    points = mesh.points
    dim = points.shape[1]
    n_elem = len(cells)
    dofs = node_dofs(cells, dim)
    t0 = time.perf_counter()
    pattern = SparsePattern([dofs], points.shape[0] * dim)
    full = pattern.positions[0]
    pos = block_positions(full, dim)
    setup = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    # a smooth stretch and twist plus noise of 1 % of the cube edge: deformed, nothing inverted
    x, y, z = points.T
    U = 0.1 * np.stack([x * y, np.sin(z), 0.5 * x * z], axis=1) + (0.01 / n) * rng.standard_normal(points.shape)
    result = {"element": element, "law": LAW, "quadrature": quadrature, "cells": n_elem,
              "nodes": int(points.shape[0]), "dofs": int(U.size), "nnz": int(pattern.nnz),
              "pattern_setup_s": setup, "backends": {}}
    progress(f"{name}: {n_elem} {element} cells, {U.size} dofs, {pattern.nnz} nonzeros "
             f"(pattern and node-blocked map built in {setup:.2f} s)")
    for backend in backends:
        k = load_kernel(element, LAW, quadrature, backend=backend)
        module = k.module
        D = k.constants(points[cells], E=1.0e6, nu=0.3)
        nd = k.n_dofs
        u = np.empty((n_elem, k.n_nodes, dim))
        fe, Ke = np.empty((n_elem, nd)), np.empty((n_elem, nd, nd))
        f, data = np.zeros(U.size), np.zeros(pattern.nnz)
        flags = np.zeros(n_elem, dtype=np.int32)
        np.take(U, cells, axis=0, out=u)

        def kernel_only():
            module.forces_and_stiffness(D, u, fe, Ke, flags)

        def buffers():
            np.take(U, cells, axis=0, out=u)
            module.forces_and_stiffness(D, u, fe, Ke, flags)
            f.fill(0.0)
            data.fill(0.0)
            scatter_vector(f, fe, dofs)
            scatter_matrix(data, Ke, full, 1.0)

        def fused():
            f.fill(0.0)
            data.fill(0.0)
            module.forces_and_stiffness_scatter(D, U, cells, pos, f, data, flags)

        times = {"kernel": _best(kernel_only, repeats), "buffers": _best(buffers, repeats)}
        f_ref, data_ref = f.copy(), data.copy()
        times["fused"] = _best(fused, repeats)
        if not (np.array_equal(f, f_ref) and np.array_equal(data, data_ref)):
            raise TensormassError(f"{name} ({backend}): the fused assembly differs from buffers + scatter")
        if flags.any():
            raise TensormassError(f"{name} ({backend}): inverted elements in the benchmark state")
        rates = {p: n_elem / t for p, t in times.items()}
        row = {"ms": {p: 1e3 * t for p, t in times.items()}, "elements_per_s": rates,
               "ratio_to_kernel": {p: rates[p] / rates["kernel"] for p in ("buffers", "fused")},
               "faster": min(("buffers", "fused"), key=lambda p: times[p])}
        result["backends"][backend] = row
        progress(f"  {backend:5s} kernel {row['ms']['kernel']:8.1f} ms | buffers+scatter {row['ms']['buffers']:8.1f} ms "
                 f"({row['ratio_to_kernel']['buffers']:.0%} of kernel rate) | fused {row['ms']['fused']:8.1f} ms "
                 f"({row['ratio_to_kernel']['fused']:.0%}) -> {row['faster']} faster")
        fe = Ke = u = None                  # free the element buffers before the runtime rows
        row.update(_runtime_rows(mesh, element, quadrature, backend, U, f_ref, data_ref, repeats))
        rt = row["runtime_ms"]
        progress("  " + " | ".join(f"runtime Assembler, {t} thread(s) {ms:8.1f} ms" for t, ms in rt.items()))
    return result


def _runtime_rows(mesh, element, quadrature, backend, U, f_ref, data_ref, repeats) -> dict:
    """Assembler.forces_and_stiffness of a Model on this mesh, on 1 thread and on all of them."""
    model = Model(mesh, [Material(law=LAW, quadrature=quadrature, E=1.0e6, nu=0.3)],
                  solver=Solver(backend=backend), check=False)
    asm = Assembler(model)
    u = U.reshape(-1)
    times, bits = {}, {}
    for threads in sorted({1, parallel.available()}):
        with parallel.threads(threads):
            times[threads] = _best(lambda: asm.forces_and_stiffness(u), repeats)
            f, data = asm.forces_and_stiffness(u)
            bits[threads] = f.tobytes() + data.tobytes()
    if len(set(bits.values())) != 1:
        raise TensormassError(f"{element} ({backend}): the runtime assembly differs between thread counts")
    f, data = asm.forces_and_stiffness(u)
    scale = np.abs(data_ref).max()
    if np.abs(data - data_ref).max() > 1e-12 * scale or np.abs(f - f_ref).max() > 1e-12 * np.abs(f_ref).max():
        raise TensormassError(f"{element} ({backend}): the runtime assembly differs from buffers + scatter")
    return {"runtime_ms": {str(t): 1e3 * v for t, v in times.items()},
            "runtime_elements_per_s": {str(t): len(mesh.blocks[0].cells) / v for t, v in times.items()}}


def run_assembly_bench(quick: bool = False, json_path=None, backends=BACKENDS, progress=print) -> dict:
    cases = QUICK_CASES if quick else CASES
    repeats = QUICK_REPEATS if quick else REPEATS
    report = {"machine": machine_info(), "quick": quick, "threads": 1, "repeats": repeats, "cases": {}}
    import numba
    previous = numba.get_num_threads()
    numba.set_num_threads(1)                # the scatter loops and kernels: one thread
    try:
        for name, (element, quadrature, n) in cases.items():
            report["cases"][name] = run_case(name, element, quadrature, n, backends, repeats, progress)
    finally:
        numba.set_num_threads(previous)
    report["faster"] = {case["element"]: {b: row["faster"] for b, row in case["backends"].items()}
                        for case in report["cases"].values()}
    progress(format_report(report))
    if json_path:
        write_json_atomic(json_path, report)
        progress(f"wrote {json_path}")
    return report


def format_report(report: dict) -> str:
    lines = ["", "full Newton assembly, one thread (M elements/s; % = rate / kernel-only rate)",
             f"{'case':16s} {'backend':7s} {'kernel':>8s} {'buffers':>14s} {'fused':>14s}  faster"]
    for name, case in report["cases"].items():
        for b, row in case["backends"].items():
            r, q = row["elements_per_s"], row["ratio_to_kernel"]
            lines.append(f"{name:16s} {b:7s} {r['kernel'] / 1e6:8.2f} {r['buffers'] / 1e6:8.2f} ({q['buffers']:4.0%})"
                         f" {r['fused'] / 1e6:8.2f} ({q['fused']:4.0%})  {row['faster']}")
    tetra = report["cases"].get("tetra_384k")
    if tetra:
        for b, row in tetra["backends"].items():
            ms = row["ms"]["fused"]
            lines.append(f"384k tetra cube, {b}: fused {ms:.0f} ms (target <= {TARGET_MS:.0f} ms, SymX "
                         f"{SYMX_MS[0]:.0f}-{SYMX_MS[1]:.0f} ms; assembly/kernel {row['ratio_to_kernel']['fused']:.0%},"
                         f" target >= {TARGET_RATIO:.0%})")
    lines.append("runtime Assembler.forces_and_stiffness (ms by threads): " + "; ".join(
        f"{name} {b} " + ", ".join(f"{t}: {ms:.1f}" for t, ms in row.get("runtime_ms", {}).items())
        for name, case in report["cases"].items() for b, row in case["backends"].items()))
    lines.append("faster path per element type: " + "; ".join(
        f"{el}: " + ", ".join(f"{b} {p}" for b, p in by.items()) for el, by in report["faster"].items()))
    return "\n".join(lines)


def cmd_assembly(args) -> int:
    run_assembly_bench(quick=args.quick, json_path=args.json, backends=tuple(args.backend or BACKENDS))
    return 0


def add_assembly_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("assembly", help="full Newton assembly (384k-tetra cube, tetra10, hexahedron): "
                                    "kernel only, element buffers + scatter, fused; numba and C")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--quick", action="store_true", help="small cubes, 2 repeats (CI smoke test)")
    p.add_argument("--backend", nargs="+", choices=BACKENDS, help="c and/or numba (default both)")
    p.set_defaults(run=cmd_assembly)
