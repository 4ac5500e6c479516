"""Kernel benchmark: generated C and numba kernels against the hand-written classic baseline.

    tensormass bench kernels [--json FILE] [--elements N] [--quick] [--all] [--entries NAME ...]
    tensormass bench compile [--json FILE] [--entries NAME ...]

`kernels` times, single-threaded and on a batch of random non-inverted
elements, forces and forces+stiffness of every selected catalogue entry with
each backend and with the classic loop (apps/classic.py) on the same data;
rates are elements per second, best of `repeats` (the runs of the different
implementations are interleaved so that a noisy neighbour hurts all alike).
`compile` compiles the largest catalogue kernels with the C compiler into a
temporary folder (seconds, peak MB) and times numba's cold first calls in a
fresh subprocess (own NUMBA_CACHE_DIR), against a budget.

    from tensormass.apps.bench import run_kernel_bench
    report = run_kernel_bench(n_elements=100_000, entries=["tetra_stvk_gauss1"], json_path="bench.json")
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from ..generator.catalogue import Entry
from ..generator.catalogue import entries as catalogue
from ..backends.c.loader import build, cflags, compiler
from ..runtime.base.errors import TensormassError
from ..runtime.kernels.kernels import BACKENDS, kernel_source, load_kernel, load_recompute_kernel
from ..runtime.base.files import write_json_atomic
from ..runtime.base.samples import random_elements
from .bench_assembly import add_assembly_command
from .bench_history import add_history_command
from .bench_formulations import add_formulations_command
from .bench_laws import add_laws_command
from .bench_integrators import add_integrators_command
from .bench_organ import add_organ_command
from .bench_springs import add_springs_command
from .bench_shells import add_shells_command
from .bench_cutting import add_cutting_command
from .bench_contact import add_contact_command
from .bench_batch import add_batch_command
from .bench_steps import add_steps_command
from .bench_gpu import add_gpu_command
from .bench_view import add_view_bench_command
from .classic import LAWS, load_classic
from .machine import format_machine, machine_info

DEFAULT_ENTRIES = tuple(f"{element}_{law}_{quadrature}"
                        for element, quadrature in (("tetra", "gauss1"), ("hexahedron", "gauss2"))
                        for law in ("hooke", "stvk", "neohookean"))
COMPILE_ENTRIES = tuple([f"hexahedron_{law}_{q}" for law in ("stvk", "neohookean", "mooney_rivlin")
                         for q in ("gauss2", "gauss3")]
                        + ["wedge_mooney_rivlin_gauss3", "pyramid_mooney_rivlin_gauss3"])
C_BUDGET_SECONDS = 60.0
C_BUDGET_MB = 2048.0
NUMBA_BUDGET_SECONDS = 10.0
QUICK_ELEMENTS = 10_000
QUICK_REPEATS = 2
KINDS = ("forces", "forces_and_stiffness")
NUMBA_FUNCTIONS = ("constants", "energy", "forces", "stiffness", "forces_and_stiffness")


# -- catalogue names ----------------------------------------------------------------------------
def resolve_entries(names) -> list:
    """Catalogue entries from names like 'tetra_stvk_gauss1' (laws may hold underscores)."""
    known = {e.name: e for e in catalogue()}
    out = []
    for value in names:
        for name in (v for v in str(value).split(",") if v):
            if name not in known:
                raise ValueError(f"unknown catalogue entry {name!r} (see `tensormass list`)")
            out.append(known[name])
    return out


# -- inputs -------------------------------------------------------------------------------------
def _valid_batch(kernel, n: int, seed: int):
    """Rest coordinates X (det J > 0 everywhere), displacements u (det F > 0) and kernel constants D."""
    straight = kernel.quadrature == "exact"
    X = random_elements(kernel.element, n, seed, straight=straight)
    params = kernel._params(n, 1.0e5, 0.3, {})
    D = np.empty((n, kernel.n_constants))
    flags = np.zeros(n, dtype=np.int32)
    for attempt in range(20):
        kernel.module.constants(X, params, D, flags)
        bad = np.flatnonzero(flags)
        if bad.size == 0:
            break
        X[bad] = random_elements(kernel.element, bad.size, seed + 1000 + attempt, straight=straight)
    else:
        raise TensormassError(f"{kernel}: could not draw {n} valid random elements")
    rng = np.random.default_rng(seed + 1)
    u = 0.03 * rng.standard_normal(X.shape)
    u[kernel.inverted(D, u)] = 0.0
    return X, u, D


# -- timing -------------------------------------------------------------------------------------
def _timed(fn, *args) -> float:
    t0 = time.perf_counter()
    fn(*args)
    return time.perf_counter() - t0


def _dispatcher_cache_hits(fn) -> int | None:
    stats = getattr(fn, "stats", None)
    return None if stats is None else int(sum(stats.cache_hits.values()))


def _c_compile_record(kernel) -> dict:
    """gcc seconds and peak MB: from this process's compile, else compiled again into a temporary folder."""
    module = kernel.module
    if module.COMPILED:
        return {"seconds": module.COMPILE_SECONDS, "maxrss_mb": module.COMPILE_MAXRSS_MB, "remeasured": False}
    return dict(compile_c(Entry(kernel.element, kernel.law, kernel.quadrature)), remeasured=True)


def compile_c(entry) -> dict:
    """Compile the entry's C kernel into a temporary folder; {'seconds', 'maxrss_mb'}."""
    with tempfile.TemporaryDirectory(prefix="tensormass-bench-") as folder:
        record = build(entry.name, kernel_source(entry.element, entry.law, entry.quadrature, "c"), Path(folder) / f"{entry.name}.so", compiler(), cflags())
    return {"seconds": record["seconds"], "maxrss_mb": record["maxrss_mb"]}


class _Impl:
    """One implementation under test: its two preallocated-output calls and a first-call time."""

    def __init__(self, name, forces, forces_and_stiffness, tiny):
        self.name = name
        self.calls = {"forces": forces, "forces_and_stiffness": forces_and_stiffness}
        self.tiny = tiny                    # kind -> the same call on 1 element (first call: compile)
        self.best = {kind: float("inf") for kind in KINDS}
        self.first_call = {}

    def warm(self):
        for kind in KINDS:
            self.first_call[kind] = _timed(self.tiny[kind])


def _bench_entry(entry, n, backends, repeats, seed, log, cold_compile) -> dict:
    result = {"entry": entry.name, "element": entry.element, "law": entry.law, "quadrature": entry.quadrature,
              "n_elements": n, "rates": {}, "ratios": {}, "compile": {}, "errors": {}}
    kernels = {}
    for backend in backends:
        try:
            t0 = time.perf_counter()
            kernels[backend] = load_kernel(entry.element, entry.law, entry.quadrature, backend=backend)
            result["compile"][backend] = {"load_s": time.perf_counter() - t0}
        except TensormassError as error:
            result["errors"][backend] = str(error)
            log(f"  {backend}: unavailable ({str(error).splitlines()[0]})")
    if not kernels:
        return result
    first = next(iter(kernels.values()))
    result.update(n_points=first.n_points, n_nodes=first.n_nodes, dim=first.dim, n_dofs=first.n_dofs,
                  n_constants=first.n_constants, constants_bytes=first.n_constants * 8, ops=dict(first.ops))

    X, u, D = _valid_batch(first, n, seed)
    n_dofs = first.n_dofs
    f = np.empty((n, n_dofs))
    K = np.empty((n, n_dofs, n_dofs))
    flags = np.zeros(n, dtype=np.int32)

    impls = []
    for backend, kernel in kernels.items():
        Db = D if kernel is first else kernel.constants(X, E=1.0e5, nu=0.3)
        mod = kernel.module
        impls.append(_Impl(
            backend,
            lambda Db=Db, mod=mod: mod.forces(Db, u, f, flags),
            lambda Db=Db, mod=mod: mod.forces_and_stiffness(Db, u, f, K, flags),
            {"forces": lambda Db=Db, mod=mod: mod.forces(Db[:1], u[:1], f[:1], flags[:1]),
             "forces_and_stiffness": lambda Db=Db, mod=mod: mod.forces_and_stiffness(Db[:1], u[:1], f[:1], K[:1], flags[:1])}))
    # The generator's other constants mode: rest coordinates in D, geometry recomputed per call.
    for backend in list(kernels):
        try:
            variant = load_recompute_kernel(entry.element, entry.law, entry.quadrature, backend)
        except TensormassError as error:
            result["errors"][f"{backend}-recompute"] = str(error)
            continue
        Dv, mod = variant.constants(X, E=1.0e5, nu=0.3), variant.module
        result.setdefault("recompute_constants_bytes", variant.n_constants * 8)
        impls.append(_Impl(
            f"{backend}-recompute",
            lambda Dv=Dv, mod=mod: mod.forces(Dv, u, f, flags),
            lambda Dv=Dv, mod=mod: mod.forces_and_stiffness(Dv, u, f, K, flags),
            {"forces": lambda Dv=Dv, mod=mod: mod.forces(Dv[:1], u[:1], f[:1], flags[:1]),
             "forces_and_stiffness": lambda Dv=Dv, mod=mod: mod.forces_and_stiffness(Dv[:1], u[:1], f[:1], K[:1], flags[:1])}))
    # The public API on the same batch: with out= buffers (no allocation) and without (fresh arrays).
    # Its checks (shapes, one finiteness sum over u, flags) are what separates it from the raw rows.
    for backend, kernel in kernels.items():
        Db = D if kernel is first else kernel.constants(X, E=1.0e5, nu=0.3)
        impls.append(_Impl(
            f"{backend}-api-out",
            lambda Db=Db, k=kernel: k.forces(Db, u, out=f, flags=flags),
            lambda Db=Db, k=kernel: k.forces_and_stiffness(Db, u, out=(f, K), flags=flags),
            {"forces": lambda Db=Db, k=kernel: k.forces(Db[:1], u[:1], out=f[:1], flags=flags[:1]),
             "forces_and_stiffness": lambda Db=Db, k=kernel: k.forces_and_stiffness(Db[:1], u[:1], out=(f[:1], K[:1]))}))
        impls.append(_Impl(
            f"{backend}-api",
            lambda Db=Db, k=kernel: k.forces(Db, u),
            lambda Db=Db, k=kernel: k.forces_and_stiffness(Db, u),
            {"forces": lambda Db=Db, k=kernel: k.forces(Db[:1], u[:1]),
             "forces_and_stiffness": lambda Db=Db, k=kernel: k.forces_and_stiffness(Db[:1], u[:1])}))
    classic = None
    if entry.law in LAWS and first.dim == 3:
        classic = load_classic(entry.element, entry.law, entry.quadrature)
        state = classic.constants(X, E=1.0e5, nu=0.3)
        result["classic_constants_bytes"] = classic.n_constants * 8
        small = type(state)(state.G[:1], state.v[:1], state.mat[:1])
        impls.append(_Impl(
            "classic",
            lambda: classic.forces_into(state, u, f, flags),
            lambda: classic.forces_and_stiffness_into(state, u, f, K, flags),
            {"forces": lambda: classic.forces_into(small, u[:1], f[:1], flags[:1]),
             "forces_and_stiffness": lambda: classic.forces_and_stiffness_into(small, u[:1], f[:1], K[:1], flags[:1])}))

    numba.set_num_threads(1)
    for impl in impls:
        impl.warm()
        for kind in KINDS:
            impl.calls[kind]()          # one full call (page faults, caches) before timing
    for _ in range(repeats):
        for kind in KINDS:
            for impl in impls:
                impl.best[kind] = min(impl.best[kind], _timed(impl.calls[kind]))
    if flags.any():
        result["errors"]["flags"] = f"{int(np.count_nonzero(flags))} element(s) flagged (det F <= 0)"

    for impl in impls:
        result["rates"][impl.name] = {kind: n / impl.best[kind] for kind in KINDS}
        result["compile"].setdefault(impl.name, {})["first_call_s"] = dict(impl.first_call)
    if "numba" in kernels:
        hits = _dispatcher_cache_hits(kernels["numba"].module.forces_and_stiffness)
        result["compile"]["numba"]["from_disk_cache"] = bool(hits) if hits is not None else None
        if cold_compile:
            try:
                result["compile"]["numba"]["cold_first_call_s"] = numba_cold_compile(entry, KINDS)
            except (TensormassError, subprocess.SubprocessError) as error:
                result["errors"]["numba_compile"] = str(error)
    if "c" in kernels:
        try:
            result["compile"]["c"].update(_c_compile_record(kernels["c"]))
        except TensormassError as error:
            result["errors"]["c_compile"] = str(error)
    # Which constants mode is faster, per backend and kernel: the benchmark's pick.
    result["constants_mode"] = {
        b: {kind: ("recompute" if result["rates"].get(f"{b}-recompute", {}).get(kind, 0) > result["rates"][b][kind]
                   else "precompute") for kind in KINDS}
        for b in kernels}
    if classic is not None:
        for kind in KINDS:
            base = result["rates"]["classic"][kind]
            ratios = {b: result["rates"][b][kind] / base for b in kernels}
            ratios["best"] = max(ratios.values())
            result["ratios"][kind] = ratios
    return result


def run_kernel_bench(n_elements=100_000, entries=None, backends=("c", "numba"), repeats=5, json_path=None,
                     quick=False, seed=0, progress=True, cold_compile=None) -> dict:
    """Benchmark the selected catalogue entries (names; default DEFAULT_ENTRIES); returns the report dict.

    quick: 10_000 elements and 2 repeats (CI smoke test). json_path: also write the report there (atomically).
    cold_compile (default: not quick): also time numba's cold first calls of forces and forces_and_stiffness
    in a subprocess with an empty cache (the in-process first call may load numba's disk cache)."""
    if cold_compile is None:
        cold_compile = not quick
    if quick:
        n_elements, repeats = min(int(n_elements), QUICK_ELEMENTS), min(int(repeats), QUICK_REPEATS)
    n_elements, repeats = int(n_elements), int(repeats)
    if n_elements < 1 or repeats < 1:
        raise ValueError("n_elements and repeats must be >= 1")
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"unknown backend {', '.join(unknown)}; known: {', '.join(BACKENDS)}")
    selected = resolve_entries(entries if entries else DEFAULT_ENTRIES)
    log = (lambda text: print(text, file=sys.stderr, flush=True)) if progress else (lambda text: None)
    report = {"benchmark": "kernels", "machine": machine_info(), "settings": {
        "n_elements": n_elements, "repeats": repeats, "backends": list(backends), "quick": bool(quick),
        "seed": seed, "threads": 1, "cold_compile": bool(cold_compile), "unit": "elements per second (best of repeats)"}, "results": []}
    for k, entry in enumerate(selected):
        log(f"[{k + 1}/{len(selected)}] {entry.name}")
        report["results"].append(_bench_entry(entry, n_elements, tuple(backends), repeats, seed + 17 * k, log,
                                              cold_compile and "numba" in backends))
    if json_path:
        write_json_atomic(json_path, report)
    return report


# -- report -------------------------------------------------------------------------------------
def _table(rows) -> str:
    widths = [max(len(str(row[i])) for row in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(str(c).ljust(w) if i == 0 else str(c).rjust(w)
                               for i, (c, w) in enumerate(zip(row, widths))) for row in rows)


def _rate(value) -> str:
    return "-" if value is None else f"{value:,.0f}"


def _ratio(value) -> str:
    return "-" if value is None else f"{value:.2f}x"


def format_kernel_report(report: dict) -> str:
    s = report["settings"]
    out = [format_machine(report["machine"]),
           f"{s['n_elements']:,} random elements, 1 thread, best of {s['repeats']}; elements per second"]
    labels = {"forces": "forces", "forces_and_stiffness": "forces + stiffness"}
    for kind in KINDS:
        rows = [(labels[kind], "C", "numba", "classic", "best/classic", "C/classic", "numba/classic")]
        for r in report["results"]:
            rate = {b: r["rates"].get(b, {}).get(kind) for b in ("c", "numba", "classic")}
            ratio = r["ratios"].get(kind, {})
            rows.append((r["entry"], _rate(rate["c"]), _rate(rate["numba"]), _rate(rate["classic"]),
                         _ratio(ratio.get("best")), _ratio(ratio.get("c")), _ratio(ratio.get("numba"))))
        out += ["", _table(rows)]
    rows = [("public API (k.forces_and_stiffness)", "backend", "raw f+K", "API out= f+K", "API f+K", "classic f+K",
             "out=/raw", "out=/classic", "API/raw", "raw f", "API out= f", "out=/raw f")]
    for r in report["results"]:
        rates = r["rates"]
        for b in ("c", "numba"):
            if b not in rates or f"{b}-api-out" not in rates:
                continue
            get = lambda name, kind: rates.get(name, {}).get(kind)   # noqa: E731
            raw, out_, api = (get(b, "forces_and_stiffness"), get(f"{b}-api-out", "forces_and_stiffness"),
                              get(f"{b}-api", "forces_and_stiffness"))
            classic = get("classic", "forces_and_stiffness")
            div = lambda a, c: None if a is None or c is None else a / c   # noqa: E731
            rows.append((r["entry"], b, _rate(raw), _rate(out_), _rate(api), _rate(classic), _ratio(div(out_, raw)),
                         _ratio(div(out_, classic)), _ratio(div(api, raw)), _rate(get(b, "forces")),
                         _rate(get(f"{b}-api-out", "forces")), _ratio(div(get(f"{b}-api-out", "forces"), get(b, "forces")))))
    out += ["", _table(rows), "raw: the generated function into preallocated arrays (k.module...); API out=: "
            "k.forces_and_stiffness(D, u, out=(f, K)); API: the same without out= (fresh arrays each call)."]
    rows = [("constants: precompute vs recompute", "C f", "C f recomp.", "C f+K", "C f+K recomp.",
             "numba f", "numba f recomp.", "numba f+K", "numba f+K recomp.", "B/elem pre", "B/elem recomp.")]
    for r in report["results"]:
        rate = lambda b, kind: _rate(r["rates"].get(b, {}).get(kind))   # noqa: E731
        rows.append((r["entry"], rate("c", "forces"), rate("c-recompute", "forces"),
                     rate("c", "forces_and_stiffness"), rate("c-recompute", "forces_and_stiffness"),
                     rate("numba", "forces"), rate("numba-recompute", "forces"),
                     rate("numba", "forces_and_stiffness"), rate("numba-recompute", "forces_and_stiffness"),
                     r.get("constants_bytes", "-"), r.get("recompute_constants_bytes", "-")))
    out += ["", _table(rows)]
    rows = [("kernel", "points", "ops f", "ops f+K", "B/elem gen", "B/elem classic", "gcc s", "gcc MB",
             "numba 1st f s", "numba 1st f+K s")]
    for r in report["results"]:
        comp = r["compile"]
        c, nb = comp.get("c", {}), comp.get("numba", {})
        fmt = lambda x: "-" if x is None else f"{x:.2f}"   # noqa: E731
        first = nb.get("cold_first_call_s")
        mark = ""
        if first is None:
            first = nb.get("first_call_s", {})
            mark = "+" if nb.get("from_disk_cache") else ""
        rows.append((r["entry"], r.get("n_points", "-"), r.get("ops", {}).get("forces", "-"),
                     r.get("ops", {}).get("forces_and_stiffness", "-"), r.get("constants_bytes", "-"),
                     r.get("classic_constants_bytes", "-"),
                     fmt(c.get("seconds")) + ("*" if c.get("remeasured") else ""), fmt(c.get("maxrss_mb")),
                     fmt(first.get("forces")) + mark, fmt(first.get("forces_and_stiffness")) + mark))
    out += ["", _table(rows),
            "ops: generated kernel operations per element. B/elem: per-element constants (8 bytes each).",
            "gcc s*: the library was cached, so it was compiled again into a temporary folder to time it.",
            "numba 1st: cold first call (compile) in a subprocess with an empty numba cache; "
            "'+': in-process first call served by numba's disk cache (not a compile)."]
    errors = [f"  {r['entry']}: {k}: {v}" for r in report["results"] for k, v in r["errors"].items()]
    if errors:
        out += ["", "problems:"] + errors
    return "\n".join(out)


# -- compile budget -----------------------------------------------------------------------------
_NUMBA_PROBE = r"""
import json, sys, time
import numpy as np
from tensormass.generator.elements import element as reference
from tensormass.runtime.kernels.kernels import load_kernel
element, law, quadrature = sys.argv[1:4]
from numba import njit
t0 = time.perf_counter()
njit(lambda x: x + 1)(1)          # numba's one-off start-up, kept out of the kernels' times
init = time.perf_counter() - t0
module = load_kernel(element, law, quadrature, backend="numba").module
X = np.array([[float(x) for x in node] for node in reference(element).nodes])[None].copy()
params = np.ones((1, len(module.METADATA["parameters"])))
D = np.zeros((1, module.METADATA["n_constants"]))
flags = np.zeros(1, dtype=np.int32)
u = np.zeros_like(X)
n = module.METADATA["n_dofs"]
calls = {
    "constants": lambda: module.constants(X, params, D, flags),
    "forces_and_stiffness": lambda: module.forces_and_stiffness(D, u, np.empty((1, n)), np.empty((1, n, n)), flags),
    "energy": lambda: module.energy(D, u, np.empty(1), flags),
    "forces": lambda: module.forces(D, u, np.empty((1, n)), flags),
    "stiffness": lambda: module.stiffness(D, u, np.empty((1, n, n)), flags),
}
out = {"numba_startup": init}
for name in sys.argv[4:]:
    t0 = time.perf_counter()
    calls[name]()
    out[name] = time.perf_counter() - t0
print("TM-RESULT " + json.dumps(out))
"""


def numba_cold_compile(entry, functions=NUMBA_FUNCTIONS, timeout=600) -> dict:
    """First-call (compile) seconds of each generated numba function, in a fresh subprocess whose
    NUMBA_CACHE_DIR is an empty temporary folder (the on-disk cache cannot hide the compile)."""
    with tempfile.TemporaryDirectory(prefix="tensormass-numba-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, NUMBA_NUM_THREADS="1")
        done = subprocess.run([sys.executable, "-c", _NUMBA_PROBE, entry.element, entry.law, entry.quadrature,
                               *functions], capture_output=True, text=True, env=env, timeout=timeout)
    for line in done.stdout.splitlines():
        if line.startswith("TM-RESULT "):
            return json.loads(line[len("TM-RESULT "):])
    tail = "\n".join((done.stdout + done.stderr).strip().splitlines()[-20:])
    raise TensormassError(f"numba compile probe for {entry.name} failed (exit code {done.returncode}):\n{tail}")


def run_compile_bench(entries=None, json_path=None, progress=True, c=True, numba=True) -> dict:
    """Compile budget of the largest kernels: gcc seconds / peak MB (budget 60 s, 2 GB) and numba cold
    first calls (budget 10 s for each generated function; numba's own start-up is reported apart)."""
    selected = resolve_entries(entries if entries else COMPILE_ENTRIES)
    log = (lambda text: print(text, file=sys.stderr, flush=True)) if progress else (lambda text: None)
    report = {"benchmark": "compile", "machine": machine_info(),
              "budget": {"c_seconds": C_BUDGET_SECONDS, "c_mb": C_BUDGET_MB, "numba_seconds": NUMBA_BUDGET_SECONDS,
                         "numba_rule": "cold first call of each generated function (numba start-up excluded)"},
              "results": []}
    for k, entry in enumerate(selected):
        log(f"[{k + 1}/{len(selected)}] {entry.name}")
        r = {"entry": entry.name, "errors": {}}
        if c:
            try:
                r["c"] = compile_c(entry)
                r["c"]["pass"] = r["c"]["seconds"] <= C_BUDGET_SECONDS and r["c"]["maxrss_mb"] <= C_BUDGET_MB
            except TensormassError as error:
                r["errors"]["c"] = str(error)
        if numba:
            try:
                times = numba_cold_compile(entry)
                startup = times.pop("numba_startup", 0.0)
                slowest = max(times, key=times.get)
                r["numba"] = {"startup_s": startup, "first_call_s": times, "total_s": sum(times.values()),
                              "slowest": slowest, "pass": times[slowest] <= NUMBA_BUDGET_SECONDS}
            except (TensormassError, subprocess.SubprocessError) as error:
                r["errors"]["numba"] = str(error)
        r["pass"] = (not r["errors"]) and all(r[b]["pass"] for b in ("c", "numba") if b in r)
        report["results"].append(r)
    report["pass"] = all(r["pass"] for r in report["results"])
    if json_path:
        write_json_atomic(json_path, report)
    return report


def format_compile_report(report: dict) -> str:
    b = report["budget"]
    rows = [("kernel", "gcc s", "gcc MB", "C", "numba f+K s", "numba slowest s", "numba all s", "numba", "")]
    for r in report["results"]:
        c, nb = r.get("c"), r.get("numba")
        verdict = lambda x: "-" if x is None else ("PASS" if x["pass"] else "FAIL")   # noqa: E731
        rows.append((r["entry"],
                     f"{c['seconds']:.1f}" if c else "-", f"{c['maxrss_mb']:.0f}" if c else "-", verdict(c),
                     f"{nb['first_call_s']['forces_and_stiffness']:.1f}" if nb else "-",
                     f"{nb['first_call_s'][nb['slowest']]:.1f} ({nb['slowest']})" if nb else "-",
                     f"{nb['total_s']:.1f}" if nb else "-", verdict(nb),
                     "PASS" if r["pass"] else "FAIL"))
    lines = [format_machine(report["machine"]),
             f"budget: C {b['c_seconds']:.0f} s and {b['c_mb']:.0f} MB of gcc per kernel; numba "
             f"{b['numba_seconds']:.0f} s for the cold first call of each function "
             "(constants, energy, forces, stiffness, forces_and_stiffness; numba start-up excluded)", "", _table(rows)]
    errors = [f"  {r['entry']}: {k}: {v}" for r in report["results"] for k, v in r["errors"].items()]
    if errors:
        lines += ["", "problems:"] + errors
    lines.append(f"overall: {'PASS' if report['pass'] else 'FAIL'}")
    return "\n".join(lines)


# -- command line -------------------------------------------------------------------------------
def cmd_kernels(args) -> int:
    entries = args.entries
    if args.all:
        entries = [e.name for e in catalogue()]
    backends = tuple(v for value in args.backend for v in value.split(",") if v) if args.backend else ("c", "numba")
    report = run_kernel_bench(n_elements=args.elements, entries=entries, backends=backends, repeats=args.repeats,
                              json_path=args.json, quick=args.quick)
    print(format_kernel_report(report))
    if args.json:
        print(f"wrote {args.json}")
    return 0


def cmd_compile(args) -> int:
    report = run_compile_bench(entries=args.entries, json_path=args.json)
    print(format_compile_report(report))
    if args.json:
        print(f"wrote {args.json}")
    return 0 if report["pass"] else 1


def add_bench_command(subparsers) -> argparse.ArgumentParser:
    """Add `bench kernels` and `bench compile` to a `tensormass` subparsers object."""
    bench = subparsers.add_parser("bench", help="benchmark the kernels (speed, compile budget)")
    sub = bench.add_subparsers(dest="bench_command", required=True)

    p = sub.add_parser("kernels", help="elements/s of generated C and numba kernels vs a hand-written classic loop")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--elements", type=int, default=100_000, metavar="N", help="batch size (default 100000)")
    p.add_argument("--repeats", type=int, default=5, help="timed runs per kernel, best kept (default 5)")
    p.add_argument("--quick", action="store_true", help=f"{QUICK_ELEMENTS} elements, {QUICK_REPEATS} repeats (CI)")
    p.add_argument("--entries", nargs="+", metavar="NAME",
                   help=f"catalogue entries (default: {' '.join(DEFAULT_ENTRIES)})")
    p.add_argument("--all", action="store_true", help="every catalogue entry")
    p.add_argument("--backend", nargs="+", help="c and/or numba (default both)")
    p.set_defaults(run=cmd_kernels)

    p = sub.add_parser("compile", help="compile time and memory of the largest kernels against the budget")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.add_argument("--entries", nargs="+", metavar="NAME", help=f"entries (default: {' '.join(COMPILE_ENTRIES)})")
    p.set_defaults(run=cmd_compile)

    add_steps_command(sub)
    add_gpu_command(sub)
    add_view_bench_command(sub)
    add_integrators_command(sub)
    add_assembly_command(sub)
    add_organ_command(sub)
    add_history_command(sub)
    add_formulations_command(sub)
    add_laws_command(sub)
    add_springs_command(sub)
    add_shells_command(sub)
    add_cutting_command(sub)
    add_contact_command(sub)
    add_batch_command(sub)
    return bench


def main(argv=None) -> int:
    """`python -m tensormass.apps.bench kernels|compile ...` (same as `tensormass bench ...`)."""
    parser = argparse.ArgumentParser(prog="tensormass")
    add_bench_command(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["bench"] + list(sys.argv[1:] if argv is None else argv))
    try:
        return args.run(args)
    except (TensormassError, ValueError, FileNotFoundError) as error:
        print(f"tensormass: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
