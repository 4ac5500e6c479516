"""Memory and time estimates of a run, made from counts before anything big is allocated.

    est = estimate(scene)                  # Estimate: est.bytes (peak), est.parts, est.seconds_per_step
    check(est, limit="8G")                 # ResourceError (exit 2) when est.bytes is above the limit
    limit_bytes(None)                      # the default: $TENSORMASS_MAX_MEMORY, else 80 % of MemAvailable

Scene.load_mesh estimates and checks a generated bar from its cell counts before building
it, and a mesh file right after reading it (before check_mesh, the element constants and
the sparsity pattern); Model checks again for the mesh it is given (refined meshes too).

The peak is modelled phase by phase after what the runtime allocates:

    runtime     interpreter, numpy/scipy/numba and compiled kernels (BASELINE, KERNEL_CODE)
    mesh        points and cells, held all run; check_mesh's face tables (transient)
    model       element constants D (n_cells x "constants" of the kernel's manifest entry,
                float64, once per law a cell can be switched to), dof tables, nodal vectors
    pattern     SparsePattern (runtime.assembly.pattern): the CSR structure and the node-blocked scatter map
                (n_cells, k*dim, k) int32, built in one pass over the cells (PATTERN_BUILD bytes
                per cell int of marker and incidence arrays at the peak)
    step        element stiffness blocks: the assembler's blocks of about BLOCK_BYTES per
                thread (PROJECTION_BLOCK times that while PSD projection runs; before the
                blocked assembler, a whole (n_cells, k*dim, k*dim) array and PROJECTION), copies of the
                global matrix, and the factor: a band Cholesky of n x kd entries (kd from the
                nodes per cell layer along the longest axis) or CG's IC(0) factor
    history     per-step rows, bounded by Simulation (HISTORY_ROWS)

peak = runtime + mesh + history + max(mesh check, model + pattern build, model + pattern + step).

Calibration (peak RSS of whole runs through /usr/bin/time on the 2-core, 23 GB benchmark
machine, warm numba cache, StVK gauss2, linear = "auto", 2 steps):

    bar, cells                        solver            estimate   measured   ratio
    hexahedron  40x8x8    (2 560)     implicit_euler     522 MiB    297 MiB   1.76
    hexahedron  80x16x16  (20 480)    implicit_euler    1641 MiB    945 MiB   1.74
    hexahedron 120x24x24  (69 120)    implicit_euler    4728 MiB   2692 MiB   1.76
    tetra       80x16x16  (122 880)   implicit_euler    2027 MiB   1309 MiB   1.55
    tetra10     40x8x8    (15 360)    implicit_euler    1822 MiB   1032 MiB   1.77
    tetra10     20x4x4    (1 920)     static             580 MiB    310 MiB   1.87
    hexahedron  80x16x16  (20 480)    explicit          1085 MiB    946 MiB   1.15
    with project_psd = true (2 560, 20 480 hexahedra, 122 880 tetra, 15 360 tetra10): 1.31-1.49

The estimate sits on the upper side by design: it assumes PSD projection may switch on
(the default project_psd = None does so when a Newton step fails to descend), every dof
free, and unstructured node adjacency.

Time per step: the Newton iterations the integrator typically takes (runtime.base.integrator_kinds)
times the kernels' operation counts (the manifest), the scatter entries and the linear solve the
solver will choose (its own rule on its own modelled costs), each at a rate fitted once to measured
runs (the constants below; tests/runtime/scene/measure_estimates.py prints predicted against
measured, the table is in docs/results.md, "Resource estimates"): the measured time per step is
0.36-2.8x the estimate on the organ, a liver-like tetra10 body and the bench bars (idle machine;
shared cores measured up to 2-3x slower). A static step that needs more Newton iterations than
assumed (a soft body sagging by a third of its size in three load steps: 11 per step) takes that
many times longer; the printed estimate says how many it assumed.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ... import elements as _elements
from ..solve import pardiso as _pardiso
from ..base import integrator_kinds
from ..assembly.assembly import BLOCK_BYTES
from ..base.errors import TensormassError
from ..base.parallel import available as available_threads
from ..kernels import catalogue
from ..solve.band import band_costs
from ..mesh.solids import LAYERS as BALL_LAYERS
from .types import Material, Solver
from ..solve.choices import (AUTO_BAND_WORK_PER_NNZ, AUTO_DIRECT_BELOW, BAND_MAX_ENTRIES, DIRECT_LIMIT,
                              PARDISO_ANALYSE_ABOVE, PARDISO_FLOPS)
from ..mesh.bars import bar_counts
from ..mesh.regions import may_cover, reachable_laws

__all__ = ["ResourceError", "MeshCounts", "Estimate", "estimate", "check", "limit_bytes", "parse_size",
           "fmt_bytes", "ENV_MAX_MEMORY", "SAFETY_FRACTION"]

ENV_MAX_MEMORY = "TENSORMASS_MAX_MEMORY"
# Of the memory the machine reports available, the run may plan to use this share: the
# estimate is not exact and other processes keep allocating.
SAFETY_FRACTION = 0.8

MiB = 2 ** 20
# Peak RSS of a 4-cell run: 210 MiB with numba's cache warm, 265-272 MiB when the kernel
# is compiled first (LLVM); each further kernel adds its compiled code.
BASELINE = 320 * MiB
KERNEL_CODE = 16 * MiB

# Coefficients measured with tracemalloc around each phase (hexahedron, tetra, tetra10 and
# pyramid bars of 0.4-5.8 M element matrix entries):
PATTERN_BUILD = 40       # B per cell int while runtime.assembly.pattern builds (incidence, markers, node CSR): 37 measured
PROJECTION = 9.5         # step peak with PSD projection / element matrix bytes: 8.0-9.3 (1.8-3.3 without)
# Since the assembler projects block by block (runtime.assembly.assembly): the block, the copy of its
# indefinite elements, their eigenvectors and the rebuild's temporaries.
PROJECTION_BLOCK = 5.0
MESH_CHECK = 26.0        # check_mesh transient / bytes of points and cells: 8-26
NNZ_HELD = 4 + 12        # B per nonzero: CSR indices (int32), Dirichlet submatrix maps (int64 entries, int32 columns)
NNZ_SETUP = 8            # B per nonzero while the submatrix maps are built (numba: counts, then fills; 7.7 measured)
NNZ_STEP = 24            # B per nonzero per step: data, its copy with the mass, K_ff (measured 12-14 + IC)
IC_BYTES = 6             # IC(0) factor: the lower half of the pattern, float64 values + int32 indices
BAND_BYTES = 12          # float32 band factor plus its float64 redo when float32 fails (both alive)
CELL_BYTES = 5 * 8       # per cell: ids, density, volume, law flags (float64/int64 each)
DOF_BYTES = 10 * 8       # per dof: u, v, mass, f_ext, prescribed values, residuals, ...
# Bandwidth kd after the solver's Cuthill-McKee ordering / (dim x nodes per cell layer
# along the longest axis): 1.03-1.2 on generated bars of every element type.
BAND_WIDTH = 1.25
# Distinct neighbours (itself included) of an interior node: structured bars and Delaunay
# meshes of random points (unstructured tetrahedra 16.4, tetra10 29.4, triangles 7.0).
PAIRS_PER_NODE = {"hexahedron": 27, "tetra": 17, "tetra10": 30, "wedge": 21, "pyramid": 19,
                  "quad": 9, "triangle": 7, "triangle6": 12}
# An element type without a measured entry (added to elements/ since): a node is shared by a
# few cells, each linking it to all its nodes; 3 x nodes per cell bounds the measured ones.
PAIRS_PER_NODE_DEFAULT = 3
# Cells per grid box (to count cell layers in a file mesh from its bounding box).
CELLS_PER_BOX = {"hexahedron": 1, "tetra": 6, "tetra10": 6, "wedge": 2, "pyramid": 6,
                 "quad": 1, "triangle": 2, "triangle6": 2}
# Node counts come from the element table (light: no sympy, no numba), also for types
# registered after import.
def _nodes(cell_type: str) -> int:
    return _elements.get(cell_type).n_nodes


def _dofs_per_node(cell_type: str, dim: int) -> int:
    """The space dimension for solids, the element table's count otherwise (runtime.base.dofs)."""
    return _elements.get(cell_type).n_dofs(dim) // _nodes(cell_type)


# Simulation keeps at most simulation.HISTORY_MAX rows (a test checks they agree); a row
# is 8 Python numbers (32 B each) plus 3 per probe and 6 per [[fixed]] entry (reaction force and
# moment, runtime.run.history), once in the history and once in the summary dict.
HISTORY_ROWS = 4096
HISTORY_ROW_BYTES = 8 * 32 * 2
HISTORY_BYTES_PER_PROBE = 3 * 32 * 2
HISTORY_BYTES_PER_FIXED = 6 * 32 * 2
# Uniform [[adapt]] refinement (every cell marked, the worst case) per round: cells x 2.0,
# nodes x 1.6-2.3 measured on tetra and triangle bars.
REFINE_CELLS, REFINE_NODES = 2.0, 2.5
# PARDISO (nested dissection) on 3D bodies, from its analysis statistics on the organ, a liver-like
# tetra10 body and the bench bars (tests/runtime/scene/measure_estimates.py): factor entries
# 12-17 x n^(4/3), factor flops 11-18 x n^2; ~12 bytes per factor entry (the float32 factor plus a
# float64 one when float32 does not converge).
PARDISO_FILL = 18.0
PARDISO_FLOPS_PER_N2 = 15.0
PARDISO_BYTES = 12
# Time per step = Newton iterations x (kernels + scatter + linear solve + per solve) + per step.
# The constants are rates of the cost model's counts, fitted once to runs on the 2-core benchmark
# machine, idle and shared (tests/runtime/scene/measure_estimates.py; the table in docs/results.md,
# "Resource estimates"); nothing is timed at run time:
#   kernels      ~0.2 ns per manifest operation with 2 assembly threads (0.1 idle, 0.3-0.5 shared);
#                scatter ~3 ns per element-matrix entry;
#   band         the solver's own model (runtime.solve.band.band_costs: a factor and three refinement
#                iterations); dynamic runs keep a factor for several steps (one for 6 steps on the
#                hexahedron_2k bench: 1 refinement iteration each), counted as 1 / BAND_REUSE_STEPS;
#   PARDISO      its factor flops (PARDISO_FLOPS_PER_N2 x n^2) at the factor rate of runtime.solve.
#                choices (PARDISO_FLOPS), plus ~2e-8 s per factor entry (PARDISO_FILL x n^(4/3)):
#                the triangular solves, iterative refinement and the float64 redo when float32 does
#                not converge, which dominate below ~20 000 dofs;
#   CG           an IC(0) iteration ~1.5e-9 s x nnz, ~100 iterations on dynamic systems (the mass
#                term conditions them), cg_max_iterations on static ones;
#   per solve    ~1 ms (the free-dof submatrix, the mass term, copies, residual checks);
#   per step     an energy and a forces evaluation (the energy history, the reactions) and ~1 ms
#                (health checks, probes, history).
SECONDS_PER_OP = 0.2e-9
SECONDS_PER_ENTRY = 3e-9
BAND_REUSE_STEPS = 4
PARDISO_ENTRY_SECONDS = 2e-8
CG_SECONDS = 1.5e-9
CG_DYNAMIC_ITERATIONS = 100
SOLVE_OVERHEAD = 1e-3
STEP_OVERHEAD = 1e-3
# What estimate() assumes when no materials or solver are given: a scene's defaults.
DEFAULT_MATERIAL = Material()
DEFAULT_SOLVER = Solver()

_UNITS = {"": 1, "B": 1, "K": 2 ** 10, "M": 2 ** 20, "G": 2 ** 30, "T": 2 ** 40, "P": 2 ** 50}


class ResourceError(TensormassError):
    """A run that would not fit the memory limit (or an unusable limit)."""


# ============================================================================== sizes


def parse_size(value, what: str = "--max-memory") -> int:
    """Bytes from 8G, 500M, 1.5GiB, 2e9 or an int (binary units: 1G = 2**30 B)."""
    if isinstance(value, bool):
        raise ResourceError(f"{what}: expected a size such as 8G, 500M or a number of bytes, got {value!r}")
    if isinstance(value, (int, float)):
        number, unit = float(value), ""
    else:
        m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([kKmMgGtTpP]?)(?:i?[bB])?\s*", str(value))
        if m is None:
            raise ResourceError(f"{what}: expected a size such as 8G, 500M or a number of bytes, got {value!r}")
        number, unit = float(m.group(1)), m.group(2).upper()
    size = number * _UNITS[unit]
    if not math.isfinite(size) or size < 1:
        raise ResourceError(f"{what}: the memory limit must be a positive size, got {value!r}")
    return int(size)


def fmt_bytes(n) -> str:
    """1.5 GiB, 320 MiB, 12 KiB (binary units, as --max-memory reads them)."""
    n = float(n)
    for unit, scale in (("PiB", 2 ** 50), ("TiB", 2 ** 40), ("GiB", 2 ** 30), ("MiB", 2 ** 20), ("KiB", 2 ** 10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n:.0f} B"


def available_memory() -> int | None:
    """What can be allocated without swapping: /proc/meminfo's MemAvailable (else total RAM),
    and no more than the memory cgroup's limit leaves (containers: the OOM killer acts there)."""
    avail = _meminfo_available()
    free = _cgroup_free()
    if free is not None:
        avail = free if avail is None else min(avail, free)
    return avail


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


# (limit, usage, stat, reclaimable page cache key) of cgroup v2, then v1
_CGROUPS = (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current", "/sys/fs/cgroup/memory.stat",
             "inactive_file"),
            ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes",
             "/sys/fs/cgroup/memory/memory.stat", "total_inactive_file"))


def _cgroup_free() -> int | None:
    """Limit minus usage of this process's memory cgroup (page cache it can drop not counted); None: no limit."""
    for limit_path, usage_path, stat_path, cache_key in _CGROUPS:
        try:
            limit = Path(limit_path).read_text().strip()
            if limit == "max" or int(limit) >= 2 ** 60:      # v1 writes "no limit" as ~2**63
                return None
            usage = int(Path(usage_path).read_text())
        except (OSError, ValueError):
            continue
        cache = 0
        try:
            for line in Path(stat_path).read_text().splitlines():
                key, _, value = line.partition(" ")
                if key == cache_key:
                    cache = int(value)
        except (OSError, ValueError):
            pass
        return max(int(limit) - (usage - cache), 0)
    return None


def own_rss() -> int:
    """Resident memory of this process now (already in use, so not in MemAvailable)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def limit_bytes(limit=None) -> tuple:
    """(bytes, where the limit comes from): the argument, else $TENSORMASS_MAX_MEMORY, else the machine's.

    The machine's: SAFETY_FRACTION of its available memory, plus what this process holds
    already (the estimate counts the interpreter and libraries, MemAvailable does not).
    """
    if limit is not None:
        return parse_size(limit), "--max-memory / max_memory"
    env = os.environ.get(ENV_MAX_MEMORY, "").strip()
    if env:
        return parse_size(env, ENV_MAX_MEMORY), ENV_MAX_MEMORY
    avail = available_memory()
    if avail is None:                      # nothing to compare against: do not refuse
        return None, "unknown (no /proc/meminfo, no sysconf)"
    rss = own_rss()
    return (int(avail * SAFETY_FRACTION) + rss,
            f"{SAFETY_FRACTION:.0%} of the {fmt_bytes(avail)} available, plus the {fmt_bytes(rss)} this process holds")


# ============================================================================== counts


@dataclass
class MeshCounts:
    """What an estimate needs of a mesh: dimension, nodes, cells per type, cell layers."""
    dim: int
    nodes: int
    cells: dict                      # cell type -> number of cells
    layers: float = 1.0              # cell layers along the longest axis (sets the band width)

    @classmethod
    def of_mesh(cls, mesh) -> "MeshCounts":
        cells: dict = {}
        for b in mesh.blocks:
            cells[b.type] = cells.get(b.type, 0) + len(b)
        return cls(mesh.dim, mesh.n_points, cells, _layers(mesh.points, cells, mesh.dim))

    @classmethod
    def of_bar(cls, spec) -> "MeshCounts":
        """From a generated bar's MeshSpec (size, cells, element), without generating it."""
        cells, nodes = bar_counts(spec.cells, spec.element)
        longest = max(range(len(spec.size)), key=lambda a: spec.size[a])
        return cls(len(spec.cells), nodes, cells, float(spec.cells[longest]))


    @classmethod
    def of_generated(cls, spec) -> "MeshCounts":
        """From any generated mesh's MeshSpec (bar, shell plate or sphere, solid ball), without
        building it: a mesh too big for the machine is refused before its arrays exist."""
        if getattr(spec, "element", None) == "shell" and spec.generate == "plate":
            nx, ny = (int(c) for c in spec.cells[:2])
            return cls(3, (nx + 1) * (ny + 1), {"shell": 2 * nx * ny}, float(max(nx, ny)))
        if getattr(spec, "element", None) == "shell" and spec.generate == "sphere":
            k = 4 ** int(spec.subdivisions)          # runtime.mesh.surfaces.icosphere's counts
            return cls(3, 10 * k + 2, {"shell": 20 * k}, float(2 ** int(spec.subdivisions)))
        if spec.generate == "ball":
            n = int(spec.divisions)                  # runtime.mesh.solids.ball_tetrahedra's counts
            layers = max(1, round(BALL_LAYERS * n))
            nodes = (n + 1) ** 3 + layers * (6 * (n + 1) ** 2 - 12 * (n + 1) + 8)   # core + 6 face blocks
            return cls(3, nodes, {"tetra": 6 * (n ** 3 + 6 * n ** 2 * layers)}, float(n + 2 * layers))
        return cls.of_bar(spec)


def _layers(points, cells: dict, dim: int) -> float:
    """Cell layers along the bounding box's longest side, for cells of the box's mean size."""
    if len(points) < 2:
        return 1.0
    extent = np.ptp(points, axis=0)
    volume = float(np.prod(extent))
    boxes = sum(n / CELLS_PER_BOX.get(t, 1) for t, n in cells.items())
    if not (volume > 0 and boxes > 0 and math.isfinite(volume)):
        return 1.0
    h = (volume / boxes) ** (1.0 / dim)
    return max(1.0, float(extent.max()) / h)


# ============================================================================== the catalogue


def _entry(element, law, quadrature) -> dict:
    """The manifest entry; the largest of the element's entries when the combination is not listed."""
    table = catalogue.committed()
    entry = table.get((element, law, quadrature))
    if entry is not None:
        return entry
    same = [e for (el, _, _), e in table.items() if el == element]
    if not same:
        return _uncatalogued_entry(element)
    return max(same, key=lambda e: e["constants"])


def _uncatalogued_entry(element) -> dict:
    """A rough entry for an element type with no kernel in the catalogue (added to elements/,
    generated on first use): one integration point per node, the constants layout the
    generator uses (per point: weight x det J, then a shape gradient per node), and op counts
    scaled like the catalogue's (f+K ~ 4 nd^2 per point, forces ~ 20 nd, energy ~ 60).
    The layout is assumed here, not read from kernel metadata: this estimate is made before
    the kernel exists (no generated file to read yet); loaded kernels use their metadata."""
    el = _elements.get(element)
    points, nd = el.n_nodes, el.n_dofs(max(el.space_dims))
    per_point = {"energy": 60, "forces": 20 * nd, "stiffness": 4 * nd * nd, "forces_and_stiffness": 4 * nd * nd}
    return {"constants": points * (1 + nd) + 8, "ops": {k: points * v for k, v in per_point.items()}}


def _laws(material, adapt) -> list:
    return reachable_laws(material.law, [r for r in adapt if r.action == "switch_law"])


def _covering(materials, cell_type) -> list:
    """The materials that may cover cells of a type; a region named by a mesh group (not a cell type)
    may cover any type, which only the mesh tells."""
    def group(m):
        region = getattr(m, "region", "all")
        return isinstance(region, str) and region != "all" and not _is_cell_type(region)
    return [m for m in materials if may_cover(m, cell_type) or group(m)]


def _is_cell_type(name: str) -> bool:
    try:
        _elements.get(name)
    except (KeyError, ValueError, TensormassError):
        return False
    return True


def _per_type(cell_type, materials, adapt, output) -> tuple:
    """(constants per cell, kernel operations per cell and iteration, kernels) for the costliest material."""
    worst, kernels = (0, 0), set()
    for m in _covering(materials, cell_type):
        laws = _laws(m, adapt)
        constants = sum(_entry(cell_type, law, m.quadrature)["constants"] for law in laws)
        ops = _entry(cell_type, m.law, m.quadrature)["ops"].get(output, 0)
        worst = max(worst, (constants, ops))
        kernels.update((cell_type, law, m.quadrature) for law in laws)
    return worst[0], worst[1], kernels


# ============================================================================== the estimate


@dataclass
class Estimate:
    """Peak memory (bytes) and time per step of a run, with the parts they are made of."""
    bytes: int
    parts: dict                      # name -> bytes (peak contributions)
    phase: str                       # when the peak happens
    seconds_per_step: float
    steps: int
    nodes: int
    cells: dict
    dofs: int
    nnz: int                         # nonzeros of the global matrix (estimated)
    band: int                        # estimated band width kd of the direct solver (0: none)
    newton_iterations: int = 0       # Newton iterations per step the time assumes (0: no Newton solve)

    @property
    def seconds(self) -> float:
        return self.seconds_per_step * self.steps

    def describe(self) -> str:
        """One line for the run summary."""
        big = sorted(((v, k) for k, v in self.parts.items() if k != "runtime"), reverse=True)[:3]
        parts = ", ".join(f"{k} {fmt_bytes(v)}" for v, k in big if v > 0)
        return (f"~{fmt_bytes(self.bytes)} peak during the {self.phase} ({parts}); "
                f"~{_fmt_time(self.seconds_per_step)} per step{self._assumed()}, ~{_fmt_time(self.seconds)} for "
                f"{self.steps} step(s)")

    def _assumed(self) -> str:
        """What the time rests on: the Newton iterations per step (strongly nonlinear static steps take more)."""
        n = self.newton_iterations
        return f" ({n} Newton iteration{'s' if n != 1 else ''} assumed)" if n else ""

    def to_dict(self) -> dict:
        return {"bytes": self.bytes, "parts": dict(self.parts), "phase": self.phase,
                "seconds_per_step": self.seconds_per_step, "seconds": self.seconds, "steps": self.steps,
                "nodes": self.nodes, "cells": dict(self.cells), "dofs": self.dofs, "nnz": self.nnz,
                "band": self.band, "newton_iterations": self.newton_iterations}


def _fmt_time(s: float) -> str:
    if s < 1.0:
        return f"{s * 1e3:.2g} ms"
    if s < 3600:
        return f"{s:.3g} s"
    if s < 86400 * 3:
        return f"{s / 3600:.3g} h"
    return f"{s / 86400:.3g} days"


def estimate(scene_or_counts, *, materials=None, solver=None, adapt=None, refinement: bool = True) -> Estimate:
    """Estimate a scene's run (or that of MeshCounts with the given materials and solver).

    scene_or_counts: a Scene (its loaded mesh, else its generated bar's spec; a mesh file
    is read), or MeshCounts.  refinement: count the cell growth of [[adapt]] refine rules
    (a Model of an already refined mesh passes False).
    """
    row_bytes = HISTORY_ROW_BYTES
    if isinstance(scene_or_counts, MeshCounts):
        counts = scene_or_counts
    else:
        scene = scene_or_counts
        counts = scene_counts(scene)
        materials = scene.materials if materials is None else materials
        solver = scene.solver if solver is None else solver
        adapt = getattr(scene, "adapt", ()) if adapt is None else adapt
        row_bytes = (HISTORY_ROW_BYTES + HISTORY_BYTES_PER_PROBE * len(getattr(scene, "probes", ()))
                     + HISTORY_BYTES_PER_FIXED * len(getattr(scene, "fixed", ())))
    materials = materials if materials is not None else [DEFAULT_MATERIAL]
    solver = solver if solver is not None else DEFAULT_SOLVER
    adapt = list(adapt or ())
    if refinement:
        counts = _refined(counts, adapt)
    estimator = _Estimator(counts, list(materials), solver, adapt)
    estimator.history_row_bytes = row_bytes
    return estimator.run()


def scene_counts(scene) -> MeshCounts:
    """Counts of a scene's mesh: the loaded one, else the generated bar's spec (nothing is built)."""
    mesh = getattr(scene, "_mesh", None)
    if mesh is None and scene.mesh.file is not None:
        mesh = scene.load_mesh()
    if mesh is not None:
        return MeshCounts.of_mesh(mesh)
    return MeshCounts.of_generated(scene.mesh)


def _refined(counts: MeshCounts, adapt) -> MeshCounts:
    """Worst-case counts after the refine rounds of the [[adapt]] rules (uniform marking)."""
    rounds = sum(r.rounds for r in adapt if r.action == "refine")
    if not rounds:
        return counts
    grow = {t: (int(n * REFINE_CELLS ** rounds) if _elements.get(t).refinement else n)
            for t, n in counts.cells.items()}
    nodes = int(counts.nodes * REFINE_NODES ** rounds)
    return MeshCounts(counts.dim, nodes, grow, counts.layers * REFINE_CELLS ** (rounds / counts.dim))


class _Estimator:
    """The phase model of the module docstring, for one set of counts."""

    history_row_bytes = HISTORY_ROW_BYTES        # estimate() adds the scene's probes and [[fixed]] entries

    def __init__(self, counts: MeshCounts, materials, solver, adapt):
        self.c, self.solver = counts, solver
        self.kind = solver.kind
        self.integrator = integrator_kinds.get(self.kind)
        self.output = self.integrator.step_output
        dim = counts.dim
        # dofs per node (runtime.base.dofs): the dimension for solids; one count per mesh
        dim = self.dpn = max((_dofs_per_node(t, dim) for t in counts.cells), default=dim)
        self.dofs = counts.nodes * dim
        self.entries = self.constants = self.ops = self.step_ops = self.cell_ints = self.cell_dofs = 0
        self.projection = False
        kernels = set()
        for t, n in counts.cells.items():
            k = _nodes(t)
            constants, ops, found = _per_type(t, materials, adapt, self.output)
            kernels |= found
            self.entries += n * (k * dim) ** 2
            self.constants += n * constants
            self.ops += n * ops
            # every step also evaluates the energy and the forces once (energy history, reactions)
            self.step_ops += n * sum(_per_type(t, materials, adapt, out)[1] for out in ("energy", "forces"))
            self.cell_ints += n * k
        self.kernels = max(len(kernels), 1)
        self.projection = solver.project_psd is not False and any(
            law != "hooke" for m in materials for law in _laws(m, adapt))
        pairs = max((PAIRS_PER_NODE.get(t, PAIRS_PER_NODE_DEFAULT * _nodes(t)) for t in counts.cells),
                    default=1)
        within = sum(n * _nodes(t) ** 2 for t, n in counts.cells.items())
        self.nnz = dim * dim * min(counts.nodes * pairs, within)
        self.kd = int(math.ceil(BAND_WIDTH * dim * counts.nodes / max(counts.layers, 1.0)))
        self.linear = self._linear()

    def _linear(self) -> str:
        """What the linear solver will do: "none", "band", "pardiso" or "cg" (solvers.LinearSolver.choose)."""
        if self.output == "forces":             # no stiffness, no linear solve
            return "none"
        n, method = self.dofs, self.solver.linear
        band_entries = n * (self.kd + 1)
        if method in ("cg", "amg"):
            return "cg"
        if method in ("auto", "direct", "pardiso") and n > AUTO_DIRECT_BELOW and _pardiso.available():
            # the solver's rule (runtime.solve.solvers.LinearSolver.choose) on modelled costs
            band = self._band_seconds()
            if method == "pardiso" or (band > PARDISO_ANALYSE_ABOVE and band > self._pardiso_seconds()):
                return "pardiso"
            return "band"
        if method == "auto" and n > AUTO_DIRECT_BELOW:
            if n > DIRECT_LIMIT or band_entries > BAND_MAX_ENTRIES \
                    or n * float(self.kd) ** 2 > AUTO_BAND_WORK_PER_NNZ * self.nnz:
                return "cg"
        # "direct" past the band limit uses CHOLMOD or SuperLU: fill-reducing orderings stay
        # below the band's fill, so the band is the conservative figure there too
        return "band"

    def _band_seconds(self) -> float:
        """The solver's own modelled band seconds (runtime.solve.band.band_costs: what it chooses by)."""
        factor, iteration = band_costs(self.dofs, self.kd, self.nnz)
        return factor + 3.0 * iteration

    def _pardiso_seconds(self) -> float:
        """The solver's own modelled PARDISO seconds, a factor and three solves (runtime.solve.solvers.
        pardiso_costs) for the factor flops and entries of PARDISO_FLOPS_PER_N2 and PARDISO_FILL."""
        from ..solve.solvers import pardiso_costs      # deferred: pyamg, 0.05 s of a scene's ~1 s parse
        n = float(self.dofs)
        factor, solve = pardiso_costs(PARDISO_FLOPS_PER_N2 * n * n, PARDISO_FILL * n ** (4.0 / 3.0))
        return factor + 3.0 * solve

    def _factor(self) -> int:
        if self.linear == "pardiso":
            return int(PARDISO_BYTES * PARDISO_FILL * float(self.dofs) ** (4.0 / 3.0))
        if self.linear == "band":
            return BAND_BYTES * self.dofs * (self.kd + 1)
        return IC_BYTES * self.nnz if self.linear == "cg" else 0

    def run(self) -> Estimate:
        c, dim = self.c, self.c.dim
        mesh = 8 * (c.nodes * dim + self.cell_ints)
        constants = 8 * self.constants
        dim = self.dpn                       # from here on: per-node dofs
        model = 8 * self.cell_ints * (1 + dim) + CELL_BYTES * sum(c.cells.values()) + DOF_BYTES * self.dofs
        matrices = 8 * self.entries
        # the node-blocked map is int32 below 2**31 nonzeros (runtime.assembly.pattern; full positions are
        # only built on demand), plus int64 copies of cells and dof tables
        blocks_map = (matrices // (2 * dim) if self.nnz < 2**31 - 1 else matrices // dim)
        pattern = blocks_map + NNZ_HELD * self.nnz + 8 * self.cell_ints * (2 + dim)
        # the assembler evaluates blocks of about BLOCK_BYTES per thread, never a whole-part K
        blocks = min(matrices, 2 * _assembly_block_bytes() * _threads())
        if self.output == "forces":          # element forces only; the pattern is still built
            step = {"element forces": 2 * 8 * self.cell_ints * dim}
        else:
            step = {"element matrices": blocks * (PROJECTION_BLOCK if self.projection else 1.0),
                    "global matrices": NNZ_STEP * self.nnz, "factor": self._factor()}
        phases = {                           # what is allocated on top of the runtime, mesh and history
            "mesh check": {"mesh check": MESH_CHECK * mesh},
            "sparsity pattern build": {"constants": constants, "model": model,
                                       "pattern build": blocks_map + NNZ_HELD * self.nnz
                                       + PATTERN_BUILD * self.cell_ints},
            "Dirichlet maps": {"constants": constants, "model": model, "pattern": pattern,
                               "Dirichlet maps": NNZ_SETUP * self.nnz},
            "time steps": {"constants": constants, "model": model, "pattern": pattern, **step},
        }
        phase = max(phases, key=lambda name: sum(phases[name].values()))
        parts = {"runtime": BASELINE + KERNEL_CODE * (self.kernels - 1), "mesh": mesh,
                 "history": min(self.solver.steps, HISTORY_ROWS) * self.history_row_bytes, **phases[phase]}
        parts = {k: int(v) for k, v in parts.items()}
        return Estimate(bytes=sum(parts.values()), parts=parts, phase=phase,
                        seconds_per_step=self._seconds(), steps=int(self.solver.steps), nodes=c.nodes,
                        cells=dict(c.cells), dofs=self.dofs, nnz=int(self.nnz),
                        band=self.kd if self.linear == "band" else 0,
                        newton_iterations=0 if self.output == "forces" else self.integrator.newton_iterations)

    def _seconds(self) -> float:
        """Time per step from the counts and the rates above (module constants, never a timing)."""
        kernel = self.ops * SECONDS_PER_OP
        forces = SECONDS_PER_ENTRY * self.cell_ints * self.dpn        # scatter of the element forces
        if self.output == "forces":
            return kernel + forces
        n = float(self.dofs)
        if self.linear == "band":
            factor, iteration = band_costs(self.dofs, self.kd, self.nnz)
            reuse = BAND_REUSE_STEPS if self.integrator.dynamic else 1
            solve = factor / reuse + 3.0 * iteration
        elif self.linear == "pardiso":
            solve = (PARDISO_FLOPS_PER_N2 * n * n / PARDISO_FLOPS
                     + PARDISO_ENTRY_SECONDS * PARDISO_FILL * n ** (4.0 / 3.0))
        else:
            iterations = CG_DYNAMIC_ITERATIONS if self.integrator.dynamic else self.solver.cg_max_iterations
            solve = CG_SECONDS * self.nnz * min(iterations, self.solver.cg_max_iterations)
        per_iteration = kernel + SECONDS_PER_ENTRY * self.entries + solve + SOLVE_OVERHEAD
        extras = self.step_ops * SECONDS_PER_OP + forces + STEP_OVERHEAD
        return self.integrator.newton_iterations * per_iteration + extras


# ============================================================================== the check


def check(est: Estimate, limit=None, what: str = "this run") -> int | None:
    """Raise ResourceError when est.bytes exceeds the limit; returns the limit in bytes (None: unknown).

    limit: bytes or a size string ("8G"); None: $TENSORMASS_MAX_MEMORY, else SAFETY_FRACTION
    of the machine's available memory.
    """
    cap, source = limit_bytes(limit)
    if cap is None or est.bytes <= cap:
        return cap
    cells = ", ".join(f"{n:,} {t}" for t, n in est.cells.items())
    need = _suggest(est.bytes)
    raise ResourceError(
        f"{what} needs an estimated {fmt_bytes(est.bytes)} of memory ({cells} cells, {est.nodes:,} nodes; "
        f"peak during the {est.phase}: {_top_parts(est)}), above the limit of {fmt_bytes(cap)} ({source}). "
        f"Use fewer cells, or raise the limit with --max-memory {need} (or {ENV_MAX_MEMORY}={need}, "
        f"or max_memory=\"{need}\" in Python) if the machine really has that much.")


def _top_parts(est: Estimate) -> str:
    big = sorted(((v, k) for k, v in est.parts.items()), reverse=True)[:3]
    return ", ".join(f"{k} {fmt_bytes(v)}" for v, k in big)


def _suggest(n: int) -> str:
    """A --max-memory value just above n, in the largest unit that keeps it a small number."""
    for unit, scale in (("T", 2 ** 40), ("G", 2 ** 30), ("M", 2 ** 20)):
        if n >= scale:
            return f"{math.ceil(n * 1.05 / scale)}{unit}"
    return f"{math.ceil(n * 1.05)}"


def _assembly_block_bytes() -> int:
    return int(BLOCK_BYTES)


def _threads() -> int:
    return available_threads()
